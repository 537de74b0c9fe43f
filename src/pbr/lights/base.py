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

from ..backend import Struct
from ..plugins.registry import Registry

# Type name -> light family (each family registers itself in its module).
LIGHT_TYPES = Registry("emitter")


class LightSample(Struct):
    _fields = {"L": "Spectrum", "wi": "Vector3f", "pdf": "Float", "p": "Point3f", "delta": "Bool"}


class LightType:
    """A light family: its instances and their parameter table."""

    name = ""
    delta = False      # Dirac delta in position or direction (no MIS needed)
    infinite = False   # emits along rays that leave the scene (Le)
    textures = None    # the scene's TextureSet, set by LightSet.build
    traces_rays_in = ()  # methods that trace rays: LightSet calls them outside its dr.switch

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

    # -- emission, for light tracing (see LeSample) -----------------------------------------
    emits_rays = False  # whether the family implements sample_Le / pdf_Le

    def sample_Le(self, idx, u_pos, u_dir, wl, active) -> "LeSample":
        """A ray leaving the light (``pmf``, ``weight`` and ``light`` are filled in by
        ``LightSet.sample_Le``)."""
        raise NotImplementedError

    def pdf_Le(self, idx, p, n, d, active):
        """(pdf_pos, pdf_dir) with which ``sample_Le`` produces the ray (p, d); ``n``: the
        surface normal at ``p`` (area lights)."""
        raise NotImplementedError


class LeSample(Struct):
    """A ray leaving a light (pbrt-v4's ``SampleLe``, Mitsuba's ``sample_ray``), for light
    tracing, BDPT and photon mapping.

    ``o``, ``d``: the ray (origin on the light, unit direction away from it); ``L``: the
    radiance (area, infinite lights), intensity (W/sr, point-like lights) or irradiance
    (W/m^2, directional) carried along it at the sampled wavelengths; ``pdf_pos``: area
    density of ``o`` (1/m^2; 1 for delta-position lights); ``pdf_dir``: solid-angle density
    of ``d`` (1/sr; 1 for delta-direction lights); ``pmf``: the probability of having
    picked this light; ``n``: the light's surface normal at ``o`` on its emitting side
    (area lights), the ray direction (directional and infinite lights: the normal of the
    disk ``o`` lies on), 0 for point-like lights; ``weight`` = ``L |n . d| / (pmf pdf_pos
    pdf_dir)`` with ``|n . d|`` read as 1 for point-like lights: the throughput a light
    path starts with (Mitsuba's ray weight). Flags: ``delta_pos``, ``delta_dir``,
    ``infinite``; ``light``: the light's index (as in ``LightSet``)."""

    _fields = {"o": "Point3f", "d": "Vector3f", "L": "Spectrum", "pdf_pos": "Float", "pdf_dir": "Float",
               "pmf": "Float", "n": "Normal3f", "weight": "Spectrum", "delta_pos": "Bool", "delta_dir": "Bool",
               "infinite": "Bool", "light": "UInt32"}
