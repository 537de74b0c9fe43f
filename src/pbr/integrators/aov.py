"""``aov``: arbitrary output variables of the surfaces camera rays see (Mitsuba's
``aov``), after the radiance of nested integrators, in Mitsuba 3.9's channel order.
Types and conventions: docs/integrators.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from .. import spectrum as spec
from .base import INTEGRATORS, PRIMAL, NestingIntegrator, nested_integrators

# AOV type -> channel suffixes (Mitsuba's aov.cpp).
AOV_TYPES = {
    "albedo": "RGB", "depth": "T", "position": "XYZ", "uv": "UV", "geo_normal": "XYZ", "sh_normal": "XYZ",
    "dp_du": "XYZ", "dp_dv": "XYZ", "prim_index": "I", "shape_index": "I",
}


@INTEGRATORS.register("aov")
class AOVIntegrator(NestingIntegrator):
    """``aov`` (Mitsuba's): arbitrary output variables of the surfaces camera rays see,
    after the R, G, B of the nested integrators (any number, each under its own key);
    :attr:`channels` names the channels.

    =========  ======  =======  ========================================================
    name       type    default  meaning
    =========  ======  =======  ========================================================
    aovs       string  ''       comma-separated 'name:type' pairs; types: albedo, depth,
                                position, uv, geo_normal, sh_normal, dp_du, dp_dv,
                                prim_index, shape_index
    (any key)  plugin  -        a nested integrator rendered alongside
    =========  ======  =======  ========================================================
    """

    name = "aov"
    light_sampler_type = "uniform"   # the AOVs sample no light; nested integrators use their own

    def __init__(self, props):
        super().__init__(props)
        self.aovs = []
        for token in props.string("aovs", "").split(","):
            token = token.strip()
            if not token:
                continue
            name, _, kind = token.partition(":")
            name, kind = name.strip(), kind.strip()
            if not name or not kind:
                raise props.error("aovs", f"expected 'name:type' pairs, got {token!r}")
            if kind not in AOV_TYPES:
                raise props.error("aovs", f"unknown AOV type {kind!r} in {token!r} "
                                          f"(supported: {', '.join(AOV_TYPES)})")
            self.aovs.append((name, kind))
        self.nested = nested_integrators(
            props, lambda t, _: "an 'aov' integrator cannot be nested in another" if t == self.name else None)
        props.finish()
        if not self.aovs and not self.nested:
            raise props.error("aovs", "no AOV and no nested integrator given")
        self.channels = [f"{key}.{c}" for key, _ in self.nested for c in "RGB"]
        self.channels += [f"{name}.{c}" for name, kind in self.aovs for c in AOV_TYPES[kind]]

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        """(H, W, len(channels)) tensor: nested RGB, then AOVs (module docstring)."""
        self.prepare(scene, sensor)

        def radiance(rng, ray, wl, inside):
            L, extra = mi.Spectrum(0.0), []
            for i, (_, integ) in enumerate(self.nested):
                Li = integ.sample(scene, rng, mi.Ray3f(ray), wl, PRIMAL, None, None, inside)[0]
                if i == 0:
                    L = Li
                else:   # further radiance images: sRGB per sample (the film is linear)
                    extra += list(spec.xyz_to_srgb(spec.to_xyz(Li, wl)))
            return L, extra + self.sample_aovs(scene, rng, ray, wl, inside)

        img = self._film(scene, sensor, seed, spp, radiance, progress)
        return img if self.nested else img[:, :, 3:]

    def sample_aovs(self, scene, rng, ray, wl, active):
        """Per-sample AOV channels (list of ``mi.Float``) of the surface ``ray`` sees."""
        si, shape = scene.geometry.intersect(ray, active)
        hit = active & si.is_valid()
        bsdfs = scene.bsdfs
        bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
        ctx = ShadingContext(si, wl)
        out = []
        for _, kind in self.aovs:
            if kind == "depth":
                v = [si.t]
            elif kind == "position":
                v = list(si.p)
            elif kind == "uv":
                v = list(si.uv)
            elif kind == "geo_normal":
                v = list(si.n)
            elif kind == "sh_normal":
                v = list(bsdfs.shading_normal(bsdf_id, ctx, hit))
            elif kind == "dp_du":
                v = list(si.dp_du)
            elif kind == "dp_dv":
                v = list(si.dp_dv)
            elif kind == "prim_index":
                v = [mi.Float(si.prim_index)]
            elif kind == "shape_index":
                v = [mi.Float(shape + 1)]
            else:   # albedo
                u1 = rng.next_float32()
                u2 = rng.next_2d()
                bs = bsdfs.sample(bsdf_id, ctx, u1, u2, hit)
                rho = dr.select(bs.pdf > 0, bs.weight, 0.0)
                v = list(spec.xyz_to_srgb(spec.to_xyz(rho, wl)))
            out += [dr.select(hit, mi.Float(c), 0.0) for c in v]
        return out
