"""``point``: an isotropic point light (Mitsuba's ``point``).

Parameters: ``intensity`` (W/sr; a spectrum, RGB in the illuminant form as Mitsuba),
``position`` or ``to_world`` (only its translation), and pbrt-v4's photometric
``scale`` (a multiplier) and ``power`` (total emitted power: the intensity is rescaled
so that ``4 pi I_v = power``, where ``I_v`` is the luminance of the intensity spectrum
without its RGB multiplier, exactly as pbrt-v4's ``SpectrumToPhotometric``; unlike
pbrt-v4 the spectrum is *not* normalised when ``power`` is absent, as in Mitsuba).

Every delta light samples the single direction toward the light with ``pdf = 1``
(``delta = True``: the integrator skips MIS and multiplies by the light sampler's
probability); radiance ``L = I(w) / d^2``; lanes where the light sends nothing get
``pdf = 0`` so that no shadow ray is traced. ``pdf_Li`` is 0 (BSDF sampling never hits
a delta light).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from .base import (LIGHT_TYPES, DeltaPositionLight, LightSample, light_frame, load_constant_emission, luminance,
                   max_value, point_bounds, power_factor)


# ------------------------------------------------------------------------ point

@LIGHT_TYPES.register("point")
class PointLight(DeltaPositionLight):
    name = "point"

    def add(self, loader, props, shape_index=None) -> int:
        slot = load_constant_emission(loader, props, "intensity")
        m = light_frame(props, allow_position=True)
        factor = power_factor(props, loader.textures, slot, 4.0 * math.pi)
        props.finish()
        self.instances.append({"slot": slot, "to_world": m, "factor": factor})
        return len(self.instances) - 1

    def build(self, scene) -> None:
        self._base_tables()

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        return 4.0 * math.pi * inst["factor"] * luminance(scene.textures, inst["slot"])

    def bounds(self, i: int, scene):
        inst = self.instances[i]
        phi = 4.0 * math.pi * inst["factor"] * max_value(scene.textures, inst["slot"])
        return point_bounds(self._position(i), (0, 0, 1), phi, -1.0, 0.0)

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        p, wi, inv_dist2, ok = self._toward(idx, ref, active)
        L = self._intensity(idx, wl, ok) * inv_dist2
        return LightSample(dr.select(ok, L, 0.0), wi, dr.select(ok, 1.0, 0.0), p, mi.Bool(True))
