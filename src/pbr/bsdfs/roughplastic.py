"""``roughplastic``: Mitsuba's rough plastic: a microfacet dielectric coating over a
diffuse base, with the coating's transmittance tabulated per instance at load time.
The model: docs/materials.md.
"""

from __future__ import annotations

from functools import lru_cache

import drjit as dr
import mitsuba as mi
import numpy as np

from ..sampling import cosine_hemisphere_pdf, square_to_cosine_hemisphere
from .base import BSDF_TYPES, BSDFSample, DIFFUSE, GLOSSY, REFLECTION
from .fresnel import fresnel_dielectric, lookup_ior, reflect_about
from .microfacet import BECKMANN, GGX, Microfacet
from .plastic import Plastic

TABLE_RES = 64   # Mitsuba's resolution of the transmittance table over cos(theta)


# ----------------------------------------------------------------- precomputation

def _g1_np(kind, alpha, v, m):
    """Smith masking of the isotropic distribution (the same forms as Microfacet.G1),
    for float64 arrays; v and m are (x, y, z) tuples."""
    xy2 = alpha * alpha * (v[0] * v[0] + v[1] * v[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = xy2 / (v[2] * v[2])
        if kind == BECKMANN:
            a = 1.0 / np.sqrt(tan2)
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + tan2))
    g = np.where(xy2 == 0, 1.0, g)
    vm = v[0] * m[0] + v[1] * m[1] + v[2] * m[2]
    return np.where(vm * v[2] > 0, g, 0.0)


def _fresnel_np(c, eta):
    """Unpolarised dielectric reflectance for c = cos(theta_i) >= 0 on the side of
    relative IOR ``eta`` (transmitted side / incident side); also cos(theta_t) (0 under
    total internal reflection, where the reflectance is 1)."""
    s2t = (1.0 - c * c) / (eta * eta)
    tir = (s2t >= 1.0) | (c <= 0.0)
    ct = np.sqrt(np.maximum(1.0 - s2t, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (c - eta * ct) / (c + eta * ct)
        rp = (eta * c - ct) / (eta * c + ct)
    return np.where(tir, 1.0, 0.5 * (rs * rs + rp * rp)), ct


@lru_cache(maxsize=16)
def _gauss_legendre(n):
    return np.polynomial.legendre.leggauss(n)


class _NormalQuadrature:
    """Quadrature over microfacet normals m for incident directions wi = (sin, 0, mu),
    for integrals of D_wi(m) h(m) with D_wi(m) = G1(wi, m) max(0, wi.m) D(m) / mu, the
    density of visible normals.

    The polar angle of m is parameterised by t, tan(theta_m) = alpha tan(t): the lobe
    then spreads over t in [0, pi/2) for any roughness and D sin(theta_m) dtheta_m/dt
    is bounded and smooth. The azimuth is integrated over pieces bounded by the
    azimuths where wi.m crosses given values (h is even in phi: [0, pi] suffices), so
    cuts such as visibility or total internal reflection are piece ends, not kinks
    inside a piece. Where such a cut reaches phi = 0 or pi (at theta_m = |theta_i -+
    theta_c| for a constant cut wi.m = cos theta_c) the pieces' integrals have kinks in
    theta: t is split into panels there (``theta_breaks``), and at theta_m = pi/4 (at
    grazing incidence visible normals weight steep normals, which the t-parameterisation
    of a small roughness squeezes near t = pi/2). Gauss-Legendre, n points per panel
    and per piece."""

    def __init__(self, kind, alpha, mu, theta_breaks, n):
        self.kind, self.alpha = kind, alpha
        self.x, self.w = _gauss_legendre(n)
        a = alpha
        theta_breaks = list(theta_breaks) + [np.pi / 4]
        breaks = np.clip(np.stack([np.broadcast_to(b, mu.shape) for b in theta_breaks], axis=1), 0.0, np.pi / 2)
        mu = mu[:, None]
        edges = np.sort(np.concatenate([np.zeros_like(mu), breaks, np.full_like(mu, np.pi / 2)], axis=1), axis=1)
        te = np.arctan2(np.sin(edges), a * np.cos(edges))          # the panels' ends in t
        lo, hi = te[:, :-1, None], te[:, 1:, None]
        t = (lo + 0.5 * (hi - lo) * (self.x + 1.0)).reshape(len(mu), -1)
        wt = (0.5 * (hi - lo) * self.w).reshape(len(mu), -1)
        st, ct = np.sin(t), np.cos(t)
        tan_m = a * st / ct
        cos_m = 1.0 / np.sqrt(1.0 + tan_m * tan_m)
        sin_m = tan_m * cos_m
        q = ct * ct + a * a * st * st            # (cos t / cos theta_m)^2
        if kind == BECKMANN:
            # D = exp(-tan^2 theta_m / alpha^2) / (pi alpha^2 cos^4 theta_m)
            with np.errstate(over="ignore", invalid="ignore"):
                d = np.exp(-(st / ct) ** 2) * (1.0 + tan_m * tan_m) ** 2 / (np.pi * a * a)
            d = np.nan_to_num(d, nan=0.0, posinf=0.0)
        else:
            d = q * q / (np.pi * a * a)          # GGX in terms of t
        # D sin(theta_m) dtheta_m/dt dt, dtheta_m/dt = alpha / q
        self.measure = (d * sin_m * a / q * wt)[:, :, None]
        self.sin_m, self.cos_m = sin_m[:, :, None], cos_m[:, :, None]
        mu = mu[:, :, None]
        self.wi = (np.sqrt(np.maximum(1.0 - mu * mu, 0.0)), 0.0 * mu, mu)

    def phi_at(self, c):
        """The azimuth in [0, pi] where wi.m = c (wi.m decreases with phi); 0 if wi.m < c
        for every phi, pi if wi.m > c for every phi."""
        sin_i, _, mu = self.wi
        with np.errstate(divide="ignore", invalid="ignore"):
            r = (c - mu * self.cos_m) / (sin_i * self.sin_m)
        return np.arccos(np.clip(np.nan_to_num(r, nan=-1.0, neginf=-1.0, posinf=1.0), -1.0, 1.0))

    def piece(self, lo, hi):
        """Points m, cosines wi.m and weights (density of visible normals included, both
        halves of the even integrand) for phi in [lo, hi]."""
        phi = lo + 0.5 * (hi - lo) * (self.x + 1.0)
        m = (self.sin_m * np.cos(phi), self.sin_m * np.sin(phi), self.cos_m + 0.0 * phi)
        wi = self.wi
        c = np.maximum(wi[0] * m[0] + wi[2] * m[2], 0.0)
        wgt = self.measure * (hi - lo) * self.w * _g1_np(self.kind, self.alpha, wi, m) * c / wi[2]
        return m, c, wgt


def coating_integrals(kind: str, alpha: float, eta: float, mu, n: int = 32):
    """Directional transmittance T(mu) of the rough interface for light from outside
    (relative IOR ``eta``) and directional reflectance R(mu) for light from inside
    (relative IOR 1 / eta), at the cosines ``mu`` (numpy array), for wi in the xz-plane:

        T(wi) = int D_wi(m) (1 - F(wi.m)) G1(wo_t, m) dm,  wo_t refracted (below)
        R(wi) = int D_wi(m) F'(wi.m) G1(wo_r, m) dm,       wo_r reflected (above)

    with the density of visible normals D_wi (see :class:`_NormalQuadrature`)."""
    alpha = max(float(alpha), 1e-4)   # the clamp every microfacet model applies
    mu = np.asarray(mu, dtype=np.float64)
    theta_i = np.arccos(np.clip(mu, -1.0, 1.0))

    # Transmission from outside. With k = 1 - eta^2 > 0 (optically thinner inside),
    # refraction needs wi.m > sqrt(k), and the refracted direction points down
    # (wo.z < 0) iff g(wi.m) cos(theta_m) < mu, g(c) = c - sqrt(c^2 - k) decreasing:
    # wi.m > (s^2 + k) / (2 s) with s = mu / cos(theta_m), where s < sqrt(k). With
    # eta > 1 every visible normal refracts downwards.
    k = 1.0 - eta * eta
    theta_c = np.arccos(np.sqrt(max(k, 0.0)))
    # (panels also where the cut switches from one form to the other)
    theta_s = np.arccos(np.minimum(1.0, mu / np.sqrt(k))) if k > 0 else 0.0
    quad = _NormalQuadrature(kind, alpha, mu, [np.abs(theta_c - theta_i), theta_c + theta_i, theta_s], n)
    if k > 0:
        s = quad.wi[2] / quad.cos_m
        c_lo = np.where(s < np.sqrt(k), (s * s + k) / (2.0 * s), np.sqrt(k))
    else:
        c_lo = 0.0
    m, c, wgt = quad.piece(0.0, quad.phi_at(c_lo))
    f, cos_t = _fresnel_np(c, eta)
    wo = tuple((c / eta - cos_t) * mc - wc / eta for mc, wc in zip(m, quad.wi))
    h = np.where((wo[2] < 0) & (f < 1.0), (1.0 - f) * _g1_np(kind, alpha, wo, m), 0.0)
    trans = (wgt * h).sum(axis=(1, 2))

    # Reflection from inside: the reflected direction points up iff
    # wi.m > mu / (2 cos(theta_m)) (this cut reaches phi = 0, pi at theta_m =
    # pi/4 -+ theta_i / 2); total internal reflection below wi.m = cos(theta_r),
    # sin(theta_r) = 1 / eta (a kink of F, a separate piece).
    theta_r = np.arccos(np.sqrt(max(0.0, 1.0 - 1.0 / (eta * eta))))
    # (panels also where the two cuts cross, mu / (2 cos(theta_m)) = cos(theta_r))
    theta_x = np.arccos(np.minimum(1.0, mu / (2.0 * max(np.cos(theta_r), 1e-300))))
    quad = _NormalQuadrature(kind, alpha, mu, [np.abs(theta_r - theta_i), theta_r + theta_i, theta_x,
                                               np.pi / 4 - theta_i / 2, np.pi / 4 + theta_i / 2], n)
    c_lo = quad.wi[2] / (2.0 * quad.cos_m)
    split = quad.phi_at(np.maximum(c_lo, np.cos(theta_r)))
    refl = 0.0
    for lo, hi in ((0.0, split), (split, quad.phi_at(c_lo))):
        m, c, wgt = quad.piece(lo, hi)
        f, _ = _fresnel_np(c, 1.0 / eta)
        wo = tuple(2.0 * c * mc - wc for mc, wc in zip(m, quad.wi))
        refl = refl + (wgt * np.where(wo[2] > 0, f * _g1_np(kind, alpha, wo, m), 0.0)).sum(axis=(1, 2))
    return trans, refl


def table_cosines() -> np.ndarray:
    """The cosines of the table's entries (Mitsuba's: linspace(0, 1, 64), first 1e-6)."""
    return np.maximum(np.linspace(0.0, 1.0, TABLE_RES, dtype=np.float32), np.float32(1e-6)).astype(np.float64)


@lru_cache(maxsize=64)
def coating_tables(kind: str, alpha: float, eta: float):
    """(transmittance table over table_cosines(), internal reflectance) of one coating."""
    mu = table_cosines()
    t_ext, r_int = coating_integrals(kind, alpha, eta, mu)
    # R_int is the transmitted side's directional reflectance integrated over the
    # cosine-weighted hemisphere with Mitsuba's rule: 2 * mean(R(mu) mu) over the table.
    return tuple(float(v) for v in t_ext), float(2.0 * np.mean(r_int * mu))


def lerp_table(table, offset, x, active):
    """Linear interpolation in a table of TABLE_RES values over [0, 1] at ``offset``."""
    x = x * (TABLE_RES - 1)
    i = dr.minimum(mi.UInt32(dr.maximum(x, 0.0)), TABLE_RES - 2)
    v0 = dr.gather(mi.Float, table, offset + i, active)
    v1 = dr.gather(mi.Float, table, offset + i + 1, active)
    return dr.lerp(v0, v1, x - mi.Float(i))


# --------------------------------------------------------------------------- family

@BSDF_TYPES.register("roughplastic")
class RoughPlastic(Plastic):
    """``roughplastic``: Mitsuba's rough plastic (isotropic roughness only); the coating's
    transmittance tables are computed per instance at load time.

    ====================  =========  ===============  =======================================================
    name                  type       default          meaning
    ====================  =========  ===============  =======================================================
    int_ior               float|str  'polypropylene'  interior IOR (a number or a Mitsuba name)
    ext_ior               float|str  'air'            exterior IOR
    diffuse_reflectance   texture    0.5              albedo of the diffuse base
    specular_reflectance  texture    1                factor on the specular coating
    nonlinear             bool       false            account for the colour shift of internal scattering
    distribution          string     beckmann         microfacet distribution: 'beckmann' or 'ggx'
    alpha                 texture    0.1              roughness (RMS slope), or anisotropic alpha_u / alpha_v
    sample_visible        bool       true             sample visible normals (else D(m) cos(theta_m))
    ====================  =========  ===============  =======================================================
    """

    name = "roughplastic"
    flags = REFLECTION | DIFFUSE | GLOSSY

    def add(self, loader, props) -> int:
        dist = props.string("distribution", BECKMANN, choices=(BECKMANN, GGX))
        if props.has("alpha") and (props.has("alpha_u") or props.has("alpha_v")):
            raise props.error("alpha", "give either 'alpha' or 'alpha_u'/'alpha_v'")
        if props.has("alpha_u") or props.has("alpha_v"):
            if not (props.has("alpha_u") and props.has("alpha_v")):
                raise props.error("alpha_v" if props.has("alpha_u") else "alpha_u",
                                  "both 'alpha_u' and 'alpha_v' must be given")
            alpha = props.float("alpha_u", min=0.0)
            if props.float("alpha_v", min=0.0) != alpha:
                raise props.error("alpha_u", "roughplastic does not support anisotropic roughness "
                                             "(as Mitsuba's)")
        else:
            alpha = props.float("alpha", 0.1, min=0.0)
        visible = props.bool("sample_visible", True)
        int_ior, ext_ior = lookup_ior(props, "int_ior", "polypropylene"), lookup_ior(props, "ext_ior", "air")
        if int_ior == ext_ior:
            raise props.error("int_ior", f"must differ from ext_ior (both are {int_ior})")
        i = super().add(loader, props)
        inst = self.instances[i]
        alpha32 = float(np.float32(max(alpha, 1e-4)))
        table, r_int = coating_tables(dist, alpha32, float(inst["eta"]))
        inst.update(fdr_int=r_int, alpha=alpha32, table=table, variant=(dist, visible))
        return i

    def build(self) -> None:
        super().build()
        self.alpha = mi.Float([i["alpha"] for i in self.instances])
        self.table = mi.Float(np.concatenate([np.asarray(i["table"], np.float32) for i in self.instances]))
        self.variants = sorted({i["variant"] for i in self.instances})
        self.variant = mi.UInt32([self.variants.index(i["variant"]) for i in self.instances])

    # -- the glossy lobe, per microfacet variant (one kernel branch per variant in use)
    def _variant_mask(self, idx, active):
        if len(self.variants) == 1:
            return None
        return dr.gather(mi.UInt32, self.variant, idx, active)

    def _glossy(self, wi, wo, eta, alpha, vid):
        """(F D G / (4 cos_i), density of sampling wo through the glossy lobe).

        wi.m = wo.m = |wi + wo| / 2 for the half vector m: that length is used rather
        than the dot products, which at grazing angles (wi, wo nearly opposite) carry
        the float32 error of the half vector's direction; the visible-normal density
        D G1(wi) (wi.m) / cos_i / (4 wo.m) is written with wi.m / wo.m cancelled, as
        in Mitsuba."""
        h = wi + wo
        h_len = dr.norm(h)
        m = h / h_len
        cos_h = 0.5 * h_len
        f_r = fresnel_dielectric(cos_h, eta)[0]
        val, pdf = mi.Float(0.0), mi.Float(0.0)
        for k, (dist, visible) in enumerate(self.variants):
            md = Microfacet(dist, alpha, alpha, visible)
            D, g1_i = md.D(m), md.G1(wi, m)
            v = f_r * D * g1_i * md.G1(wo, m) / (4.0 * wi.z)
            if md.sample_visible:
                p = D * g1_i / (4.0 * wi.z)
            else:
                p = D * m.z / (4.0 * cos_h)    # D(m) cos(theta_m) / (4 wo.m)
            if vid is None:
                return v, p
            val, pdf = dr.select(vid == k, v, val), dr.select(vid == k, p, pdf)
        return val, pdf

    def _sample_normal(self, wi, u2, alpha, vid):
        m = mi.Vector3f(0.0, 0.0, 1.0)
        for k, (dist, visible) in enumerate(self.variants):
            mk = Microfacet(dist, alpha, alpha, visible).sample(wi, u2)[0]
            if vid is None:
                return mk
            m = dr.select(vid == k, mk, m)
        return m

    def _coating(self, ctx, idx, active):
        eta, r_int, sw = self._params(ctx, idx, active)
        alpha = dr.gather(mi.Float, self.alpha, idx, active)
        vid = self._variant_mask(idx, active)
        offset = idx * TABLE_RES
        t_i = lerp_table(self.table, offset, ctx.si.wi.z, active)
        # Plastic's lobe choice with the Fresnel reflectance replaced by 1 - T(cos_i)
        p_spec = self._prob_specular(1.0 - t_i, sw)
        return eta, r_int, alpha, vid, offset, t_i, p_spec

    def _eval_pdf(self, ctx, idx, wo, coating, active):
        eta, r_int, alpha, vid, offset, t_i, p_spec = coating
        wi = ctx.si.wi
        ok = active & (wi.z > 0) & (wo.z > 0)
        g_val, g_pdf = self._glossy(wi, wo, eta, alpha, vid)
        spec = self._tex("spec", ctx, idx, ok)
        t_o = lerp_table(self.table, offset, wo.z, ok)
        # Plastic's diffuse term with (1 - F) at both crossings replaced by T.
        diffuse = self._diffuse_term(ctx, idx, eta, r_int, 1.0 - t_i, 1.0 - t_o, ok) * (dr.inv_pi * wo.z)
        f = spec * g_val + diffuse
        pdf = p_spec * g_pdf + (1.0 - p_spec) * cosine_hemisphere_pdf(wo)
        ok &= dr.isfinite(pdf) & dr.isfinite(g_val)
        return dr.select(ok, f, 0.0), dr.select(ok, pdf, 0.0)

    def eval_pdf(self, ctx, idx, wo, active):
        ok = active & (ctx.si.wi.z > 0)
        return self._eval_pdf(ctx, idx, wo, self._coating(ctx, idx, ok), active)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        ok = active & (ctx.si.wi.z > 0)
        return self._sample(ctx, idx, u1, u2, self._coating(ctx, idx, ok), ok)

    def _sample(self, ctx, idx, u1, u2, coating, ok) -> BSDFSample:
        """The glossy lobe (a microfacet normal, reflected) with probability p_spec,
        else the cosine-weighted diffuse lobe; the weight is the mixture's f / pdf."""
        wi = ctx.si.wi
        alpha, vid, p_spec = coating[2], coating[3], coating[6]
        glossy = u1 < p_spec
        m = self._sample_normal(wi, u2, alpha, vid)
        wo = dr.select(glossy, reflect_about(wi, m), square_to_cosine_hemisphere(u2))
        f, pdf = self._eval_pdf(ctx, idx, wo, coating, ok)
        ok &= pdf > 0
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), mi.Float(1.0), mi.Bool(False),
                          dr.select(ok, f / pdf, 0.0))

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        # One coating lookup (parameters, T(cos_i), lobe choice) for both queries.
        ok = active & (ctx.si.wi.z > 0)
        coating = self._coating(ctx, idx, ok)
        f, pdf = self._eval_pdf(ctx, idx, wo, coating, active)
        return f, pdf, self._sample(ctx, idx, u1, u2, coating, ok)
