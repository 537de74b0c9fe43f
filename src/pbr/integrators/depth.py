"""``depth``: the distance from the camera to the first surface each camera ray hits
(Mitsuba's ``depth``), 0 where it hits nothing. Conventions: docs/integrators.md."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .base import INTEGRATORS, SamplingIntegrator


@INTEGRATORS.register("depth")
class DepthIntegrator(SamplingIntegrator):
    """``depth`` (Mitsuba's): the distance along each camera ray, from its origin on the
    near clip plane, to the first surface (any surface: no BSDF is looked at); a miss is
    0 and still counts in the pixel's average. Returned as a constant spectrum, which the
    film develops like radiance: in Mitsuba's spectral variants (pbr's reference) about
    t (1.20, 0.95, 0.91) in linear sRGB, noisy with the sampled wavelengths; ``aov``'s
    ``depth`` channel is the plain distance. No parameters, no derivatives."""

    name = "depth"
    light_sampler_type = "uniform"   # lights play no part

    def __init__(self, props):
        super().__init__(props)
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        scene.geometry.check_current()
        pi = scene.geometry.mi_scene.ray_intersect_preliminary(ray, False, active)
        hit = active & pi.is_valid()
        return mi.Spectrum(dr.select(hit, pi.t, 0.0)), hit
