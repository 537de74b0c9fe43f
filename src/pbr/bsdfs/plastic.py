"""``plastic``: Mitsuba 3's smooth plastic, a diffuse base under a smooth dielectric
coating. Light reflects specularly off the coating with the Fresnel reflectance R, or
refracts, scatters diffusely (with internal re-reflections at the coating folded into
``1 / (1 - F_dr)``, or ``1 / (1 - reflectance F_dr)`` with ``nonlinear``) and leaves
through the coating again: f_d = reflectance (1 - R_i)(1 - R_o) / (eta^2 pi (1 - ...)).
The two lobes are chosen in proportion to R times the specular/diffuse mean ratio."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..sampling import square_to_cosine_hemisphere, cosine_hemisphere_pdf
from ..textures import load_spectrum
from .base import BSDF_TYPES, BSDFType, BSDFSample, REFLECTION, DIFFUSE, SPECULAR
from .fresnel import fresnel_dielectric, fresnel_diffuse_reflectance, lookup_ior, reflect


@BSDF_TYPES.register("plastic")
class Plastic(BSDFType):
    """``plastic``: Mitsuba's smooth plastic: a diffuse base under a smooth dielectric coating.

    ====================  =========  ===============  ===================================================
    name                  type       default          meaning
    ====================  =========  ===============  ===================================================
    int_ior               float|str  'polypropylene'  interior IOR (a number or a Mitsuba name)
    ext_ior               float|str  'air'            exterior IOR
    diffuse_reflectance   texture    0.5              albedo of the diffuse base
    specular_reflectance  texture    1                factor on the specular coating
    nonlinear             bool       false            account for the colour shift of internal scattering
    ====================  =========  ===============  ===================================================
    """

    name = "plastic"
    flags = REFLECTION | DIFFUSE | SPECULAR

    def add(self, loader, props) -> int:
        eta = lookup_ior(props, "int_ior", "polypropylene") / lookup_ior(props, "ext_ior", "air")
        diffuse = load_spectrum(loader, props.raw("diffuse_reflectance", 0.5), props.key("diffuse_reflectance"),
                                emitter=False)
        spec = load_spectrum(loader, props.raw("specular_reflectance", 1.0), props.key("specular_reflectance"),
                             emitter=False)
        nonlinear = props.bool("nonlinear", False)
        props.finish()
        d_mean = loader.textures.constant_value(diffuse)
        s_mean = loader.textures.constant_value(spec)
        self.instances.append({
            "diffuse": diffuse, "spec": spec, "eta": eta, "nonlinear": nonlinear,
            "fdr_int": fresnel_diffuse_reflectance(1.0 / eta),
            "spec_weight": s_mean / max(d_mean + s_mean, 1e-12)})
        return len(self.instances) - 1

    def build(self) -> None:
        col = lambda k, t=mi.Float: t([i[k] for i in self.instances])  # noqa: E731
        self.diffuse, self.spec = col("diffuse", mi.UInt32), col("spec", mi.UInt32)
        # The slots each texture's lookup can reach (TextureSet.eval's reach).
        self.reach = {n: tuple(i[n] for i in self.instances) for n in ("diffuse", "spec")}
        self.eta, self.fdr_int, self.spec_weight = col("eta"), col("fdr_int"), col("spec_weight")
        self.nonlinear = col("nonlinear", mi.Bool)
        self.any_nonlinear = any(i["nonlinear"] for i in self.instances)

    def _params(self, ctx, idx, active):
        g = lambda a: dr.gather(type(a), a, idx, active)  # noqa: E731
        return g(self.eta), g(self.fdr_int), g(self.spec_weight)

    def _tex(self, name, ctx, idx, active):
        """Texture ``name`` ('diffuse' or 'spec') at this hit."""
        slot = dr.gather(mi.UInt32, getattr(self, name), idx, active)
        return self.textures.eval(slot, ctx.si, ctx.wl.lambda_, active, illuminant=False,
                                  reach=self.reach[name])

    def _diffuse_term(self, ctx, idx, eta, fdr_int, f_i, f_o, active):
        """f_d * pi / cos: the diffuse albedo after coating losses and re-reflections."""
        d = self._tex("diffuse", ctx, idx, active)
        denom = 1.0 - fdr_int
        if self.any_nonlinear:
            denom = dr.select(dr.gather(mi.Bool, self.nonlinear, idx, active), 1.0 - d * fdr_int, denom)
        return d / denom * ((1.0 - f_i) * (1.0 - f_o) / (eta * eta))

    @staticmethod
    def _prob_specular(f_i, spec_weight):
        ps = f_i * spec_weight
        pd = (1.0 - f_i) * (1.0 - spec_weight)
        return ps / (ps + pd)

    def eval_pdf(self, ctx, idx, wo, active):
        wi = ctx.si.wi
        ok = active & (wi.z > 0) & (wo.z > 0)
        eta, fdr_int, sw = self._params(ctx, idx, ok)
        f_i = fresnel_dielectric(wi.z, eta)[0]
        f_o = fresnel_dielectric(wo.z, eta)[0]
        f = self._diffuse_term(ctx, idx, eta, fdr_int, f_i, f_o, ok) * (dr.inv_pi * wo.z)
        pdf = (1.0 - self._prob_specular(f_i, sw)) * cosine_hemisphere_pdf(wo)
        return dr.select(ok, f, 0.0), dr.select(ok, pdf, 0.0)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        wi = ctx.si.wi
        ok = active & (wi.z > 0)
        eta, fdr_int, sw = self._params(ctx, idx, ok)
        f_i = fresnel_dielectric(wi.z, eta)[0]
        p_spec = self._prob_specular(f_i, sw)
        specular = u1 < p_spec
        wo_d = square_to_cosine_hemisphere(u2)
        wo = dr.select(specular, reflect(wi), wo_d)
        f_o = fresnel_dielectric(wo_d.z, eta)[0]
        w_spec = self._tex("spec", ctx, idx, ok & specular) * (f_i / p_spec)
        w_diff = self._diffuse_term(ctx, idx, eta, fdr_int, f_i, f_o, ok & ~specular) / (1.0 - p_spec)
        pdf = dr.select(specular, p_spec, (1.0 - p_spec) * cosine_hemisphere_pdf(wo_d))
        w = dr.select(specular, w_spec, w_diff)
        ok &= pdf > 0
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), mi.Float(1.0), specular, dr.select(ok, w, 0.0))
