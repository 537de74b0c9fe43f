"""``aov``: arbitrary output variables of the surfaces camera rays see (Mitsuba's
``aov``), after the radiance of nested integrators, in Mitsuba 3.9's channel order.
Types and conventions: docs/integrators.md.
"""

from __future__ import annotations

import mitsuba as mi

from .. import spectrum as spec
from .base import INTEGRATORS, PRIMAL, NestingIntegrator, nested_integrators
from .surface import surface_channels

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
    supports_films = False        # develops its own channels (RGB films only)
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
        return surface_channels(scene, rng, ray, wl, [kind for _, kind in self.aovs], active)
