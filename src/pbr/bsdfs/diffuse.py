"""``diffuse``: the Lambertian reflector (one-sided, as in Mitsuba: it reflects light
only on the side its shading normal points to)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..sampling import square_to_cosine_hemisphere, cosine_hemisphere_pdf
from ..textures import load_spectrum
from .base import BSDFType, BSDFSample, REFLECTION, DIFFUSE


class Diffuse(BSDFType):
    name = "diffuse"
    flags = REFLECTION | DIFFUSE

    def add(self, loader, props) -> int:
        slot = load_spectrum(loader, props.raw("reflectance", 0.5), props.key("reflectance"), emitter=False)
        props.finish()
        self.instances.append({"reflectance": slot})
        return len(self.instances) - 1

    def build(self) -> None:
        self.reflectance = mi.UInt32([i["reflectance"] for i in self.instances])

    def _albedo(self, ctx, idx, active):
        slot = dr.gather(mi.UInt32, self.reflectance, idx, active)
        return ctx.textures.eval(slot, ctx.si.uv, ctx.wl.lambda_, active)

    def eval_pdf(self, ctx, idx, wo, active):
        wi = ctx.si.wi
        active = active & (wi.z > 0) & (wo.z > 0)
        f = self._albedo(ctx, idx, active) * (dr.inv_pi * wo.z)
        return dr.select(active, f, 0.0), dr.select(active, cosine_hemisphere_pdf(wo), 0.0)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        wo = square_to_cosine_hemisphere(u2)
        active = active & (ctx.si.wi.z > 0) & (wo.z > 0)
        pdf = cosine_hemisphere_pdf(wo)
        # f cos / pdf = albedo for a cosine-distributed direction.
        w = self._albedo(ctx, idx, active)
        return BSDFSample(wo, dr.select(active, pdf, 0.0), mi.Float(1.0), mi.Bool(False),
                          dr.select(active, w, 0.0))
