"""The light interface (one family per module, vectorised over its instances).

``sample_Li(idx, ref, u, wl, active)`` returns a :class:`LightSample`: radiance ``L``
arriving at ``ref`` from a sampled point of the light, the world direction ``wi`` toward it,
its solid-angle density ``pdf`` (excluding the light sampler's pick probability), the
point ``p`` to trace a shadow ray to, and ``delta`` for lights that are Dirac deltas in
position or direction (no MIS with BSDF sampling). ``pdf_Li`` gives the same density for a
surface point (area lights) or a direction (infinite lights) found by BSDF sampling.
``L`` is the radiance an area light emits at a surface hit; ``Le`` the radiance an
infinite light sends along an escaped ray.
"""

from __future__ import annotations

import mitsuba as mi

from ..backend import VariantStruct


class LightSample(metaclass=VariantStruct):
    _fields = {"L": "Spectrum", "wi": "Vector3f", "pdf": "Float", "p": "Point3f", "delta": "Bool"}

    def __init__(self, L=None, wi=None, pdf=None, p=None, delta=None):
        self.L = L if L is not None else mi.Spectrum(0)
        self.wi = wi if wi is not None else mi.Vector3f(0)
        self.pdf = pdf if pdf is not None else mi.Float(0)
        self.p = p if p is not None else mi.Point3f(0)
        self.delta = delta if delta is not None else mi.Bool(False)


class LightType:
    """A light family: its instances and their parameter table."""

    name = ""
    delta = False      # Dirac delta in position or direction (no MIS needed)
    infinite = False   # emits along rays that leave the scene (Le)
    textures = None    # the scene's TextureSet, set by LightSet.build

    def __init__(self):
        self.instances: list = []

    def add(self, loader, props, shape_index=None) -> int:
        raise NotImplementedError

    def build(self, scene) -> None:
        pass

    def power(self, i: int, scene) -> float:
        """Approximate emitted power of instance ``i`` (W; for the power/BVH samplers)."""
        raise NotImplementedError

    def bounds(self, i: int, scene):
        """pbrt-v4 LightBounds of instance ``i`` for the BVH sampler (None: infinite)."""
        return None

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        raise NotImplementedError

    def pdf_Li(self, idx, ref_p, si, active):
        return mi.Float(0.0)

    def Le(self, idx, d, wl, active):
        """Radiance along direction ``d`` of a ray that left the scene (infinite lights)."""
        return mi.Spectrum(0.0)

    def pdf_Le_dir(self, idx, d, active):
        """Solid-angle density of ``sample_Li`` choosing direction ``d`` (infinite lights)."""
        return mi.Float(0.0)
