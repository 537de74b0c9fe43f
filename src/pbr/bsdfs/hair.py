"""``hair``: the Chiang et al. 2016 hair fibre scattering model (Mitsuba's ``hair``,
pbrt-v4's ``HairBxDF``): R, TT, TRT and residual lobes over the whole sphere. The
model, its parameters and conventions: docs/materials.md.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..plugins.props import NONNEGATIVE, Range
from ..spectrum import clamp_keep_grad, rgb_to_coeffs, sigmoid_polynomial
from ..textures import load_spectrum
from .base import BSDF_TYPES, BSDFType, BSDFSample, REFLECTION, TRANSMISSION, GLOSSY
from .fresnel import fresnel_dielectric, lookup_ior
from .principled import _luminance

P_MAX = 3  # R, TT, TRT and the sum of all longer paths

# d'Eon et al. 2011's absorption coefficients of the pigments (per unit fibre radius).
EUMELANIN_SIGMA_A = (0.419, 0.697, 1.37)
PHEOMELANIN_SIGMA_A = (0.187, 0.4, 1.05)

# Absorption given by pigments, by ``sigma_a`` or by ``reflectance``.
PIGMENT, SIGMA_A, REFLECTANCE = 0, 1, 2
_BETA_MIN = 0.01


# ------------------------------------------------------------------ lobe functions

def i0(x):
    """Modified Bessel function I0 (series to x^20, as Mitsuba)."""
    x2 = x * x
    result, term = mi.Float(1.0), x2 * 0.25
    for k in range(1, 11):
        result += term
        term = term * x2 * (0.25 / ((k + 1) * (k + 1)))
    return result


def log_i0_minus_x(x):
    """log I0(x) - x (the exponential part cancels against M_p's), asymptotic above 12
    with the same correction term as pbrt-v4 and Mitsuba."""
    big = x > 12.0
    xs = dr.select(big, 1.0, x)
    xb = dr.select(big, x, 12.0)
    return dr.select(big, 0.5 * (-dr.log(2.0 * dr.pi * xb) + dr.rcp(8.0 * xb)), dr.log(i0(xs)) - xs)


def m_p(cos_i, cos_o, sin_i, sin_o, v):
    """Longitudinal scattering M_p (d'Eon et al.), normalised over theta_o with measure
    cos theta_o d theta_o; ``v`` is the lobe variance."""
    kappa = dr.rcp(v)
    c = cos_i * cos_o
    s = sin_i * sin_o
    cos_sum = c - s                    # cos(theta_i + theta_o)
    sin_sum = sin_i * cos_o + cos_i * sin_o
    one_minus = dr.select(cos_sum > 0, sin_sum * sin_sum / (1.0 + cos_sum), 1.0 - cos_sum)
    log_m = (-kappa * one_minus + log_i0_minus_x(kappa * c) + dr.log(kappa)
             - dr.log(1.0 - dr.exp(-2.0 * kappa)))
    return dr.exp(log_m)


def logistic(x, s):
    e = dr.exp(-dr.abs(x) / s)
    return e / (s * dr.square(1.0 + e))


def logistic_cdf(x, s):
    return dr.rcp(1.0 + dr.exp(-x / s))


def trimmed_logistic(x, s):
    """The logistic density of scale ``s`` restricted to [-pi, pi]."""
    return logistic(x, s) / (logistic_cdf(dr.pi, s) - logistic_cdf(-dr.pi, s))


def sample_trimmed_logistic(u, s):
    k = logistic_cdf(dr.pi, s) - logistic_cdf(-dr.pi, s)
    x = -s * dr.log(dr.rcp(u * k + logistic_cdf(-dr.pi, s)) - 1.0)
    return dr.clip(x, -dr.pi, dr.pi)


def phi_specular(p, gamma_i, gamma_t):
    """Azimuthal change of the specular path with p internal segments."""
    return 2.0 * p * gamma_t - 2.0 * gamma_i + p * dr.pi


def n_p(dphi, p, s, gamma_i, gamma_t):
    """Azimuthal scattering N_p: trimmed logistic around the specular azimuth."""
    x = dphi - phi_specular(p, gamma_i, gamma_t)
    x = x - dr.two_pi * dr.floor((x + dr.pi) * (1.0 / dr.two_pi))   # to [-pi, pi)
    return trimmed_logistic(x, s)


def longitudinal_variances(beta_m):
    """v_p for p = 0..3 (Chiang et al.'s fit; TT narrower, TRT and beyond wider)."""
    v0 = dr.square(0.726 * beta_m + 0.812 * dr.square(beta_m) + 3.7 * dr.power(beta_m, 20))
    return [v0, 0.25 * v0, 4.0 * v0, 4.0 * v0]


def logistic_scale(beta_n):
    """Scale of the azimuthal logistic (Chiang et al.'s fit)."""
    return math.sqrt(math.pi / 8.0) * (0.265 * beta_n + 1.194 * dr.square(beta_n) + 5.372 * dr.power(beta_n, 22))


def sigma_a_from_reflectance(c, beta_n):
    """pbrt-v4's absorption for a hair volume of albedo ``c`` (Chiang et al.'s fit)."""
    b = beta_n
    d = 5.969 - 0.215 * b + 2.532 * b * b - 10.73 * b ** 3 + 5.574 * b ** 4 + 0.245 * b ** 5
    return dr.square(dr.log(c) / d)


# ------------------------------------------------------------------------ the fibre

class _Fibre:
    """Per-hit fibre parameters: variances ``v``, logistic scale ``s``, sin/cos of
    2^k alpha (scale tilt), ``eta`` and ``sigma_a``."""


class _Incident:
    """Everything that depends on wi only (shared by eval and sample): hair angles,
    offset, refracted azimuth, attenuations A_p and their sampling probabilities, and
    theta_i tilted by the scales for each p."""

    def __init__(self, fb: _Fibre, wi, lam):
        self.sin_i = wi.y
        self.cos_i = dr.safe_sqrt(1.0 - dr.square(wi.y))
        self.phi_i = dr.atan2(wi.z, wi.x)
        self.gamma_i = dr.atan2(-wi.x, wi.z)
        h = dr.sin(self.gamma_i)
        eta = fb.eta
        sin_t = self.sin_i / eta
        cos_t = dr.safe_sqrt(1.0 - dr.square(sin_t))
        eta_p = dr.safe_sqrt(dr.square(eta) - dr.square(self.sin_i)) / dr.maximum(self.cos_i, 1e-30)
        sin_gamma_t = h / eta_p
        cos_gamma_t = dr.safe_sqrt(1.0 - dr.square(sin_gamma_t))
        self.gamma_t = dr.safe_asin(sin_gamma_t)
        T = dr.exp(-fb.sigma_a * (2.0 * cos_gamma_t / cos_t))
        self.ap = a_p(self.cos_i, eta, h, T)
        lum = [_luminance(a, lam) for a in self.ap]
        total = lum[0] + lum[1] + lum[2] + lum[3]
        inv = dr.select(total > 0, dr.rcp(total), 0.0)
        self.ap_pdf = [l * inv for l in lum]
        self.tilted = [_tilt(self.sin_i, self.cos_i, fb, p) for p in range(P_MAX + 1)]

    def eval_pdf(self, fb: _Fibre, wo):
        """(f |cos|, pdf) toward ``wo``: the sum over the terms p."""
        sin_o = wo.y
        cos_o = dr.safe_sqrt(1.0 - dr.square(sin_o))
        dphi = dr.atan2(wo.z, wo.x) - self.phi_i
        f, pdf = mi.Spectrum(0.0), mi.Float(0.0)
        for p in range(P_MAX + 1):
            sin_ip, cos_ip = self.tilted[p]
            m = m_p(cos_ip, cos_o, sin_ip, sin_o, fb.v[p])
            if p < P_MAX:
                m = m * n_p(dphi, p, fb.s, self.gamma_i, self.gamma_t)
            else:
                m = m * dr.inv_two_pi
            f += m * self.ap[p]
            pdf += m * self.ap_pdf[p]
        ok = dr.isfinite(pdf) & (pdf >= 0)
        f = dr.select(ok & dr.all(dr.isfinite(f)), f, 0.0)
        return f, dr.select(ok, pdf, 0.0)


def a_p(cos_i, eta, h, T):
    """A_p for p = 0..3: Fresnel at the first hit, then (1 - F)^2 T, ... and the sum of
    all longer paths (a geometric series)."""
    f = fresnel_dielectric(cos_i * dr.safe_sqrt(1.0 - dr.square(h)), eta)[0]
    a0 = mi.Spectrum(f)
    a1 = dr.square(1.0 - f) * T
    a2 = a1 * T * f
    tf = T * f
    a3 = mi.Spectrum(dr.select(tf < 1.0, a2 * tf / dr.maximum(1.0 - tf, 1e-30), 0.0))
    return [a0, a1, a2, a3]


def _tilt(sin_i, cos_i, fb: _Fibre, p: int):
    """(sin, |cos|) of theta_i shifted by the cuticle scales for term p: theta_i - 2 alpha
    for R, theta_i + alpha for TT, theta_i + 4 alpha for TRT, unchanged beyond."""
    if p == P_MAX:
        return sin_i, dr.abs(cos_i)
    k, sign = {0: (1, -1.0), 1: (0, 1.0), 2: (2, 1.0)}[p]
    s2, c2 = fb.sin2k[k] * sign, fb.cos2k[k]
    return sin_i * c2 + cos_i * s2, dr.abs(cos_i * c2 - sin_i * s2)


def _select_p(p, values):
    """values[p] per lane (p a UInt32 in 0..P_MAX)."""
    out = values[P_MAX]
    for q in range(P_MAX - 1, -1, -1):
        out = dr.select(p == q, values[q], out)
    return out


# --------------------------------------------------------------------- the family

@BSDF_TYPES.register("hair")
class Hair(BSDFType):
    """``hair``: Chiang et al.'s hair fibre (Mitsuba's ``hair``, pbrt-v4's ``HairBxDF``), for
    ``bsplinecurve``/``linearcurve`` shapes. Absorption from melanin, ``sigma_a`` or
    ``reflectance`` (one of them).

    ======================  =========  =======  =======================================================
    name                    type       default  meaning
    ======================  =========  =======  =======================================================
    eumelanin               texture    1.3      eumelanin concentration
    pheomelanin             texture    0.2      pheomelanin concentration
    sigma_a                 texture    -        absorption coefficient instead of melanin (times scale)
    scale                   float      1        factor on sigma_a
    reflectance             texture    -        pbrt-v4's colour instead of melanin
    longitudinal_roughness  texture    0.3      longitudinal roughness beta_m, in [0, 1]
    azimuthal_roughness     texture    0.3      azimuthal roughness beta_n, in [0, 1]
    scale_tilt              texture    2        tilt of the cuticle scales (degrees)
    int_ior                 float|str  'amber'  IOR of the fibre (1.55)
    ext_ior                 float|str  'air'    IOR around it
    ======================  =========  =======  =======================================================
    """

    name = "hair"
    flags = REFLECTION | TRANSMISSION | GLOSSY

    def _float_texture(self, loader, props, name, default, lo=None, hi=None):
        """A float parameter (a number or a texture whose first wavelength is used) in
        [lo, hi], as a texture slot."""
        return load_spectrum(loader, props.raw(name, default), props.key(name), emitter=False, valid=Range(lo, hi))

    def add(self, loader, props) -> int:
        inst = {}
        inst["beta_m"] = self._float_texture(loader, props, "longitudinal_roughness", 0.3, 0.0, 1.0)
        inst["beta_n"] = self._float_texture(loader, props, "azimuthal_roughness", 0.3, 0.0, 1.0)
        inst["alpha"] = self._float_texture(loader, props, "scale_tilt", 2.0, -90.0, 90.0)
        eta = lookup_ior(props, "int_ior", "amber") / lookup_ior(props, "ext_ior", "air")
        if not eta > 1.0:
            raise props.error("int_ior", f"a fibre needs int_ior > ext_ior (eta = {eta:g})")
        inst["eta"] = eta
        given = [k for k in ("sigma_a", "reflectance", "eumelanin", "pheomelanin") if props.has(k)]
        if props.has("sigma_a") or props.has("reflectance"):
            if len(given) > 1:
                raise props.error(given[1], f"give absorption either as {given[0]!r} or as {given[1]!r}, not both")
        if props.has("scale") and not props.has("sigma_a"):
            raise props.error("scale", "'scale' multiplies 'sigma_a' and needs it")
        inst["scale"] = props.float("scale", 1.0, min=0.0)
        inst["sigma"] = inst["eu"] = inst["ph"] = None
        if props.has("sigma_a"):
            inst["mode"] = SIGMA_A
            inst["sigma"] = load_spectrum(loader, props.raw("sigma_a"), props.key("sigma_a"), emitter=False,
                                          unbounded=True, valid=NONNEGATIVE)
        elif props.has("reflectance"):
            inst["mode"] = REFLECTANCE
            inst["sigma"] = load_spectrum(loader, props.raw("reflectance"), props.key("reflectance"), emitter=False)
        else:
            inst["mode"] = PIGMENT
            inst["eu"] = self._float_texture(loader, props, "eumelanin", 1.3, 0.0)
            inst["ph"] = self._float_texture(loader, props, "pheomelanin", 0.2, 0.0)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self) -> None:
        ins = self.instances
        slots = lambda k: [0 if i[k] is None else i[k] for i in ins]  # noqa: E731
        table = lambda k: mi.UInt32(slots(k))  # noqa: E731
        self.beta_m, self.beta_n, self.alpha = table("beta_m"), table("beta_n"), table("alpha")
        self.sigma, self.eu, self.ph = table("sigma"), table("eu"), table("ph")
        # The slots each parameter's lookup can reach (TextureSet.eval's reach).
        self.reach = {k: tuple(slots(k)) for k in ("beta_m", "beta_n", "alpha", "sigma", "eu", "ph")}
        self.eta = mi.Float([i["eta"] for i in ins])
        self.scale = mi.Float([i["scale"] for i in ins])
        self.mode = mi.UInt32([i["mode"] for i in ins])
        self.modes = {i["mode"] for i in ins}
        if PIGMENT in self.modes:
            # Sigmoid coefficients of the pigments (Mitsuba's albedo-form upsampling).
            self.pigment_coeffs = [
                [float(x[0]) for x in rgb_to_coeffs(mi.Color3f(*rgb))]
                for rgb in (EUMELANIN_SIGMA_A, PHEOMELANIN_SIGMA_A)]

    def _fibre(self, ctx, idx, active) -> _Fibre:
        tex, uv, lam = self.textures, ctx.si.uv, ctx.wl.lambda_

        def ev(name, on=active):
            return tex.eval(dr.gather(mi.UInt32, getattr(self, name), idx, on), uv, lam, on, illuminant=False,
                            reach=self.reach[name])

        fb = _Fibre()
        # Numerical clamps of checked values: the derivative at a bound passes.
        beta_m = clamp_keep_grad(ev("beta_m")[0], _BETA_MIN, 1.0)
        beta_n = clamp_keep_grad(ev("beta_n")[0], _BETA_MIN, 1.0)
        fb.v = longitudinal_variances(beta_m)
        fb.s = logistic_scale(beta_n)
        sin_a = dr.sin(ev("alpha")[0] * (dr.pi / 180.0))
        cos_a = dr.safe_sqrt(1.0 - dr.square(sin_a))
        fb.sin2k, fb.cos2k = [sin_a], [cos_a]
        for _ in range(2):
            s, c = fb.sin2k[-1], fb.cos2k[-1]
            fb.sin2k.append(2.0 * c * s)
            fb.cos2k.append(dr.square(c) - dr.square(s))
        fb.eta = dr.gather(mi.Float, self.eta, idx, active)
        mode = dr.gather(mi.UInt32, self.mode, idx, active) if len(self.modes) > 1 else None
        sigma_a = mi.Spectrum(0.0)
        if PIGMENT in self.modes:
            on = active if mode is None else active & (mode == PIGMENT)
            ce = clamp_keep_grad(ev("eu", on)[0], 0.0)
            cp = clamp_keep_grad(ev("ph", on)[0], 0.0)
            se, sp = (sigmoid_polynomial(mi.Array3f(*c), lam) for c in self.pigment_coeffs)
            sigma_a = dr.select(on, ce * se + cp * sp, sigma_a)
        if SIGMA_A in self.modes:
            on = active if mode is None else active & (mode == SIGMA_A)
            sig = clamp_keep_grad(ev("sigma", on) * dr.gather(mi.Float, self.scale, idx, on), 0.0)
            sigma_a = dr.select(on, sig, sigma_a)
        if REFLECTANCE in self.modes:
            on = active if mode is None else active & (mode == REFLECTANCE)
            c = dr.clip(ev("sigma", on), 0.0, 1.0)
            sigma_a = dr.select(on, sigma_a_from_reflectance(c, beta_n), sigma_a)
        fb.sigma_a = sigma_a
        return fb

    def _sample(self, fb: _Fibre, inc: _Incident, u1, u2, active) -> BSDFSample:
        # Choose the term p with probability ap_pdf[p]; reuse u1 for the azimuth.
        pdf = inc.ap_pdf
        rescale = lambda u, q: dr.select(q > 0, u / dr.select(q > 0, q, 1.0), 0.0)  # noqa: E731
        u = mi.Float(u1)
        u_phi = rescale(u, pdf[0])
        p = mi.UInt32(0)
        for q in range(P_MAX):
            take = pdf[q] < u
            u = u - pdf[q]
            p = dr.select(take, q + 1, p)
            u_phi = dr.select(take, rescale(u, pdf[q + 1]), u_phi)
        u_phi = dr.clip(u_phi, 0.0, 1.0)

        # theta_o from M_p around the (tilted) specular cone.
        sin_ip = _select_p(p, [t[0] for t in inc.tilted])
        cos_ip = _select_p(p, [t[1] for t in inc.tilted])
        v = _select_p(p, fb.v)
        cos_theta = dr.clip(1.0 + v * dr.log(u2.x + (1.0 - u2.x) * dr.exp(-2.0 * dr.rcp(v))), -1.0, 1.0)
        sin_theta = dr.safe_sqrt(1.0 - dr.square(cos_theta))
        cos_phi = dr.cos(dr.two_pi * u2.y)
        sin_o = -cos_theta * sin_ip + sin_theta * cos_phi * cos_ip
        cos_o = dr.safe_sqrt(1.0 - dr.square(sin_o))

        # Azimuth from N_p (uniform for the lumped longer paths).
        pf = mi.Float(p)
        dphi = dr.select(p < P_MAX,
                         phi_specular(pf, inc.gamma_i, inc.gamma_t) + sample_trimmed_logistic(u_phi, fb.s),
                         dr.two_pi * u_phi)
        sp, cp = dr.sincos(inc.phi_i + dphi)
        wo = dr.normalize(mi.Vector3f(cos_o * cp, sin_o, cos_o * sp))

        f, pdf_wo = inc.eval_pdf(fb, wo)
        ok = active & (pdf_wo > 0)
        w = f / dr.select(ok, pdf_wo, 1.0)
        return BSDFSample(wo, dr.select(ok, pdf_wo, 0.0), mi.Float(1.0), mi.Bool(False), dr.select(ok, w, 0.0))

    def eval_pdf(self, ctx, idx, wo, active):
        fb = self._fibre(ctx, idx, active)
        f, pdf = _Incident(fb, ctx.si.wi, ctx.wl.lambda_).eval_pdf(fb, wo)
        return dr.select(active, f, 0.0), dr.select(active, pdf, 0.0)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        fb = self._fibre(ctx, idx, active)
        return self._sample(fb, _Incident(fb, ctx.si.wi, ctx.wl.lambda_), u1, u2, active)

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        fb = self._fibre(ctx, idx, active)
        inc = _Incident(fb, ctx.si.wi, ctx.wl.lambda_)
        f, pdf = inc.eval_pdf(fb, wo)
        return dr.select(active, f, 0.0), dr.select(active, pdf, 0.0), self._sample(fb, inc, u1, u2, active)
