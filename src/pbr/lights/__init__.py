"""Light families and :class:`LightSet`, the per-scene collection of lights."""

from __future__ import annotations

import numpy as np
import drjit as dr
import mitsuba as mi

from .area import AreaLight
from .lightsamplers import LightSampler, LIGHT_SAMPLERS  # noqa: F401

LIGHT_TYPES = {"area": AreaLight}


class LightSet:
    """All lights of a scene. Only area lights exist so far: ``light index`` is the
    index into the area family, and ``shape_light`` maps a shape to its light (+1, 0 = none)."""

    def __init__(self):
        self.area = AreaLight()

    def __len__(self):
        return len(self.area.instances)

    def build(self, scene, sampler_kind: str) -> None:
        self.area.build(scene)
        powers = np.array([self.area.power(i, scene) for i in range(len(self))])
        self.sampler = LightSampler(sampler_kind, powers)

    def L(self, light, si, wl, textures, active):
        return self.area.L(light, si, wl, textures, active)

    def sample_Li(self, ref, u1, u2, wl, textures, active):
        """Pick a light and sample it; the returned pdf includes the pick probability."""
        light, pmf, _ = self.sampler.sample(u1, active)
        ls = self.area.sample_Li(light, ref, u2, wl, textures, active)
        ls.pdf = ls.pdf * pmf
        return ls

    def pdf_Li(self, light, ref_p, si, active):
        return self.sampler.pmf(light, active) * self.area.pdf_Li(light, ref_p, si, active)
