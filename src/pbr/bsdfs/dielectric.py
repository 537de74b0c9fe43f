"""Dielectric interfaces, as Mitsuba 3's plugins of the same names and parameters:
``dielectric`` (smooth), ``thindielectric`` (a thin slab) and ``roughdielectric``
(Walter et al.'s microfacet refraction model).

Conventions (Mitsuba's): ``eta = int_ior / ext_ior``; the shading normal (+z) points to
the exterior, so ``wi.z < 0`` means the path arrives from inside. ``BSDFSample.eta`` is
the relative IOR crossed along the path (``eta_it``, 1 for reflection). Weights and
values are for radiance transport (paths traced from the camera): crossing into a
medium of relative IOR ``eta_it`` scales radiance by ``1 / eta_it^2``, so transmitted
weights carry that factor and ``weight * eta_it^2`` is the energy that crossed.

The optional ``specular_reflectance`` / ``specular_transmittance`` textures are only
evaluated in kernels of families where some instance sets them.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

import numpy as np

from ..spectrum import LAMBDA_MAX, LAMBDA_MIN, SELLMEIER, sellmeier_ior
from ..textures import add_tabulated, load_spectrum
from ..plugins.params import ParamOwner, param_table
from ..plugins.props import IOR, ROUGHNESS
from .base import BSDF_TYPES, BSDFSample, BSDFType, GLOSSY, REFLECTION, SPECULAR, TRANSMISSION
from .fresnel import fresnel_dielectric, lookup_ior, reflect, reflect_about, refract, refract_about
from .microfacet import (BECKMANN, GGX, REGULARIZED_ALPHA, REGULARIZED_VARIANT, Microfacet, VariantTable,
                         regularized_alpha)

_NO_TEXTURE = 0xFFFFFFFF


def _ior_spectrum(loader, props, name: str, default: str):
    """An IOR: a float (number or Mitsuba name) or, for dispersion, a texture slot of a
    wavelength-dependent IOR (a ``spectrum`` dict, or a Sellmeier glass name such as
    'glass-BK7'). Returns (float or None, slot or None)."""
    v = props.raw(name, default)
    if isinstance(v, str) and v.strip().lower() in SELLMEIER:
        grid = np.arange(int(LAMBDA_MIN), int(LAMBDA_MAX) + 1, dtype=np.float64)
        return None, add_tabulated(loader, grid, sellmeier_ior(v.strip().lower(), grid), props.key(name))
    if isinstance(v, dict):
        if v.get("type") != "spectrum":
            raise props.error(name, "a wavelength-dependent IOR must be a 'spectrum' (pairs or a file)")
        return None, load_spectrum(loader, v, props.key(name), emitter=False, unbounded=True, valid=IOR)
    return lookup_ior(props, name, default), None


def _eta(loader, props, rough: bool):
    """(constant relative IOR or None, interior slot, exterior slot)."""
    ni, si = _ior_spectrum(loader, props, "int_ior", "bk7")
    ne, se = _ior_spectrum(loader, props, "ext_ior", "air")
    if si is None and se is None:
        if rough and ni == ne:
            # The half vector of refraction is undefined for index-matched interfaces.
            raise props.error("int_ior", f"must differ from ext_ior for a rough interface (both are {ni})")
        return ni / ne, _NO_TEXTURE, _NO_TEXTURE
    if si is None:
        si = load_spectrum(loader, ni, props.key("int_ior"), emitter=False, valid=IOR)
    if se is None:
        se = load_spectrum(loader, ne, props.key("ext_ior"), emitter=False, valid=IOR)
    return 1.0, si, se


# -- shared interface math (also used by the layered BSDFs) ------------------------------
# ``lobes`` restricts sampling to REFLECTION or TRANSMISSION (pbrt-v4's sample flags): the
# restricted lobe is then chosen with probability 1 and its weight carries the Fresnel
# factor instead. It is a Python constant, so each kernel holds one variant.
BOTH = REFLECTION | TRANSMISSION


def smooth_dielectric_sample(wi, eta, u1, lobes=BOTH):
    """Sample a smooth interface: (wo, pdf of the lobe choice, radiance weight, reflected
    mask, eta_it, eta_ti). The weight is 0 where the only allowed lobe has zero energy."""
    r, cos_t, eta_it, eta_ti = fresnel_dielectric(wi.z, eta)
    if lobes == BOTH:
        sel_r = u1 < r
        pdf = dr.select(sel_r, r, 1.0 - r)
        # Lobe choice in proportion to R / (1 - R) makes the Fresnel factor cancel.
        weight = dr.select(sel_r, 1.0, eta_ti * eta_ti)
    elif lobes == REFLECTION:
        sel_r, pdf, weight = mi.Bool(True), mi.Float(1.0), r
    else:
        sel_r, pdf, weight = mi.Bool(False), mi.Float(1.0), (1.0 - r) * (eta_ti * eta_ti)
    wo = dr.select(sel_r, reflect(wi), refract(wi, cos_t, eta_ti))
    return wo, pdf, weight, sel_r, eta_it, eta_ti


def rough_dielectric_eval(wi, wo, eta, micro, lobes=BOTH):
    """Walter et al.'s microfacet interface for directions ``wi`` -> ``wo``:
    (f |cos_o| for radiance transport, density of sampling wo, reflected mask, valid mask).
    ``micro(m)`` returns (D(m) G(wi, wo, m), density of sampling m given wi); ``lobes``
    restricts the density (not the value) to one lobe."""
    cos_i, cos_o = wi.z, wo.z
    is_r = cos_i * cos_o > 0
    eta_io = dr.select(cos_i > 0, eta, dr.rcp(eta))      # eta_t / eta_i across the macro-surface
    m = dr.normalize(wi + wo * dr.select(is_r, 1.0, eta_io))
    m = dr.mulsign(m, m.z)
    d_i, d_o = dr.dot(wi, m), dr.dot(wo, m)
    # Both directions on the side of m their macro-surface side implies (else G = 0).
    ok = (cos_i != 0) & (d_i * cos_i > 0) & (d_o * cos_o > 0)
    f = fresnel_dielectric(d_i, eta)[0]
    sel = dr.select(is_r, f, 1.0 - f)
    if lobes == REFLECTION:
        choice = dr.select(is_r & (f > 0), 1.0, 0.0)
    elif lobes == TRANSMISSION:
        choice = dr.select(~is_r & (f < 1), 1.0, 0.0)
    else:
        choice = sel
    den_t = d_i + eta_io * d_o
    dg, pdf_m = micro(m)
    # f|cos_o|: F D G / (4 |cos_i|) for reflection; for refraction
    # (1-F) D G |d_i d_o| eta^2 / (|cos_i| den^2) times the radiance scale 1/eta^2.
    val = dr.select(is_r, 0.25, dr.abs(d_i * d_o) / (den_t * den_t)) * sel * dg / dr.abs(cos_i)
    jac = dr.select(is_r, 0.25 / dr.abs(d_o), eta_io * eta_io * dr.abs(d_o) / (den_t * den_t))
    pdf = pdf_m * choice * jac
    ok &= dr.isfinite(val) & dr.isfinite(pdf)
    return dr.select(ok, val, 0.0), dr.select(ok, pdf, 0.0), is_r, ok


def rough_dielectric_sample(wi, eta, sample_m, weight_m, u1, u2, lobes=BOTH):
    """Sample Walter et al.'s microfacet interface: (wo, pdf, radiance weight, reflected
    mask, eta_it, ok). ``sample_m(wi_up, u2)`` returns (m, density of m);
    ``weight_m(wo, m, d_i)`` is the weight with the Fresnel factor cancelled (the lobe
    chosen with probability F or 1 - F); ``lobes`` as in :func:`smooth_dielectric_sample`."""
    cos_i = wi.z
    wi_up = dr.mulsign(wi, cos_i)
    m, pdf_m = sample_m(wi_up, u2)
    d_i = dr.dot(wi, m)
    f, cos_t, eta_it, eta_ti = fresnel_dielectric(d_i, eta)
    if lobes == BOTH:
        sel_r = u1 < f
        choice, scale = dr.select(sel_r, f, 1.0 - f), mi.Float(1.0)
    elif lobes == REFLECTION:
        sel_r, choice, scale = mi.Bool(True), mi.Float(1.0), f
    else:
        sel_r, choice, scale = mi.Bool(False), mi.Float(1.0), 1.0 - f
    wo = dr.select(sel_r, reflect_about(wi, m), refract_about(wi, m, cos_t, eta_ti))
    d_o = dr.dot(wo, m)
    den_t = d_i + eta_it * d_o
    jac = dr.select(sel_r, 0.25 / dr.abs(d_o), eta_it * eta_it * dr.abs(d_o) / (den_t * den_t))
    pdf = pdf_m * choice * jac
    w = weight_m(wo, m, d_i) * scale
    # The lobe the sample claims must match its side of the surface (m may send a
    # reflection below the horizon); such samples fail (pdf 0), as the eval agrees.
    ok = ((cos_i != 0) & dr.select(sel_r, wo.z * cos_i > 0, wo.z * cos_i < 0)
          & (d_i * cos_i > 0) & (d_o * wo.z > 0) & (pdf > 0) & dr.isfinite(pdf) & dr.isfinite(w) & (scale > 0))
    w = dr.select(sel_r, w, w * eta_ti * eta_ti)
    return wo, dr.select(ok, pdf, 0.0), dr.select(ok, w, 0.0), sel_r, eta_it, ok


class _Dielectric(BSDFType):
    """Shared parsing and parameter tables: eta and the two optional spectral scales."""

    _rough = False   # rough interfaces need int_ior != ext_ior
    refracts = True

    def _add_common(self, loader, props, inst: dict) -> None:
        inst["eta"], inst["int_slot"], inst["ext_slot"] = _eta(loader, props, self._rough)
        # A constant relative IOR is a scene parameter (Mitsuba's key ``<bsdf>.eta``);
        # dispersive IORs are textures, already parameters of their own.
        inst["owner"] = (ParamOwner(props.path, valid={"eta": IOR}, eta=mi.Float(inst["eta"]))
                         if inst["int_slot"] == _NO_TEXTURE else None)
        for name in ("specular_reflectance", "specular_transmittance"):
            inst[name] = (load_spectrum(loader, props.raw(name), props.key(name), emitter=False)
                          if props.has(name) else None)

    def add(self, loader, props) -> int:
        inst: dict = {}
        self._add_common(loader, props, inst)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def param_owners(self) -> list:
        return [i["owner"] for i in self.instances if i["owner"] is not None]

    def refresh_params(self) -> None:
        """Recompute the table of the IOR parameters (see ``SceneParameters.update``)."""
        self.eta = param_table([i["owner"].params["eta"] if i["owner"] else i["eta"] for i in self.instances])

    def build(self) -> None:
        self.refresh_params()
        self.dispersive = any(i["int_slot"] != _NO_TEXTURE for i in self.instances)
        if self.dispersive:
            self.int_slot = mi.UInt32([i["int_slot"] for i in self.instances])
            self.ext_slot = mi.UInt32([i["ext_slot"] for i in self.instances])
        self.tex = {}
        for name in ("specular_reflectance", "specular_transmittance"):
            slots = [i[name] for i in self.instances]
            if any(s is not None for s in slots):
                # (slot table, whether some instance lacks the texture)
                self.tex[name] = (mi.UInt32([_NO_TEXTURE if s is None else s for s in slots]),
                                  any(s is None for s in slots), tuple(s for s in slots if s is not None))

    def _eta_of(self, ctx, idx, active):
        """Relative IOR per lane; a dispersive instance uses its value at the first
        wavelength (the one that survives, see ``_terminates``)."""
        eta = dr.gather(mi.Float, self.eta, idx, active)
        if not self.dispersive:
            return eta
        si = dr.gather(mi.UInt32, self.int_slot, idx, active)
        disp = active & (si != _NO_TEXTURE)
        se = dr.gather(mi.UInt32, self.ext_slot, idx, disp)
        lam = ctx.wl.lambda_
        reach = lambda k: tuple(i[k] for i in self.instances if i[k] != _NO_TEXTURE)  # noqa: E731
        ni = self.textures.eval(si, ctx.si, lam, disp, illuminant=False, reach=reach("int_slot"))[0]
        ne = self.textures.eval(se, ctx.si, lam, disp, illuminant=False, reach=reach("ext_slot"))[0]
        return dr.select(disp, ni / dr.maximum(ne, 1e-6), eta)

    def _terminates(self, idx, active):
        if not self.dispersive:
            return mi.Bool(False)
        return active & (dr.gather(mi.UInt32, self.int_slot, idx, active) != _NO_TEXTURE)

    def _scale(self, name, ctx, idx, active):
        """The spectral scale ``name`` (1 where an instance does not set it), or None when
        no instance of the family sets it (nothing to multiply)."""
        if name not in self.tex:
            return None
        table, some_missing, reach = self.tex[name]
        slot = dr.gather(mi.UInt32, table, idx, active)
        if not some_missing:
            return self.textures.eval(slot, ctx.si, ctx.wl.lambda_, active, illuminant=False, reach=reach)
        has = slot != _NO_TEXTURE
        v = self.textures.eval(slot, ctx.si, ctx.wl.lambda_, active & has, illuminant=False, reach=reach)
        return dr.select(has, v, 1.0)

    def _lobe_weight(self, ctx, idx, sel_r, w_r, w_t, active):
        """Spectral weight: scalar ``w_r`` on reflected lanes, ``w_t`` on transmitted
        ones, each times its optional texture (looked up only on its own lanes)."""
        r = self._scale("specular_reflectance", ctx, idx, active & sel_r)
        t = self._scale("specular_transmittance", ctx, idx, active & ~sel_r)
        w_r = mi.Spectrum(w_r) if r is None else w_r * r
        w_t = mi.Spectrum(w_t) if t is None else w_t * t
        return dr.select(sel_r, w_r, w_t)

    def eval_pdf(self, ctx, idx, wo, active):
        """Delta lobes: zero for every direction that was not sampled."""
        n = dr.width(wo)
        return dr.zeros(mi.Spectrum, n), dr.zeros(mi.Float, n)

    # -- the microfacet interface (roughdielectric's, and regularised smooth ones') ---------
    # ``prm``: (eta, alpha_u, alpha_v, variant lane or None, VariantTable).
    @staticmethod
    def _distributions(variant, au, av, cos_i):
        """(distribution, the one sampled from): widened for D cos sampling."""
        kind, visible = variant
        d = Microfacet(kind, au, av, visible)
        if visible:
            return d, d
        s = 1.2 - 0.2 * dr.sqrt(dr.abs(cos_i))
        return d, Microfacet(kind, au * s, av * s, False)

    def _eval_pdf(self, ctx, idx, prm, wo, active):
        eta, au, av, var, table = prm
        wi = ctx.si.wi
        cos_i = wi.z

        def micro(m):
            def per_variant(variant):
                d, sd = self._distributions(variant, au, av, cos_i)
                return d.D(m) * d.G(wi, wo, m), sd.pdf(dr.mulsign(wi, cos_i), m)
            return table.per_variant(var, per_variant)

        val, pdf, is_r, ok = rough_dielectric_eval(wi, wo, eta, micro)
        ok &= active
        value = self._lobe_weight(ctx, idx, is_r, val, val, ok)
        return dr.select(ok, value, 0.0), dr.select(ok, pdf, 0.0)

    def _sample(self, ctx, idx, prm, u1, u2, active) -> BSDFSample:
        eta, au, av, var, table = prm
        wi = ctx.si.wi
        cos_i = wi.z

        def sample_m(wi_up, u):
            return table.per_variant(var, lambda v: self._distributions(v, au, av, cos_i)[1].sample(wi_up, u))

        def weight_m(wo, m, d_i):
            def per_variant(variant):
                d, sd = self._distributions(variant, au, av, cos_i)
                if variant[1]:
                    # D G1(wi) |wi.m| / |cos_i| cancels against the visible-normal density.
                    return (d.G1(wo, m),)
                return (d.G(wi, wo, m) * dr.abs(d_i) / (dr.abs(cos_i) * m.z) * (d.D(m) / sd.D(m)),)
            return table.per_variant(var, per_variant)[0]

        wo, pdf, w, sel_r, eta_it, ok = rough_dielectric_sample(wi, eta, sample_m, weight_m, u1, u2)
        ok &= active
        spec = self._lobe_weight(ctx, idx, sel_r, w, w, ok)
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), dr.select(sel_r, 1.0, eta_it), mi.Bool(False),
                          dr.select(ok, spec, 0.0), self._terminates(idx, active))


@BSDF_TYPES.register("dielectric")
class SmoothDielectric(_Dielectric):
    """``dielectric``: a smooth interface between two dielectrics (Mitsuba's); a
    wavelength-dependent IOR disperses light (only the first wavelength goes on).

    ======================  =========  =======  =========================================================
    name                    type       default  meaning
    ======================  =========  =======  =========================================================
    int_ior                 float|str  'bk7'    interior IOR: a number, a Mitsuba name, a 'spectrum' or a
                                                Sellmeier glass name (glass-BK7, ...: dispersion)
    ext_ior                 float|str  'air'    exterior IOR (as int_ior)
    specular_reflectance    texture    1        factor on the reflected lobe (not physical; Mitsuba's)
    specular_transmittance  texture    1        factor on the transmitted lobe
    ======================  =========  =======  =========================================================
    """

    name = "dielectric"
    flags = REFLECTION | TRANSMISSION | SPECULAR
    regularizes_to_glossy = True

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        wi = ctx.si.wi
        eta = self._eta_of(ctx, idx, active)
        wo, pdf, w, sel_r, eta_it, _ = smooth_dielectric_sample(wi, eta, u1)
        weight = self._lobe_weight(ctx, idx, sel_r, w, w, active)
        bs = BSDFSample(wo, dr.select(active, pdf, 0.0), dr.select(sel_r, 1.0, eta_it), mi.Bool(True),
                        dr.select(active & (pdf > 0), weight, 0.0), self._terminates(idx, active))
        if ctx.regularizing:     # pbrt-v4's regularised interface: a rough one of alpha 0.1
            reg = active & ctx.regularize
            bs = dr.select(reg, self._sample(ctx, idx, self._regularized(eta), u1, u2, reg), bs)
        return bs

    def eval_pdf(self, ctx, idx, wo, active):
        if not ctx.regularizing:
            return _Dielectric.eval_pdf(self, ctx, idx, wo, active)
        reg = active & ctx.regularize
        f, pdf = self._eval_pdf(ctx, idx, self._regularized(self._eta_of(ctx, idx, reg)), wo, reg)
        return dr.select(reg, f, 0.0), dr.select(reg, pdf, 0.0)

    @staticmethod
    def _regularized(eta):
        return (eta, mi.Float(REGULARIZED_ALPHA), mi.Float(REGULARIZED_ALPHA), None,
                VariantTable([REGULARIZED_VARIANT]))


@BSDF_TYPES.register("thindielectric")
class ThinDielectric(_Dielectric):
    """``thindielectric``: a thin dielectric slab (Mitsuba's): reflection R' = 2R / (1 + R),
    straight transmission. Parameters: those of ``dielectric`` (int_ior, ext_ior,
    specular_reflectance, specular_transmittance).

    As in Mitsuba, the transmission is a *null* lobe: ``volpath`` does not count crossing
    the slab as a bounce, and its shadow rays pass through with weight 1 - R' (times
    specular_transmittance).
    """

    name = "thindielectric"
    flags = REFLECTION | TRANSMISSION | SPECULAR
    null_lobe = True
    refracts = False   # light leaves the slab into the medium it came from

    def _reflectance(self, ctx, idx, cos, active):
        r = fresnel_dielectric(dr.abs(cos), self._eta_of(ctx, idx, active))[0]
        return 2.0 * r / (1.0 + r)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        wi = ctx.si.wi
        r = self._reflectance(ctx, idx, wi.z, active)
        sel_r = u1 < r
        wo = dr.select(sel_r, reflect(wi), -wi)
        weight = self._lobe_weight(ctx, idx, sel_r, 1.0, 1.0, active)
        pdf = dr.select(sel_r, r, 1.0 - r)
        return BSDFSample(wo, dr.select(active, pdf, 0.0), mi.Float(1.0), mi.Bool(True),
                          dr.select(active & (pdf > 0), weight, 0.0), mi.Bool(False), active & ~sel_r)

    def null_transmission(self, ctx, idx, active):
        """Weight of light passing straight through (Mitsuba's ``eval_null_transmission``)."""
        t = 1.0 - self._reflectance(ctx, idx, ctx.si.wi.z, active)
        s = self._scale("specular_transmittance", ctx, idx, active)
        return mi.Spectrum(t) if s is None else t * s


@BSDF_TYPES.register("roughdielectric")
class RoughDielectric(_Dielectric):
    """``roughdielectric``: a rough dielectric interface (Mitsuba's), reflecting and
    refracting through microfacets on both sides.

    ======================  =========  ========  =========================================================
    name                    type       default   meaning
    ======================  =========  ========  =========================================================
    int_ior                 float|str  'bk7'     interior IOR: a number, a Mitsuba name, a 'spectrum' or a
                                                 Sellmeier glass name (glass-BK7, ...: dispersion)
    ext_ior                 float|str  'air'     exterior IOR (as int_ior)
    specular_reflectance    texture    1         factor on the reflected lobe (not physical; Mitsuba's)
    specular_transmittance  texture    1         factor on the transmitted lobe
    distribution            string     beckmann  microfacet distribution: 'beckmann' or 'ggx'
    alpha                   texture    0.1       roughness (RMS slope), or anisotropic alpha_u / alpha_v
    sample_visible          bool       true      sample visible normals (else D(m) cos(theta_m))
    ======================  =========  ========  =========================================================
    """

    name = "roughdielectric"
    flags = REFLECTION | TRANSMISSION | GLOSSY
    _rough = True

    def add(self, loader, props) -> int:
        inst: dict = {}
        dist = props.string("distribution", BECKMANN).lower()
        if dist not in (BECKMANN, GGX):
            raise props.error("distribution", f"expected 'beckmann' or 'ggx', got {dist!r}")
        visible = props.bool("sample_visible", True)
        inst["variant"] = (dist, visible)
        if props.has("alpha_u") or props.has("alpha_v"):
            for k in ("alpha_u", "alpha_v"):
                if not props.has(k):
                    raise props.error(k, "both 'alpha_u' and 'alpha_v' must be given")
            if props.has("alpha"):
                raise props.error("alpha", "give either 'alpha' or 'alpha_u'/'alpha_v', not both")
            names = ("alpha_u", "alpha_v")
        else:
            names = ("alpha",)
        slots = []
        for k in names:
            slots.append(load_spectrum(loader, props.raw(k, 0.1), props.key(k), emitter=False, unbounded="mitsuba",
                                       valid=ROUGHNESS, scalar=True))
        inst["alpha"] = (slots[0], slots[-1])
        self._add_common(loader, props, inst)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self) -> None:
        super().build()
        self.variant_table = VariantTable([i["variant"] for i in self.instances])
        self.anisotropic = any(i["alpha"][0] != i["alpha"][1] for i in self.instances)
        self.alpha_u = mi.UInt32([i["alpha"][0] for i in self.instances])
        self.alpha_v = mi.UInt32([i["alpha"][1] for i in self.instances])
        self.alpha_reach = (tuple(i["alpha"][0] for i in self.instances), tuple(i["alpha"][1] for i in self.instances))

    # -- per-hit parameters ----------------------------------------------------------
    def _params(self, ctx, idx, active):
        """(eta, alpha_u, alpha_v, variant index or None, variant table) at this hit
        (regularised where the context says so)."""
        eta = self._eta_of(ctx, idx, active)
        uv, lam = ctx.si, ctx.wl.lambda_
        au = self.textures.eval(dr.gather(mi.UInt32, self.alpha_u, idx, active), uv, lam, active, illuminant=False,
                                reach=self.alpha_reach[0])[0]
        av = (self.textures.eval(dr.gather(mi.UInt32, self.alpha_v, idx, active), uv, lam, active, illuminant=False,
                                 reach=self.alpha_reach[1])[0]
              if self.anisotropic else au)
        if ctx.regularizing:
            au, av = regularized_alpha(au, ctx.regularize), regularized_alpha(av, ctx.regularize)
        return eta, au, av, self.variant_table.lane(idx, active), self.variant_table

    def eval_pdf(self, ctx, idx, wo, active):
        return self._eval_pdf(ctx, idx, self._params(ctx, idx, active), wo, active)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        return self._sample(ctx, idx, self._params(ctx, idx, active), u1, u2, active)

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        prm = self._params(ctx, idx, active)
        f, pdf = self._eval_pdf(ctx, idx, prm, wo, active)
        return f, pdf, self._sample(ctx, idx, prm, u1, u2, active)
