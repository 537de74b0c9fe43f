"""The light interface.

``sample_Li(ref, u, wl)`` returns a :class:`LightSample` (incident radiance ``L`` from a
point on the light, the world direction ``wi`` toward it, its solid-angle ``pdf`` and the
point ``p`` for the shadow ray); ``pdf_Li(ref, si)`` gives the same density for a
direction that hit the light by BSDF sampling; ``L(si, wl)`` is the emitted radiance at
a surface hit. Densities here exclude the light sampler's probability of the light.
"""

from __future__ import annotations

import mitsuba as mi

from ..backend import VariantStruct


class LightSample(metaclass=VariantStruct):
    _fields = {"L": "Spectrum", "wi": "Vector3f", "pdf": "Float", "p": "Point3f"}

    def __init__(self, L=None, wi=None, pdf=None, p=None):
        self.L = L if L is not None else mi.Spectrum(0)
        self.wi = wi if wi is not None else mi.Vector3f(0)
        self.pdf = pdf if pdf is not None else mi.Float(0)
        self.p = p if p is not None else mi.Point3f(0)


class LightType:
    """A light family: its instances and their parameter table."""

    name = ""
    delta = False      # Dirac delta in position or direction (no MIS needed)
    infinite = False

    def __init__(self):
        self.instances: list = []

    def build(self, scene) -> None:
        pass

    def power(self, i: int, scene) -> float:
        """Approximate emitted power of instance ``i`` (for the power light sampler)."""
        raise NotImplementedError
