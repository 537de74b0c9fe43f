"""``diffusetransmission`` (pbrt-v4's name and parameters): a Lambertian reflector and a
Lambertian transmitter in one, for thin translucent sheets (leaves, paper, lamp shades).

    f(wi, wo) = r / pi   if wi and wo lie on the same side of the surface,
                t / pi   otherwise,

with ``r = clamp(scale * reflectance, 0, 1)`` and ``t = clamp(scale * transmittance, 0, 1)``
(``reflectance`` and ``transmittance`` are spectrum textures, default 0.25; ``scale`` is a
float, default 1). The BSDF is two-sided by nature (it needs no ``twosided`` wrapper):
light arriving from either side is reflected with albedo r and transmitted with albedo t.

Sampling follows pbrt-v4's ``DiffuseTransmissionBxDF``: the reflection lobe is chosen with
probability ``max(r) / (max(r) + max(t))`` (maxima over the sampled wavelengths), then a
cosine-distributed direction on that side; the density is that probability times the
cosine density, and the weight ``f |cos| / pdf`` is ``r / P(reflect)`` or ``t / P(transmit)``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..sampling import square_to_cosine_hemisphere, cosine_hemisphere_pdf
from ..textures import load_spectrum
from .base import BSDF_TYPES, BSDFType, BSDFSample, REFLECTION, TRANSMISSION, DIFFUSE


@BSDF_TYPES.register("diffusetransmission")
class DiffuseTransmission(BSDFType):
    """``diffusetransmission`` (pbrt-v4's): cosine lobes on both sides of the surface.

    =============  =======  =======  ================================================
    name           type     default  meaning
    =============  =======  =======  ================================================
    reflectance    texture  0.25     albedo of the reflected lobe
    transmittance  texture  0.25     albedo of the transmitted lobe
    scale          float    1        factor on both (each clamped to [0, 1] after it)
    =============  =======  =======  ================================================
    """

    name = "diffusetransmission"
    flags = REFLECTION | TRANSMISSION | DIFFUSE

    def add(self, loader, props) -> int:
        r = load_spectrum(loader, props.raw("reflectance", 0.25), props.key("reflectance"), emitter=False)
        t = load_spectrum(loader, props.raw("transmittance", 0.25), props.key("transmittance"), emitter=False)
        scale = props.float("scale", 1.0, min=0.0)
        props.finish()
        self.instances.append({"reflectance": r, "transmittance": t, "scale": scale})
        return len(self.instances) - 1

    def build(self) -> None:
        self.reflectance = mi.UInt32([i["reflectance"] for i in self.instances])
        self.transmittance = mi.UInt32([i["transmittance"] for i in self.instances])
        self.scale = mi.Float([i["scale"] for i in self.instances])
        self.any_scale = any(i["scale"] != 1.0 for i in self.instances)

    def _albedos(self, ctx, idx, active):
        """(r, t), each clamped to [0, 1] after scaling, as in pbrt-v4."""
        out = []
        for name in ("reflectance", "transmittance"):
            slot = dr.gather(mi.UInt32, getattr(self, name), idx, active)
            v = self.textures.eval(slot, ctx.si, ctx.wl.lambda_, active, illuminant=False,
                                   reach=tuple(i[name] for i in self.instances))
            if self.any_scale:
                v = v * dr.gather(mi.Float, self.scale, idx, active)
            out.append(dr.clip(v, 0.0, 1.0))
        return out

    @staticmethod
    def _prob_reflect(r, t):
        """P(reflection lobe) and whether either lobe can be sampled at all."""
        pr, pt = dr.max(r), dr.max(t)
        total = pr + pt
        return pr * dr.rcp(dr.select(total > 0, total, 1.0)), total > 0

    @classmethod
    def _eval(cls, r, t, wi, wo):
        p_r, any_lobe = cls._prob_reflect(r, t)
        same = wi.z * wo.z > 0
        ok = any_lobe & (wi.z != 0) & (wo.z != 0)
        cos_o = dr.abs(wo.z)
        f = dr.select(same, r, t) * (dr.inv_pi * cos_o)
        pdf = dr.select(same, p_r, 1.0 - p_r) * (dr.inv_pi * cos_o)
        return dr.select(ok, f, 0.0), dr.select(ok, pdf, 0.0)

    @classmethod
    def _sample(cls, r, t, wi, u1, u2):
        p_r, any_lobe = cls._prob_reflect(r, t)
        reflect = u1 < p_r
        local = square_to_cosine_hemisphere(u2)
        # Same side as wi for reflection, the opposite side for transmission.
        flip = (wi.z < 0) == reflect
        wo = mi.Vector3f(local.x, local.y, dr.select(flip, -local.z, local.z))
        p_lobe = dr.select(reflect, p_r, 1.0 - p_r)
        ok = any_lobe & (wi.z != 0) & (local.z > 0) & (p_lobe > 0)
        pdf = p_lobe * cosine_hemisphere_pdf(local)
        weight = dr.select(reflect, r, t) * dr.rcp(dr.select(ok, p_lobe, 1.0))
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), mi.Float(1.0), mi.Bool(False), dr.select(ok, weight, 0.0))

    def eval_pdf(self, ctx, idx, wo, active):
        r, t = self._albedos(ctx, idx, active)
        return self._eval(r, t, ctx.si.wi, wo)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        r, t = self._albedos(ctx, idx, active)
        return self._sample(r, t, ctx.si.wi, u1, u2)

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        r, t = self._albedos(ctx, idx, active)
        f, pdf = self._eval(r, t, ctx.si.wi, wo)
        return f, pdf, self._sample(r, t, ctx.si.wi, u1, u2)
