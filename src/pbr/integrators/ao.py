"""``ambientocclusion``: pbrt-v4's AOIntegrator.

At the surface a camera ray sees (``null`` surfaces are passed through), one direction
is drawn on the hemisphere about the geometric normal turned toward the camera (cosine-
weighted with ``cossample``, the default, else uniform), and a shadow ray of length
``maxdistance`` (default: unbounded) is traced. The estimate, ``cos(theta) / (pi pdf)``
where the ray is free and 0 elsewhere, has the expectation

    AO = (1/pi) * integral over the hemisphere of V(w) cos(theta) dw,

the cosine-weighted unoccluded fraction (1 on an open plane, 0 in a closed box). As in
pbrt-v4 it is returned times the illuminant of the film's colour space scaled to unit
luminance: D65 for sRGB, so an unoccluded point is white, (1, 1, 1). Rays that miss the
scene give 0. Participating media are ignored (AO measures geometry only).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..sampling import cosine_hemisphere_pdf, square_to_cosine_hemisphere
from ..spectrum import d65
from .base import INTEGRATORS, SamplingIntegrator


@INTEGRATORS.register("ambientocclusion")
class AOIntegrator(SamplingIntegrator):
    """``ambientocclusion`` (pbrt-v4's ``AOIntegrator``): the cosine-weighted unoccluded
    fraction of the hemisphere at the surface a camera ray sees, times a unit-luminance
    white (1 on an open plane, 0 in a closed box).

    ===========  =====  =======  ===========================================================
    name         type   default  meaning
    ===========  =====  =======  ===========================================================
    cossample    bool   true     cosine-weighted directions (else uniform on the hemisphere)
    maxdistance  float  inf      length of the occlusion rays
    ===========  =====  =======  ===========================================================
    """

    name = "ambientocclusion"
    light_sampler_type = "uniform"   # lights play no part

    def __init__(self, props):
        super().__init__(props)
        self.cos_sample = props.bool("cossample", True)
        self.max_distance = props.float("maxdistance", min=0.0) if props.has("maxdistance") else math.inf
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        return self._sample(scene, rng, ray, wl, active)

    def _direction(self, u):
        """A local direction on the hemisphere (z up) and its density."""
        if self.cos_sample:
            w = square_to_cosine_hemisphere(u)
            return w, cosine_hemisphere_pdf(w)
        return mi.warp.square_to_uniform_hemisphere(u), mi.Float(0.5 / math.pi)

    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active):
        geo, bsdfs = scene.geometry, scene.bsdfs
        ray = mi.Ray3f(ray)
        si, shape = geo.intersect(ray, active)
        if bsdfs.has_null:
            # Surfaces without a BSDF (medium boundaries) are not shaded: look past them.
            skip = active & si.is_valid()
            skip &= bsdfs.is_null(dr.gather(mi.UInt32, scene.shape_bsdf, shape, skip), skip)
            while dr.hint(skip, label="ao_skip_null"):
                si_next, shape_next = geo.intersect(si.spawn_ray(ray.d), skip)
                si = dr.select(skip, si_next, si)
                shape = dr.select(skip, shape_next, shape)
                skip &= si.is_valid()
                skip &= bsdfs.is_null(dr.gather(mi.UInt32, scene.shape_bsdf, shape, skip), skip)
        hit = active & si.is_valid()

        u = rng.next_2d()
        w_local, pdf = self._direction(u)
        n = dr.select(dr.dot(si.n, ray.d) > 0, -si.n, si.n)
        wi = mi.Frame3f(n).to_world(w_local)
        shadow = si.spawn_ray(wi)
        if self.max_distance < math.inf:
            shadow.maxt = self.max_distance
        free = hit & (pdf > 0)
        free &= ~geo.occluded(shadow, free)
        value = w_local.z * dr.rcp(math.pi * pdf)
        return dr.select(free, d65(wl.lambda_) * value, 0.0), hit
