"""``subsurface`` (pbrt-v4's ``SubsurfaceMaterial``): a dielectric boundary (smooth or
GGX-rough: the coating interface of :mod:`.layered`) over a homogeneous scattering
medium whose light transport is the tabulated photon-beam-diffusion BSSRDF of
:mod:`.bssrdf`. As a BSDF it is the interface alone; light refracted into the surface
is carried to an exit point by ``volpath`` (:mod:`pbr.integrators.subsurface`). Other
integrators see the interface only (as pbrt-v4's ``path`` does). docs/materials.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..plugins.props import HG_ASYMMETRY, IOR, NONNEGATIVE
from ..textures import load_spectrum
from . import bssrdf
from .base import BSDF_TYPES, BSDFSample, BSDFType, GLOSSY, REFLECTION, SPECULAR, TRANSMISSION
from .layered import _kind, _Layered, _Top

# pbrt-v4's default coefficients (RGB, per mm: skim milk-like), used when neither
# sigma_a/sigma_s nor reflectance is given.
DEFAULT_SIGMA_A = (0.0011, 0.0024, 0.014)
DEFAULT_SIGMA_S = (2.55, 3.21, 3.77)


def _rgb(v):
    return {"type": "rgb", "value": list(v)}


@BSDF_TYPES.register("subsurface")
class Subsurface(BSDFType):
    """``subsurface`` (pbrt-v4's): a dielectric interface over a scattering medium rendered
    with a tabulated BSSRDF (photon beam diffusion). The medium is given by ``sigma_a``
    and ``sigma_s`` (times ``scale``), or by a diffuse ``reflectance`` and the mean free
    path ``mfp`` (inverted to coefficients as pbrt-v4's ``SubsurfaceFromDiffuse``); with
    neither, pbrt-v4's default coefficients. Subsurface transport needs ``volpath``;
    other integrators render the interface alone.

    ==============  =======  =======================  =====================================================
    name            type     default                  meaning
    ==============  =======  =======================  =====================================================
    sigma_a         texture  (.0011, .0024, .014)      absorption coefficient (with sigma_s; RGB unbounded)
    sigma_s         texture  (2.55, 3.21, 3.77)        scattering coefficient (with sigma_a)
    reflectance     texture  none                     effective diffuse albedo (instead of sigma_a/sigma_s)
    mfp             texture  1                        mean free path 1 / sigma_t (with reflectance)
    scale           float    1                        factor on sigma_a, sigma_s and mfp
    eta             float    1.33                     relative IOR of the boundary (interior / exterior)
    g               float    0                        Henyey-Greenstein asymmetry of the medium
    roughness       texture  0                        GGX roughness of the boundary (or uroughness/vroughness)
    uroughness      texture  roughness                roughness along the tangent
    vroughness      texture  roughness                roughness along the bitangent
    remaproughness  bool     true                     roughness is pbrt-v4's perceptual value (alpha = sqrt)
    ==============  =======  =======================  =====================================================
    """

    name = "subsurface"
    flags = REFLECTION | TRANSMISSION | GLOSSY | SPECULAR
    refracts = True

    def add(self, loader, props) -> int:
        if props.has("name"):
            raise props.error("name", "named scattering coefficients are not available in pbr: give sigma_a and "
                                      "sigma_s (or reflectance and mfp)")
        inst: dict = {}
        g = props.float("g", 0.0, valid=HG_ASYMMETRY)
        eta = props.float("eta", 1.33, valid=IOR)
        if eta == 1.0:
            raise props.error("eta", "must differ from 1 (the diffusion boundary needs an interface)")
        inst["scale"] = props.float("scale", 1.0, min=0.0)
        has_a, has_s = props.has("sigma_a"), props.has("sigma_s")
        if has_a != has_s:
            given, missing = ("sigma_a", "sigma_s") if has_a else ("sigma_s", "sigma_a")
            raise props.error(given, f"given without {missing!r} (both are needed)")
        if has_a and (props.has("reflectance") or props.has("mfp")):
            raise props.error("reflectance" if props.has("reflectance") else "mfp",
                              "give either sigma_a/sigma_s or reflectance/mfp, not both")
        if props.has("mfp") and not props.has("reflectance"):
            raise props.error("mfp", "needs 'reflectance' (mfp with sigma_a/sigma_s is not a pbrt-v4 parameter set)")
        inst["diffuse"] = props.has("reflectance")
        if inst["diffuse"]:
            inst["a"] = load_spectrum(loader, props.raw("reflectance"), props.key("reflectance"), emitter=False)
            inst["b"] = load_spectrum(loader, props.raw("mfp", 1.0), props.key("mfp"), emitter=False, unbounded=True,
                                      valid=NONNEGATIVE)
        else:
            for k, name, default in (("a", "sigma_a", DEFAULT_SIGMA_A), ("b", "sigma_s", DEFAULT_SIGMA_S)):
                inst[k] = load_spectrum(loader, props.raw(name, _rgb(default)), props.key(name), emitter=False,
                                        unbounded=True, valid=NONNEGATIVE)
        remap = props.bool("remaproughness", True)
        inst["remap"] = remap
        (inst["top_u"], inst["top_v"]), inst["top_kind"] = _Layered._roughness(self, loader, props, "", remap)
        inst["eta"] = eta
        inst["table"] = bssrdf.Table.get(g, eta)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self) -> None:
        I = self.instances  # noqa: E741
        u32 = lambda k: mi.UInt32([i[k] for i in I])  # noqa: E731
        self.eta = mi.Float([i["eta"] for i in I])
        self.scale = mi.Float([i["scale"] for i in I])
        self.diffuse = mi.Bool([i["diffuse"] for i in I])
        self.kinds = {i["diffuse"] for i in I}
        self.a, self.b = u32("a"), u32("b")
        self.remap = mi.Bool([i["remap"] for i in I])
        self.top_u, self.top_v = u32("top_u"), u32("top_v")
        self.top_kind = _kind(i["top_kind"] for i in I)
        self.tables = bssrdf.Tables([i["table"] for i in I])

    def _ev(self, name, ctx, idx, active, lanes=None):
        reach = tuple(i[name] for i in self.instances)
        return self.textures.eval(dr.gather(mi.UInt32, getattr(self, name), idx, active), ctx.si, ctx.wl.lambda_,
                                  active, illuminant=False, reach=reach)

    # -- the interface ---------------------------------------------------------------
    def _top(self, ctx, idx, active) -> _Top:
        remap = dr.gather(mi.Bool, self.remap, idx, active)
        au = dr.maximum(self._ev("top_u", ctx, idx, active)[0], 0.0)
        av = dr.maximum(self._ev("top_v", ctx, idx, active)[0], 0.0)
        au, av = dr.select(remap, dr.sqrt(au), au), dr.select(remap, dr.sqrt(av), av)
        return _Top(dr.gather(mi.Float, self.eta, idx, active), au, av, self.top_kind)

    def _eval_pdf(self, ctx, top, wo, active):
        f, pdf = top.eval_pdf(ctx.si.wi, wo)
        return dr.select(active, mi.Spectrum(f), 0.0), dr.select(active, pdf, 0.0)

    def _sample(self, ctx, top, u1, u2, active) -> BSDFSample:
        wi = ctx.si.wi
        s = top.sample(wi, u1, u2)
        ok = active & s.ok
        eta_it = dr.select(wi.z > 0, top.eta, dr.rcp(top.eta))
        return BSDFSample(s.w, dr.select(ok, s.pdf, 0.0), dr.select(s.refl, 1.0, eta_it), active & top.smooth,
                          dr.select(ok, mi.Spectrum(s.weight), 0.0), mi.Bool(False))

    def eval_pdf(self, ctx, idx, wo, active):
        return self._eval_pdf(ctx, self._top(ctx, idx, active), wo, active)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        return self._sample(ctx, self._top(ctx, idx, active), u1, u2, active)

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        top = self._top(ctx, idx, active)
        f, pdf = self._eval_pdf(ctx, top, wo, active)
        return f, pdf, self._sample(ctx, top, u1, u2, active)

    # -- the medium (for the BSSRDF) ---------------------------------------------------
    def coefficients(self, ctx, idx, active):
        """(sigma_t, albedo rho) per wavelength at the hit (pbrt-v4's ``GetBSSRDF``)."""
        scale = dr.gather(mi.Float, self.scale, idx, active)
        a = self._ev("a", ctx, idx, active)
        b = self._ev("b", ctx, idx, active)
        sig_a = sig_s = None
        if False in self.kinds:
            sig_a, sig_s = dr.maximum(scale * a, 0.0), dr.maximum(scale * b, 0.0)
        if True in self.kinds:
            mfp = dr.maximum(scale * b, 0.0)
            rho = bssrdf.albedo_from_reflectance(self.tables, idx, dr.clip(a, 0.0, 1.0), active)
            inv = dr.select(mfp > 0, dr.rcp(mfp), 0.0)
            da, ds = (1.0 - rho) * inv, rho * inv
            if sig_a is None:
                sig_a, sig_s = da, ds
            else:
                d = dr.gather(mi.Bool, self.diffuse, idx, active)
                sig_a, sig_s = dr.select(d, da, sig_a), dr.select(d, ds, sig_s)
        sigma_t = sig_a + sig_s
        return sigma_t, dr.select(sigma_t > 0, sig_s / sigma_t, 0.0)

