"""``aov``: arbitrary output variables of the surfaces camera rays see (Mitsuba's ``aov``).

``aovs`` is a comma-separated list of ``name:type`` pairs; nested integrators (any
number, each under its own key) render radiance alongside. The image is an (H, W, C)
tensor, in Mitsuba 3.9's channel order: the R, G, B of each nested integrator in the
order given, then the AOV channels in the order of ``aovs`` (:attr:`AOVIntegrator.channels`
names them, e.g. ``dd.y.T``, ``nn.X``). Without a nested integrator only the AOVs are
returned. Every channel is developed with the film's filter, like the radiance, so a
pixel holds the filter-weighted average over its samples (fractional at edges). The
scene's light sampler is the first nested integrator's.

Types and conventions (as Mitsuba's, values 0 where the camera ray misses):

* ``depth`` (T): distance along the camera ray from the near plane (``si.t``);
* ``position`` (X, Y, Z), ``uv`` (U, V), ``geo_normal`` (X, Y, Z), ``dp_du``, ``dp_dv``:
  the surface interaction's;
* ``sh_normal`` (X, Y, Z): the shading normal after the BSDF's normal or bump map;
* ``prim_index`` (I): the primitive (triangle) index;
* ``shape_index`` (I): 1 + the shape's index in the scene description (0: no hit), as
  Mitsuba's scalar variants; Mitsuba's JIT variants return a registry id instead;
* ``albedo`` (R, G, B): a one-sample estimate of the BSDF's directional albedo
  (the weight f cos / pdf of one BSDF sample, exact for ``diffuse``: its reflectance),
  developed like radiance, i.e. as Mitsuba treats its ``eval_diffuse_reflectance``
  spectrum. Mitsuba evaluates the BSDF toward the normal instead, so the two agree for
  ``diffuse`` only.

Mitsuba's ``duv_dx``/``duv_dy`` need ray differentials, which pbr's camera does not
produce; they are rejected. AOVs have no gradients.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from .. import spectrum as spec
from .base import INTEGRATORS, SamplingIntegrator, PRIMAL

# AOV type -> channel suffixes (Mitsuba's aov.cpp).
AOV_TYPES = {
    "albedo": "RGB", "depth": "T", "position": "XYZ", "uv": "UV", "geo_normal": "XYZ", "sh_normal": "XYZ",
    "dp_du": "XYZ", "dp_dv": "XYZ", "prim_index": "I", "shape_index": "I",
}


@INTEGRATORS.register("aov")
class AOVIntegrator(SamplingIntegrator):
    name = "aov"

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
        self.nested = []
        for key, child in props.children():
            t = child["type"]
            if t not in INTEGRATORS:
                raise props.error(key, f"expected a nested integrator, got {t!r}")
            if t == self.name:
                raise props.error(key, "an 'aov' integrator cannot be nested in another")
            self.nested.append((key, INTEGRATORS[t](props.child(key))))
        props.finish()
        if not self.aovs and not self.nested:
            raise props.error("aovs", "no AOV and no nested integrator given")
        # A scene builds one light sampler: the first nested integrator's (the choice
        # changes the others' noise, not their expectation).
        self.light_sampler = self.nested[0][1].light_sampler if self.nested else "uniform"
        self.channels = [f"{key}.{c}" for key, _ in self.nested for c in "RGB"]
        self.channels += [f"{name}.{c}" for name, kind in self.aovs for c in AOV_TYPES[kind]]

    def check(self, scene) -> None:
        super().check(scene)
        for _, integrator in self.nested:
            integrator.check(scene)

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        """(H, W, len(channels)) tensor: nested RGB, then AOVs (module docstring)."""
        for _, integ in self.nested:
            integ._plan(scene, sensor, spp)   # integrators that prepare per sensor (media)

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
        ctx = ShadingContext(si, wl, scene.textures)
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
                u2 = mi.Point2f(rng.next_float32(), rng.next_float32())
                bs = bsdfs.sample(bsdf_id, ctx, u1, u2, hit)
                rho = dr.select(bs.pdf > 0, bs.weight, 0.0)
                v = list(spec.xyz_to_srgb(spec.to_xyz(rho, wl)))
            out += [dr.select(hit, mi.Float(c), 0.0) for c in v]
        return out
