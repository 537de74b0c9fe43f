"""``principled`` and ``principledthin``: Mitsuba 3's Disney-style BSDFs (Burley 2012/2015),
with Mitsuba's lobes, sampling rates and conventions. The lobes and the measured
differences: docs/materials.md.
"""

from __future__ import annotations

import numbers

import drjit as dr
import mitsuba as mi

from ..plugins.props import ALBEDO, IOR, UNIT, Range
from ..sampling import cosine_hemisphere_pdf, square_to_cosine_hemisphere
from ..spectrum import cie_xyz, clamp_keep_grad
from ..textures import load_spectrum
from .base import BSDF_TYPES, BSDFSample, BSDFType, DIFFUSE, GLOSSY, REFLECTION, TRANSMISSION
from .fresnel import fresnel_dielectric, reflect_about, refract_about
from .microfacet import GGX, Microfacet

_NONE = 0xFFFFFFFF  # no texture: the parameter is off for this instance (value 0)


# --------------------------------------------------------------------- helpers

def _schlick_weight(c):
    m = dr.clip(1.0 - c, 0.0, 1.0)
    m2 = m * m
    return m2 * m2 * m


def _schlick(r0, cos_i, eta):
    """Schlick's Fresnel with normal reflectance ``r0``; for light leaving the denser
    side the weight uses the refracted angle (1 where totally reflected)."""
    outside = cos_i >= 0
    eta_it = dr.select(outside, eta, dr.rcp(eta))
    eta_ti = dr.rcp(eta_it)
    cos_t = dr.safe_sqrt(1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti)
    w = dr.select(eta_it > 1, _schlick_weight(dr.abs(cos_i)), _schlick_weight(cos_t))
    return r0 + (1.0 - r0) * w


def _r0(eta):
    return dr.square((eta - 1.0) / (eta + 1.0))


def _alphas(anisotropic, roughness, has_aniso: bool):
    # Mitsuba's floor of 0.001 on alpha, keeping the derivative below it (the floor is
    # numerical; an optimisation may start at roughness 0).
    r2 = roughness * roughness
    if not has_aniso:
        a = clamp_keep_grad(r2, 0.001)
        return a, a
    aspect = dr.sqrt(1.0 - 0.9 * anisotropic)
    return clamp_keep_grad(r2 / aspect, 0.001), clamp_keep_grad(r2 * aspect, 0.001)


def _luminance(spectrum, lam):
    """Mitsuba's luminance of a sampled spectrum: mean of y(lambda) * value."""
    y = cie_xyz(lam)[1] * spectrum
    return sum(y[k] for k in range(len(y))) * (1.0 / len(y))


def _tint(base, lum):
    return dr.select(lum > 0, base / dr.select(lum > 0, lum, 1.0), 1.0)


class _GTR1:
    """Burley's GTR1 ("Berry") distribution of the clearcoat, isotropic, sampled in
    proportion to D(m) cos(theta_m)."""

    def __init__(self, alpha):
        self.a2 = alpha * alpha

    def D(self, m):
        c2 = m.z * m.z
        r = (self.a2 - 1.0) / (dr.pi * dr.log(self.a2) * (1.0 + (self.a2 - 1.0) * c2))
        return dr.select(r * m.z > 1e-20, r, 0.0)

    def pdf(self, m):
        return dr.select(m.z < 0, 0.0, m.z * self.D(m))

    def sample(self, u):
        s, c = dr.sincos(2.0 * dr.pi * u.x)
        cos2 = (1.0 - dr.power(self.a2, 1.0 - u.y)) / (1.0 - self.a2)
        sin_t, cos_t = dr.sqrt(dr.maximum(1.0 - cos2, 0.0)), dr.sqrt(dr.maximum(cos2, 0.0))
        return mi.Vector3f(c * sin_t, s * sin_t, cos_t)


def _compatible(m, wi, wo, cos_i, reflection: bool):
    """Both directions on the sides of microfacet m that their macro sides imply."""
    ms = dr.mulsign(m, cos_i)
    ok = dr.dot(wi, ms) > 0
    return ok & (dr.dot(wo, ms) > 0 if reflection else dr.dot(wo, ms) < 0)


def _burley_diffuse(cos_i, cos_o, cos_d, roughness, flatness):
    """Burley's diffuse (with retro-reflection), blended with the fake subsurface term
    by ``flatness`` when given (None: off). Multiply by base_color / pi."""
    fo, fi = _schlick_weight(dr.abs(cos_o)), _schlick_weight(dr.abs(cos_i))
    f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
    rr = 2.0 * roughness * cos_d * cos_d
    f = f_diff + rr * (fo + fi + fo * fi * (rr - 1.0))
    if flatness is None:
        return f
    fss90 = 0.5 * rr
    fss = (1.0 + (fss90 - 1.0) * fo) * (1.0 + (fss90 - 1.0) * fi)
    f_ss = 1.25 * (fss * (1.0 / (dr.abs(cos_o) + dr.abs(cos_i)) - 0.5) + 0.5)
    return dr.lerp(f, f_ss, flatness)


def _is_off(v) -> bool:
    """Mitsuba's lobe flag: a parameter is off when absent or a float equal to 0."""
    return v is None or (isinstance(v, numbers.Real) and not isinstance(v, bool) and float(v) == 0.0)


class _Params:
    """Per-hit parameter values (plain attributes)."""


# ---------------------------------------------------------------- shared family

class _PrincipledFamily(BSDFType):
    refracts = True
    # (name, default) of textures always present, and of optional lobe parameters.
    _ALWAYS: tuple = ()
    _OPTIONAL: tuple = ()
    _RATES: tuple = ()
    _UNBOUNDED: tuple = ()
    # The parameters' ranges (Mitsuba's documented ones); the others are fractions in [0, 1].
    _RANGES = {"base_color": ALBEDO, "eta": IOR, "diff_trans": Range(0.0, 2.0)}

    def _parse(self, loader, props, inst: dict) -> None:
        for name, default in self._ALWAYS:
            # Every parameter but base_color is a float (Mitsuba reads it with eval_1).
            inst[name] = load_spectrum(loader, props.raw(name, default), props.key(name), emitter=False,
                                       unbounded=name in self._UNBOUNDED, valid=self._RANGES.get(name, UNIT),
                                       scalar=name != "base_color")
        for name in self._OPTIONAL:
            v = props.raw(name)
            inst[name] = None if _is_off(v) else load_spectrum(loader, v, props.key(name), emitter=False,
                                                               valid=self._RANGES.get(name, UNIT), scalar=True)
        for name in self._RATES:
            inst[name] = props.float(name, 1.0, min=0.0)

    def add(self, loader, props) -> int:
        inst: dict = {}
        self._parse(loader, props, inst)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self) -> None:
        self.slots = {}
        self.reach = {}
        for name, _ in self._ALWAYS:
            self.slots[name] = mi.UInt32([i[name] for i in self.instances])
            self.reach[name] = tuple(i[name] for i in self.instances)
        self.has = {}
        for name in self._OPTIONAL:
            s = [i[name] for i in self.instances]
            self.has[name] = any(x is not None for x in s)
            if self.has[name]:
                self.slots[name] = (mi.UInt32([_NONE if x is None else x for x in s]), any(x is None for x in s))
                self.reach[name] = tuple(x for x in s if x is not None)
        self.rates = {n: mi.Float([i[n] for i in self.instances]) for n in self._RATES}

    # -- parameter lookup ------------------------------------------------------------
    def _eval(self, name, ctx, idx, active, spectral=False):
        """Texture ``name`` at this hit (first wavelength unless ``spectral``); 0 for
        instances where an optional parameter is off; None if no instance sets it."""
        entry = self.slots.get(name)
        if entry is None:
            return None
        table, some_off = entry if isinstance(entry, tuple) else (entry, False)
        slot = dr.gather(mi.UInt32, table, idx, active)
        on = active & (slot != _NONE) if some_off else active
        v = self.textures.eval(slot, ctx.si, ctx.wl.lambda_, on, illuminant=False, reach=self.reach[name])
        if not spectral:
            v = v[0]
        return dr.select(slot != _NONE, v, 0.0) if some_off else v

    def _rate(self, name, idx, active):
        return dr.gather(mi.Float, self.rates[name], idx, active)

    # -- interface ---------------------------------------------------------------------
    def eval_pdf(self, ctx, idx, wo, active):
        p = self._params(ctx, idx, active)
        return self._eval_pdf(p, ctx.si.wi, wo, active)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        p = self._params(ctx, idx, active)
        return self._sample(p, ctx.si.wi, u1, u2, active)

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        p = self._params(ctx, idx, active)
        f, pdf = self._eval_pdf(p, ctx.si.wi, wo, active)
        return f, pdf, self._sample(p, ctx.si.wi, u1, u2, active)

    def _finish_sample(self, p, wi, wo, eta, ok):
        """Mitsuba's sample: the density and value of the mixture at the sampled wo."""
        f, pdf = self._eval_pdf(p, wi, wo, ok)
        ok = ok & (pdf > 0)
        w = f / dr.select(ok, pdf, 1.0)
        ok &= dr.all(dr.isfinite(w))
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), dr.select(ok, eta, 1.0), mi.Bool(False),
                          dr.select(ok, w, 0.0))


# ------------------------------------------------------------------- principled

@BSDF_TYPES.register("principled")
class Principled(_PrincipledFamily):
    """``principled``: Mitsuba's Disney-style BSDF (its lobes: docs/materials.md).
    Optional lobe parameters are off when not given.

    =================================  =======  =======  ========================================================
    name                               type     default  meaning
    =================================  =======  =======  ========================================================
    base_color                         texture  0.5      base colour
    roughness                          texture  0.5      perceptual roughness (alpha = roughness^2)
    anisotropic                        texture  off      anisotropy of the specular lobes, in [0, 1]
    metallic                           texture  off      metal fraction
    spec_trans                         texture  off      specular transmission fraction
    eta                                float    -        IOR of the dielectric lobes (instead of specular)
    specular                           float    0.5      specular amount: eta = 2 / (1 - sqrt(0.08 specular)) - 1
    spec_tint                          texture  off      tint of the dielectric reflection toward base_color
    sheen                              texture  off      sheen amount
    sheen_tint                         texture  off      tint of the sheen toward base_color
    flatness                           texture  off      blend of Burley diffuse toward a fake subsurface
    clearcoat                          texture  off      clearcoat amount
    clearcoat_gloss                    texture  off      clearcoat glossiness (GTR1 alpha 0.1 -> 0.001)
    main_specular_sampling_rate        float    1        relative sampling rate of the main specular lobes
    clearcoat_sampling_rate            float    1        relative sampling rate of the clearcoat
    diffuse_reflectance_sampling_rate  float    1        relative sampling rate of the diffuse lobe
    =================================  =======  =======  ========================================================
    """

    name = "principled"
    flags = REFLECTION | TRANSMISSION | DIFFUSE | GLOSSY
    _ALWAYS = (("base_color", 0.5), ("roughness", 0.5))
    _OPTIONAL = ("anisotropic", "spec_trans", "sheen", "sheen_tint", "flatness", "spec_tint", "metallic",
                 "clearcoat", "clearcoat_gloss")
    _RATES = ("main_specular_sampling_rate", "clearcoat_sampling_rate", "diffuse_reflectance_sampling_rate")

    def add(self, loader, props) -> int:
        inst: dict = {}
        self._parse(loader, props, inst)
        if props.has("eta") and props.has("specular"):
            raise props.error("eta", "give either 'eta' or 'specular', not both")
        trans = inst["spec_trans"] is not None
        if props.has("eta"):
            eta = props.float("eta", min=1e-6)
            if trans and eta == 1.0:
                eta = 1.001  # index-matched transmission has no half vector
        else:
            spec = props.float("specular", 0.5, min=0.0, max=12.4)
            if trans and spec == 0.0:
                spec = 1e-3
            eta = 2.0 / (1.0 - (0.08 * spec) ** 0.5) - 1.0
        inst["eta"] = eta
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self) -> None:
        super().build()
        self.eta = mi.Float([i["eta"] for i in self.instances])
        self.flags = REFLECTION | DIFFUSE | GLOSSY | (TRANSMISSION if self.has["spec_trans"] else 0)

    def _params(self, ctx, idx, active):
        p = _Params()
        h = self.has
        p.base = self._eval("base_color", ctx, idx, active, spectral=True)
        p.roughness = self._eval("roughness", ctx, idx, active)
        zero = mi.Float(0.0)
        for n in self._OPTIONAL:
            setattr(p, n, self._eval(n, ctx, idx, active) if h[n] else zero)
        p.eta = dr.gather(mi.Float, self.eta, idx, active)
        p.rate_spec = self._rate("main_specular_sampling_rate", idx, active)
        p.rate_cc = self._rate("clearcoat_sampling_rate", idx, active)
        p.rate_diff = self._rate("diffuse_reflectance_sampling_rate", idx, active)
        p.lum = (_luminance(p.base, ctx.wl.lambda_) if (h["spec_tint"] or h["sheen_tint"]) else None)
        p.brdf = (1.0 - p.metallic) * (1.0 - p.spec_trans)
        p.bsdf = (1.0 - p.metallic) * p.spec_trans
        p.dist = Microfacet(GGX, *_alphas(p.anisotropic, p.roughness, h["anisotropic"]))
        p.cc_dist = _GTR1(dr.lerp(0.1, 0.001, p.clearcoat_gloss)) if h["clearcoat"] else None
        return p

    def _probs(self, p, front, F):
        """Normalised lobe probabilities (diffuse, clearcoat, transmission, reflection)."""
        h = self.has
        p_r = dr.select(front, p.rate_spec * (1.0 - p.bsdf * (1.0 - F)), F)
        p_t = dr.select(front, p.rate_spec * p.bsdf * (1.0 - F), 1.0 - F) if h["spec_trans"] else mi.Float(0.0)
        p_c = dr.select(front, 0.25 * p.clearcoat * p.rate_cc, 0.0) if h["clearcoat"] else mi.Float(0.0)
        p_d = dr.select(front, p.brdf * p.rate_diff, 0.0)
        inv = dr.rcp(p_r + p_t + p_c + p_d)
        return p_d * inv, p_c * inv, p_t * inv, p_r * inv

    def _fresnel(self, p, F, cos_ih, front):
        """Mitsuba's blend of dielectric, metallic and tinted Fresnel (front side); the
        dielectric Fresnel scaled by the transmission weight from inside."""
        h = self.has
        if not (h["metallic"] or h["spec_tint"]):
            front_f = mi.Spectrum(F)
        else:
            fs = mi.Spectrum(0.0)
            if h["metallic"]:
                fs += p.metallic * _schlick(p.base, cos_ih, p.eta)
            if h["spec_tint"]:
                eta_it = dr.select(cos_ih >= 0, p.eta, dr.rcp(p.eta))
                fs += (1.0 - p.metallic) * p.spec_tint * _schlick(_tint(p.base, p.lum) * _r0(eta_it), cos_ih, p.eta)
            front_f = (1.0 - p.metallic) * (1.0 - p.spec_tint) * F + fs
        return dr.select(front, front_f, mi.Spectrum(p.bsdf * F))

    def _eval_pdf(self, p, wi, wo, active):
        h = self.has
        cos_i, cos_o = wi.z, wo.z
        front = cos_i > 0
        active = active & (cos_i != 0) & (front | (p.bsdf > 0))
        refl, refr = cos_i * cos_o > 0, cos_i * cos_o < 0
        eta_path = dr.select(front, p.eta, dr.rcp(p.eta))
        wh = dr.normalize(wi + wo * dr.select(refl, 1.0, eta_path))
        wh = dr.mulsign(wh, wh.z)
        d_i, d_o = dr.dot(wi, wh), dr.dot(wo, wh)
        F = fresnel_dielectric(d_i, p.eta)[0]
        ok_r = _compatible(wh, wi, wo, cos_i, True)
        ok_t = _compatible(wh, wi, wo, cos_i, False)
        dist = p.dist
        D, G = dist.D(wh), dist.G(wi, wo, wh)

        # Value (f |cos_o|).
        on = active & refl & ok_r & (F > 0)
        value = dr.select(on, self._fresnel(p, F, d_i, front) * (D * G / (4.0 * dr.abs(cos_i))), 0.0)
        if h["spec_trans"]:
            on = active & (p.bsdf > 0) & refr & ok_t & (F < 1)
            den = d_i + eta_path * d_o
            # eta_path^2 of the Jacobian cancels the radiance scale 1 / eta_path^2.
            t = p.bsdf * dr.abs((1.0 - F) * D * G * d_i * d_o / (cos_i * den * den))
            value += dr.select(on, dr.sqrt(p.base) * t, 0.0)
        if h["clearcoat"]:
            on = active & (p.clearcoat > 0) & refl & ok_r & front
            g_cc = Microfacet(GGX, mi.Float(0.25), mi.Float(0.25)).G(wi, wo, wh)
            cc = 0.25 * p.clearcoat * _schlick(0.04, d_i, p.eta) * p.cc_dist.D(wh) * g_cc * dr.abs(cos_o)
            value += dr.select(on, cc, 0.0)
        on = active & (p.brdf > 0) & refl & front
        f_d = _burley_diffuse(cos_i, cos_o, d_o, p.roughness, p.flatness if h["flatness"] else None)
        value += dr.select(on, p.base * (p.brdf * dr.abs(cos_o) * dr.inv_pi * f_d), 0.0)
        if h["sheen"]:
            on = active & (p.sheen > 0) & refl & (1.0 - p.metallic > 0) & front
            s = p.sheen * (1.0 - p.metallic) * _schlick_weight(dr.abs(d_o)) * dr.abs(cos_o)
            c = dr.lerp(1.0, _tint(p.base, p.lum), p.sheen_tint) if h["sheen_tint"] else 1.0
            value += dr.select(on, c * s, 0.0)

        # Density of the lobe mixture.
        pr_d, pr_c, pr_t, pr_r = self._probs(p, front, F)
        if h["spec_trans"]:
            jac_t = eta_path * eta_path * d_o / dr.square(d_i + eta_path * d_o)
            jac = dr.abs(dr.select(refl, dr.rcp(4.0 * d_o), jac_t))
        else:
            jac = dr.abs(dr.rcp(4.0 * d_o))
        wi_up = dr.mulsign(wi, cos_i)
        pdf_m = dist.pdf(wi_up, wh)
        on_r = refl & ok_r
        pdf = dr.select(on_r, pr_r * pdf_m * jac, 0.0)
        pdf += dr.select(refl, pr_d * cosine_hemisphere_pdf(dr.mulsign(wo, cos_i)), 0.0)
        if h["spec_trans"]:
            pdf += dr.select(refr & ok_t, pr_t * pdf_m * jac, 0.0)
        if h["clearcoat"]:
            pdf += dr.select(on_r, pr_c * p.cc_dist.pdf(wh) * jac, 0.0)
        ok = active & dr.isfinite(pdf) & dr.all(dr.isfinite(value))
        return dr.select(ok, value, 0.0), dr.select(ok, pdf, 0.0)

    def _sample(self, p, wi, u1, u2, active) -> BSDFSample:
        h = self.has
        cos_i = wi.z
        front = cos_i > 0
        active = active & (cos_i != 0) & (front | (p.bsdf > 0))
        m, _ = p.dist.sample(dr.mulsign(wi, cos_i), u2)
        F, cos_t, eta_it, eta_ti = fresnel_dielectric(dr.dot(wi, m), p.eta)
        pr_d, pr_c, pr_t, _ = self._probs(p, front, F)
        sel_d = u1 < pr_d
        sel_c = (u1 >= pr_d) & (u1 < pr_d + pr_c) if h["clearcoat"] else mi.Bool(False)
        sel_t = (u1 >= pr_d + pr_c) & (u1 < pr_d + pr_c + pr_t) if h["spec_trans"] else mi.Bool(False)
        sel_r = ~(sel_d | sel_c | sel_t)

        wo = reflect_about(wi, m)
        ok = ~sel_r | (_compatible(m, wi, wo, cos_i, True) & (cos_i * wo.z > 0))
        if h["spec_trans"]:
            wo_t = refract_about(wi, m, cos_t, eta_ti)
            wo = dr.select(sel_t, wo_t, wo)
            ok &= ~sel_t | (_compatible(m, wi, wo_t, cos_i, False) & (cos_i * wo_t.z < 0))
        if h["clearcoat"]:
            m_c = p.cc_dist.sample(u2)
            wo_c = reflect_about(wi, m_c)
            wo = dr.select(sel_c, wo_c, wo)
            ok &= ~sel_c | (_compatible(m_c, wi, wo_c, cos_i, True) & (cos_i * wo_c.z > 0))
        wo_d = square_to_cosine_hemisphere(u2)
        wo = dr.select(sel_d, wo_d, wo)
        ok &= ~sel_d | (cos_i * wo_d.z > 0)
        eta = dr.select(sel_t, eta_it, 1.0)
        return self._finish_sample(p, wi, wo, eta, active & ok)


# --------------------------------------------------------------- principledthin

@BSDF_TYPES.register("principledthin")
class PrincipledThin(_PrincipledFamily):
    """``principledthin``: Mitsuba's thin-sheet variant of ``principled`` (no metal, no
    clearcoat; adds diffuse transmission).

    ====================================  =======  =======  ================================================
    name                                  type     default  meaning
    ====================================  =======  =======  ================================================
    base_color                            texture  0.5      base colour
    roughness                             texture  0.5      perceptual roughness
    eta                                   texture  1.5      IOR of the sheet
    anisotropic                           texture  off      anisotropy of the specular lobes
    spec_trans                            texture  off      specular transmission fraction
    spec_tint                             texture  off      tint of the specular reflection
    sheen                                 texture  off      sheen amount
    sheen_tint                            texture  off      tint of the sheen
    flatness                              texture  off      blend of Burley diffuse toward a fake subsurface
    diff_trans                            texture  off      diffuse transmission fraction, in [0, 2]
    specular_reflectance_sampling_rate    float    1        relative sampling rates of the four lobes
    specular_transmittance_sampling_rate  float    1
    diffuse_transmittance_sampling_rate   float    1
    diffuse_reflectance_sampling_rate     float    1
    ====================================  =======  =======  ================================================
    """

    name = "principledthin"
    flags = REFLECTION | TRANSMISSION | DIFFUSE | GLOSSY
    _ALWAYS = (("base_color", 0.5), ("roughness", 0.5), ("eta", 1.5))
    _UNBOUNDED = ("eta",)
    _OPTIONAL = ("anisotropic", "spec_trans", "sheen", "sheen_tint", "flatness", "spec_tint", "diff_trans")
    _RATES = ("specular_reflectance_sampling_rate", "specular_transmittance_sampling_rate",
              "diffuse_transmittance_sampling_rate", "diffuse_reflectance_sampling_rate")

    def build(self) -> None:
        super().build()
        self.flags = REFLECTION | DIFFUSE | (GLOSSY if self.has["spec_trans"] else 0) | (
            TRANSMISSION if (self.has["spec_trans"] or self.has["diff_trans"]) else 0)

    def _params(self, ctx, idx, active):
        p = _Params()
        h = self.has
        p.base = self._eval("base_color", ctx, idx, active, spectral=True)
        p.roughness = self._eval("roughness", ctx, idx, active)
        p.eta = self._eval("eta", ctx, idx, active)
        zero = mi.Float(0.0)
        for n in self._OPTIONAL:
            setattr(p, n, self._eval(n, ctx, idx, active) if h[n] else zero)
        p.diff_trans = p.diff_trans * 0.5   # given in 0..2
        p.rate_sr = self._rate("specular_reflectance_sampling_rate", idx, active)
        p.rate_st = self._rate("specular_transmittance_sampling_rate", idx, active)
        p.rate_dt = self._rate("diffuse_transmittance_sampling_rate", idx, active)
        p.rate_dr = self._rate("diffuse_reflectance_sampling_rate", idx, active)
        p.lum = (_luminance(p.base, ctx.wl.lambda_) if (h["spec_tint"] or h["sheen_tint"]) else None)
        aniso = h["anisotropic"]
        p.dist = Microfacet(GGX, *_alphas(p.anisotropic, p.roughness, aniso))
        p.dist_t = Microfacet(GGX, *_alphas(p.anisotropic, (0.65 * p.eta - 0.35) * p.roughness, aniso))
        return p

    def _probs(self, p):
        """Normalised probabilities (specular reflection, specular transmission,
        diffuse reflection, diffuse transmission)."""
        h = self.has
        zero = mi.Float(0.0)
        p_sr = p.spec_trans * p.rate_sr * 0.5 if h["spec_trans"] else zero
        p_st = p.spec_trans * p.rate_st * 0.5 if h["spec_trans"] else zero
        p_dr = p.rate_dr * (1.0 - p.spec_trans) * (1.0 - p.diff_trans)
        p_dt = p.rate_dt * (1.0 - p.spec_trans) * p.diff_trans if h["diff_trans"] else zero
        inv = dr.rcp(p_sr + p_st + p_dr + p_dt)
        return p_sr * inv, p_st * inv, p_dr * inv, p_dt * inv

    def _eval_pdf(self, p, wi_s, wo_s, active):
        h = self.has
        active = active & (wi_s.z != 0)
        # A sheet: work on the side of wi (the model is symmetric).
        wi, wo = dr.mulsign(wi_s, wi_s.z), dr.mulsign(wo_s, wi_s.z)
        cos_i, cos_o = wi.z, wo.z
        refl, refr = cos_o > 0, cos_o < 0
        wo_r = mi.Vector3f(wo.x, wo.y, dr.abs(wo.z))   # transmission: mirror back up
        wh = dr.normalize(wi + wo_r)
        ok_r = _compatible(wh, wi, wo, cos_i, True)
        ok_t = _compatible(wh, wi, wo, cos_i, False)
        d_i, d_o = dr.dot(wi, wh), dr.dot(wo, wh)

        value = mi.Spectrum(0.0)
        if h["spec_trans"]:
            F = fresnel_dielectric(d_i, p.eta)[0]
            on = active & (p.spec_trans > 0) & refl & ok_r
            if h["spec_tint"]:
                fs = _schlick(_tint(p.base, p.lum) * _r0(p.eta), d_i, p.eta)
                f_thin = dr.lerp(mi.Spectrum(F), fs, p.spec_tint)
            else:
                f_thin = mi.Spectrum(F * (1.0 - p.spec_tint))
            value += dr.select(on, f_thin * (p.spec_trans * p.dist.D(wh) * p.dist.G(wi, wo, wh) / (4.0 * cos_i)), 0.0)
            on = active & (p.spec_trans > 0) & refr & ok_t
            t = p.spec_trans * (1.0 - F) * p.dist_t.D(wh) * p.dist_t.G(wi, wo, wh) / (4.0 * cos_i)
            value += dr.select(on, p.base * t, 0.0)
        on = active & refl & (p.spec_trans < 1) & (p.diff_trans < 1)
        f_d = _burley_diffuse(cos_i, cos_o, d_o, p.roughness, p.flatness if h["flatness"] else None)
        w_d = (1.0 - p.spec_trans) * (1.0 - p.diff_trans) * dr.abs(cos_o)
        value += dr.select(on, p.base * (w_d * dr.inv_pi * f_d), 0.0)
        if h["sheen"]:
            s = p.sheen * _schlick_weight(dr.abs(d_o)) * w_d
            c = dr.lerp(1.0, _tint(p.base, p.lum), p.sheen_tint) if h["sheen_tint"] else 1.0
            value += dr.select(on, c * s, 0.0)
        if h["diff_trans"]:
            on = active & refr & (p.spec_trans < 1) & (p.diff_trans > 0)
            value += dr.select(on, p.base * ((1.0 - p.spec_trans) * p.diff_trans * dr.inv_pi * dr.abs(cos_o)), 0.0)

        pr_sr, pr_st, pr_dr, pr_dt = self._probs(p)
        pdf = dr.select(refl, pr_dr * cos_o * dr.inv_pi, 0.0)
        if h["diff_trans"]:
            pdf += dr.select(refr, pr_dt * -cos_o * dr.inv_pi, 0.0)
        if h["spec_trans"]:
            jac = dr.abs(dr.rcp(4.0 * dr.dot(wo_r, wh)))
            pdf += dr.select(refl & ok_r, pr_sr * p.dist.pdf(wi, wh) * jac, 0.0)
            pdf += dr.select(refr & ok_t, pr_st * p.dist_t.pdf(wi, wh) * jac, 0.0)
        ok = active & dr.isfinite(pdf) & dr.all(dr.isfinite(value))
        return dr.select(ok, value, 0.0), dr.select(ok, pdf, 0.0)

    def _sample(self, p, wi_s, u1, u2, active) -> BSDFSample:
        h = self.has
        active = active & (wi_s.z != 0)
        wi = dr.mulsign(wi_s, wi_s.z)
        pr_sr, pr_st, pr_dr, _ = self._probs(p)
        wo = square_to_cosine_hemisphere(u2)
        ok = mi.Bool(True)
        if h["spec_trans"]:
            sel_sr = u1 < pr_sr
            sel_st = (u1 >= pr_sr) & (u1 < pr_sr + pr_st)
            m_r, _ = p.dist.sample(wi, u2)
            wo_r = reflect_about(wi, m_r)
            m_t, _ = p.dist_t.sample(wi, u2)
            wo_t = reflect_about(wi, m_t)
            wo_t = mi.Vector3f(wo_t.x, wo_t.y, -wo_t.z)
            ok &= ~sel_sr | (_compatible(m_r, wi, wo_r, wi.z, True) & (wo_r.z > 0))
            ok &= ~sel_st | (_compatible(m_t, wi, wo_t, wi.z, False) & (wo_t.z < 0))
            wo = dr.select(sel_sr, wo_r, dr.select(sel_st, wo_t, wo))
            spec = sel_sr | sel_st
        else:
            spec = mi.Bool(False)
        if h["diff_trans"]:
            sel_dt = ~spec & (u1 >= pr_sr + pr_st + pr_dr)
            wo = dr.select(sel_dt, -wo, wo)
        wo = dr.mulsign(wo, wi_s.z)
        return self._finish_sample(p, wi_s, wo, mi.Float(1.0), active & ok)
