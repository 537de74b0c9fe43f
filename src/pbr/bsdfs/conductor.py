"""``conductor`` (smooth mirror) and ``roughconductor`` (microfacet) metals.

The complex IOR eta + i k is given per wavelength: ``material`` names a measured metal
(Mitsuba's data files ``data/ior/<name>.{eta,k}.spd``, e.g. Au, Ag, Al, Cu, Cr; 'none'
is a perfect mirror), or ``eta``/``k`` are given as spectra. RGB values are upsampled as
Mitsuba's spectral variants do: clamped to [0, 1] and upsampled as a reflectance (so an
RGB ``k`` of 3 acts as 1); ``{'type': 'rgb', 'value': ..., 'upsampling': 'unbounded'}``
selects pbrt-v4's unbounded upsampling, which keeps values above 1 (docs/materials.md).
``specular_reflectance`` scales the result (not physical; default 1).
"""

from __future__ import annotations

import os

import drjit as dr
import mitsuba as mi

from ..plugins.props import NONNEGATIVE, ROUGHNESS
from ..spectrum import read_spd
from ..textures import add_tabulated, load_spectrum
from .base import BSDF_TYPES, BSDFType, BSDFSample, REFLECTION, GLOSSY, SPECULAR
from .fresnel import fresnel_conductor, reflect, reflect_about
from .microfacet import (BECKMANN, GGX, REGULARIZED_ALPHA, REGULARIZED_VARIANT, Microfacet, VariantTable,
                         regularized_alpha)

_IOR_DIR = os.path.join(os.path.dirname(mi.__file__), "data", "ior")


def conductor_materials() -> list[str]:
    """Names accepted by ``material`` (those with both eta and k data), plus 'none'."""
    names = {f.split(".")[0] for f in os.listdir(_IOR_DIR) if f.endswith(".eta.spd")}
    return sorted(n for n in names if os.path.exists(os.path.join(_IOR_DIR, f"{n}.k.spd"))) + ["none"]


def _load_eta_k(loader, props):
    """Texture slots (eta, k) from ``material`` or explicit ``eta``/``k``."""
    has_ek = props.has("eta") or props.has("k")
    material = props.string("material", "none")
    if has_ek:
        if props.has("material"):
            raise props.error("material", "give either 'material' or 'eta'/'k', not both")
        # Mitsuba's unbounded textures: RGB values are clamped to [0, 1] (see textures._rgb).
        eta = load_spectrum(loader, props.raw("eta", 0.0), props.key("eta"), emitter=False, unbounded="mitsuba",
                            valid=NONNEGATIVE)
        k = load_spectrum(loader, props.raw("k", 1.0), props.key("k"), emitter=False, unbounded="mitsuba",
                          valid=NONNEGATIVE)
        return eta, k
    if material == "none":
        return (load_spectrum(loader, 0.0, props.key("eta"), emitter=False),
                load_spectrum(loader, 1.0, props.key("k"), emitter=False))
    if material not in conductor_materials():
        raise props.error("material", f"unknown conductor {material!r}; known: {', '.join(conductor_materials())}")
    slots = []
    for comp in ("eta", "k"):
        wl, vals = read_spd(os.path.join(_IOR_DIR, f"{material}.{comp}.spd"))
        slots.append(add_tabulated(loader, wl, vals, props.key(comp)))
    return tuple(slots)


@BSDF_TYPES.register("conductor")
class Conductor(BSDFType):
    """``conductor``: a smooth metal (Mitsuba's): exact complex Fresnel reflection.

    ====================  =======  =======  ==================================================
    name                  type     default  meaning
    ====================  =======  =======  ==================================================
    material              string   'none'   a Mitsuba metal (Au, Ag, Al, Cu, Cr, ...; see
                                            conductor_materials()); 'none': a perfect mirror
    eta                   texture  0        real part of the IOR instead of material
    k                     texture  1        imaginary part (absorption) instead of material
    specular_reflectance  texture  1        factor on the reflection (not physical; Mitsuba's)
    ====================  =======  =======  ==================================================
    """

    name = "conductor"
    flags = REFLECTION | SPECULAR
    regularizes_to_glossy = True

    def add(self, loader, props) -> int:
        eta, k = _load_eta_k(loader, props)
        spec = load_spectrum(loader, props.raw("specular_reflectance", 1.0), props.key("specular_reflectance"),
                             emitter=False)
        props.finish()
        self.instances.append((eta, k, spec))
        return len(self.instances) - 1

    def build(self) -> None:
        self.eta, self.k, self.spec = (mi.UInt32([i[j] for i in self.instances]) for j in range(3))
        # The slots each parameter's lookup can reach (TextureSet.eval's reach).
        self.reach = {name: tuple(i[j] for i in self.instances) for j, name in enumerate(("eta", "k", "spec"))}

    def _reflectance(self, ctx, idx, cos_i, active):
        tex, uv, lam = self.textures, ctx.si, ctx.wl.lambda_
        ev = lambda n: tex.eval(dr.gather(mi.UInt32, getattr(self, n), idx, active), uv, lam, active,  # noqa: E731
                                illuminant=False, reach=self.reach[n])
        return fresnel_conductor(cos_i, ev("eta"), ev("k")) * ev("spec")

    def eval_pdf(self, ctx, idx, wo, active):
        if not ctx.regularizing:
            return mi.Spectrum(0.0), mi.Float(0.0)
        reg = active & ctx.regularize
        f, pdf = self._micro_eval_pdf(ctx, idx, wo, reg, *self._regularized())
        return dr.select(reg, f, 0.0), dr.select(reg, pdf, 0.0)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        wi = ctx.si.wi
        ok = active & (wi.z > 0)
        w = self._reflectance(ctx, idx, wi.z, ok)
        bs = BSDFSample(reflect(wi), dr.select(ok, 1.0, 0.0), mi.Float(1.0), mi.Bool(True), dr.select(ok, w, 0.0))
        if ctx.regularizing:     # pbrt-v4's regularised mirror: a rough one of alpha 0.1
            reg = active & ctx.regularize
            bs = dr.select(reg, self._micro_sample(ctx, idx, u2, reg, *self._regularized()), bs)
        return bs

    @staticmethod
    def _regularized():
        """(alpha_u, alpha_v, variant lane, variant table) of a regularised smooth metal."""
        return mi.Float(REGULARIZED_ALPHA), mi.Float(REGULARIZED_ALPHA), None, VariantTable([REGULARIZED_VARIANT])

    # -- microfacet reflection (roughconductor's, and regularised smooth metals') ----------
    def _micro_eval_pdf(self, ctx, idx, wo, active, au, av, var, table):
        wi = ctx.si.wi
        ok = active & (wi.z > 0) & (wo.z > 0)
        m = dr.normalize(wi + wo)

        def micro(variant):
            md = Microfacet(variant[0], au, av, variant[1])
            return md.D(m) * md.G(wi, wo, m), md.pdf(wi, m)

        dg, pdf_m = table.per_variant(var, micro)
        F = self._reflectance(ctx, idx, dr.dot(wi, m), ok)
        f = F * (dg / (4.0 * wi.z))
        pdf = pdf_m / (4.0 * dr.dot(wo, m))
        ok &= (pdf > 0) & dr.isfinite(pdf)
        return dr.select(ok, f, 0.0), dr.select(ok, pdf, 0.0)

    def _micro_sample(self, ctx, idx, u2, active, au, av, var, table) -> BSDFSample:
        wi = ctx.si.wi
        ok = active & (wi.z > 0)

        def micro(variant):
            md = Microfacet(variant[0], au, av, variant[1])
            m, pdf_m = md.sample(wi, u2)
            wo = reflect_about(wi, m)
            # weight / F: the masking of wo (visible normals) or G (wi.m)/(cos_i m.z) (D cos).
            g = md.G1(wo, m) if md.sample_visible else md.G(wi, wo, m) * dr.dot(wi, m) / (wi.z * m.z)
            return m, pdf_m, g

        m, pdf_m, g = table.per_variant(var, micro)
        wo = reflect_about(wi, m)
        ok &= (wo.z > 0) & (pdf_m > 0) & (dr.dot(wi, m) > 0)
        pdf = pdf_m / (4.0 * dr.dot(wo, m))
        w = self._reflectance(ctx, idx, dr.dot(wi, m), ok) * g
        ok &= dr.isfinite(pdf)
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), mi.Float(1.0), mi.Bool(False), dr.select(ok, w, 0.0))


@BSDF_TYPES.register("roughconductor")
class RoughConductor(Conductor):
    """``roughconductor``: a rough metal (Mitsuba's): microfacet reflection with complex
    Fresnel; anisotropic roughness follows dp/du.

    ====================  =======  ========  =======================================================
    name                  type     default   meaning
    ====================  =======  ========  =======================================================
    material              string   'none'    a Mitsuba metal (Au, Ag, Al, Cu, Cr, ...; see
                                             conductor_materials()); 'none': a perfect mirror
    eta                   texture  0         real part of the IOR instead of material
    k                     texture  1         imaginary part (absorption) instead of material
    specular_reflectance  texture  1         factor on the reflection (not physical; Mitsuba's)
    distribution          string   beckmann  microfacet distribution: 'beckmann' or 'ggx'
    alpha                 texture  0.1       roughness (RMS slope), or anisotropic alpha_u / alpha_v
    sample_visible        bool     true      sample visible normals (else D(m) cos(theta_m))
    ====================  =======  ========  =======================================================
    """

    name = "roughconductor"
    flags = REFLECTION | GLOSSY

    def add(self, loader, props) -> int:
        dist = props.string("distribution", BECKMANN, choices=(BECKMANN, GGX))
        if props.has("alpha") and (props.has("alpha_u") or props.has("alpha_v")):
            raise props.error("alpha", "give either 'alpha' or 'alpha_u'/'alpha_v'")
        au = props.raw("alpha_u", props.raw("alpha", 0.1))
        av = props.raw("alpha_v", props.raw("alpha", 0.1) if not props.has("alpha_u") else au)
        anisotropic = props.has("alpha_u") or props.has("alpha_v")
        au = load_spectrum(loader, au, props.key("alpha_u" if props.has("alpha_u") else "alpha"), emitter=False,
                           unbounded="mitsuba", valid=ROUGHNESS, scalar=True)
        # Isotropic: one slot for both directions, so that the parameter <bsdf>.alpha
        # moves both (two slots under one key left alpha_v at its loaded value).
        av = (load_spectrum(loader, av, props.key("alpha_v" if props.has("alpha_v") else "alpha"), emitter=False,
                            unbounded="mitsuba", valid=ROUGHNESS, scalar=True) if anisotropic else au)
        visible = props.bool("sample_visible", True)
        i = super().add(loader, props)
        self.instances[i] = self.instances[i] + (au, av, (dist, visible))
        return i

    def build(self) -> None:
        super().build()
        self.au = mi.UInt32([i[3] for i in self.instances])
        self.av = mi.UInt32([i[4] for i in self.instances])
        self.reach.update({"au": tuple(i[3] for i in self.instances), "av": tuple(i[4] for i in self.instances)})
        self.variant_table = VariantTable([i[5] for i in self.instances])

    def _roughness(self, ctx, idx, active):
        tex, uv, lam = self.textures, ctx.si, ctx.wl.lambda_
        a = lambda n: tex.eval(dr.gather(mi.UInt32, getattr(self, n), idx, active), uv, lam, active,  # noqa: E731
                               illuminant=False, reach=self.reach[n])[0]
        au, av = a("au"), a("av")
        if ctx.regularizing:
            au, av = regularized_alpha(au, ctx.regularize), regularized_alpha(av, ctx.regularize)
        return au, av, self.variant_table.lane(idx, active), self.variant_table

    def eval_pdf(self, ctx, idx, wo, active):
        ok = active & (ctx.si.wi.z > 0) & (wo.z > 0)
        return self._micro_eval_pdf(ctx, idx, wo, active, *self._roughness(ctx, idx, ok))

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        ok = active & (ctx.si.wi.z > 0)
        return self._micro_sample(ctx, idx, u2, active, *self._roughness(ctx, idx, ok))

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        return BSDFType.eval_pdf_sample(self, ctx, idx, wo, u1, u2, active)
