"""``point``: an isotropic point light (Mitsuba's ``point``). pbrt-v4's photometric
``power`` rescales the intensity so that ``4 pi I_v = power`` (``I_v``: the luminance of
the spectrum without its RGB multiplier, as pbrt-v4's ``SpectrumToPhotometric``); unlike
pbrt-v4 the spectrum is *not* normalised when ``power`` is absent, as in Mitsuba."""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from .base import (LIGHT_TYPES, DeltaPositionLight, LightSample, light_frame, load_constant_emission, luminance,
                   max_value, point_bounds, power_factor)


# ------------------------------------------------------------------------ point

@LIGHT_TYPES.register("point")
class PointLight(DeltaPositionLight):
    """``point``: an isotropic point light (Mitsuba's). ``L = I / d^2``.

    =========  =========  ========  ========================================================
    name       type       default   meaning
    =========  =========  ========  ========================================================
    intensity  spectrum   1         radiant intensity (W/sr); not spatially varying
    position   point      -         the light's position (instead of to_world)
    to_world   transform  identity  only its translation is used
    scale      float      1         pbrt-v4's factor on the emitted spectrum
    power      float      -         pbrt-v4's total emitted power (W): rescales the spectrum
                                    (photometric: its luminance without the RGB multiplier)
    =========  =========  ========  ========================================================
    """

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
