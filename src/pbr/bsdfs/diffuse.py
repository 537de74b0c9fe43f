"""``diffuse``: the Lambertian reflector (one-sided, as in Mitsuba: it reflects light
only on the side its shading normal points to)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..sampling import square_to_cosine_hemisphere, cosine_hemisphere_pdf
from ..textures import load_spectrum
from .base import BSDF_TYPES, BSDFType, BSDFSample, REFLECTION, DIFFUSE


@BSDF_TYPES.register("diffuse")
class Diffuse(BSDFType):
    """``diffuse``: the Lambertian reflector (one-sided).

    ===========  =======  =======  =======
    name         type     default  meaning
    ===========  =======  =======  =======
    reflectance  texture  0.5      albedo
    ===========  =======  =======  =======
    """

    name = "diffuse"
    flags = REFLECTION | DIFFUSE

    def add(self, loader, props) -> int:
        slot = load_spectrum(loader, props.raw("reflectance", 0.5), props.key("reflectance"), emitter=False)
        props.finish()
        self.instances.append({"reflectance": slot})
        return len(self.instances) - 1

    def build(self) -> None:
        self.reflectance = mi.UInt32([i["reflectance"] for i in self.instances])
        self.reflectance_reach = tuple(i["reflectance"] for i in self.instances)

    def _albedo(self, ctx, idx, active):
        slot = dr.gather(mi.UInt32, self.reflectance, idx, active)
        return self.textures.eval(slot, ctx.si, ctx.wl.lambda_, active, illuminant=False,
                                  reach=self.reflectance_reach)

    @staticmethod
    def _eval(albedo, wi, wo):
        ok = (wi.z > 0) & (wo.z > 0)
        return dr.select(ok, albedo * (dr.inv_pi * wo.z), 0.0), dr.select(ok, cosine_hemisphere_pdf(wo), 0.0)

    @staticmethod
    def _sample(albedo, wi, u2):
        wo = square_to_cosine_hemisphere(u2)
        ok = (wi.z > 0) & (wo.z > 0)
        # f cos / pdf = albedo for a cosine-distributed direction.
        return BSDFSample(wo, dr.select(ok, cosine_hemisphere_pdf(wo), 0.0), mi.Float(1.0), mi.Bool(False),
                          dr.select(ok, albedo, 0.0))

    def eval_pdf(self, ctx, idx, wo, active):
        return self._eval(self._albedo(ctx, idx, active), ctx.si.wi, wo)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        return self._sample(self._albedo(ctx, idx, active), ctx.si.wi, u2)

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        albedo = self._albedo(ctx, idx, active)
        f, pdf = self._eval(albedo, ctx.si.wi, wo)
        return f, pdf, self._sample(albedo, ctx.si.wi, u2)
