"""``randomwalk``: pbrt-v4's RandomWalkIntegrator, the simplest unbiased path tracer.

At each surface the path adds the emitted radiance and continues in a direction drawn
uniformly from the whole sphere (density 1/(4 pi)), weighted by f |cos| / pdf; there is
no light sampling, no MIS and no Russian roulette. Delta lobes (mirrors, glass) are
never sampled, so such surfaces show only their own emission. Rays leave the scene
through the infinite lights. ``null`` surfaces are crossed unchanged (they count as a
vertex, as pbrt-v4's SimplePath does).

Depth: pbrt-v4's ``maxdepth`` (default 5) or Mitsuba's ``max_depth`` = ``maxdepth`` + 1
(see :func:`pbr.integrators.base.pbrt_max_depth`). ``hide_emitters`` (Mitsuba's):
camera rays pass through emitting surfaces and do not see the environment.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from .base import INTEGRATORS, SamplingIntegrator, loop_ray, nonzero, path_state, pbrt_max_depth, ray_state
from .direct import add_unweighted_emission


@INTEGRATORS.register("randomwalk")
class RandomWalkIntegrator(SamplingIntegrator):
    """``randomwalk`` (pbrt-v4's ``RandomWalkIntegrator``): directions drawn uniformly on the
    sphere, no light sampling, no MIS, no Russian roulette. Surfaces only.

    =============  ====  =======  =========================================================
    name           type  default  meaning
    =============  ====  =======  =========================================================
    maxdepth       int   5        pbrt-v4's depth: bounces (0: emitters seen directly)
    max_depth      int   -        Mitsuba's depth instead (= maxdepth + 1)
    hide_emitters  bool  false    camera rays pass through emitting surfaces and do not see
                                  the environment
    =============  ====  =======  =========================================================
    """

    name = "randomwalk"
    surfaces_only = True
    light_sampler_type = "uniform"   # no light sampling

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = pbrt_max_depth(props)
        self.hide_emitters = props.bool("hide_emitters", False)
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if self.max_depth == 0:
            return mi.Spectrum(0.0), dr.zeros(mi.Bool, dr.width(active))
        return self._sample(scene, rng, ray, wl, active)

    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active):
        geo, bsdfs = scene.geometry, scene.bsdfs
        ray, active, L, beta, depth, valid = path_state(ray, active)
        # Loop state: only what a bounce changes (see path); the ifs on Python values
        # are plain ifs, so that the excluded variables they read stay outside.
        ray_var, ray_fixed = ray_state(ray)
        rng_state = rng.loop_state()
        while dr.hint(active, label="randomwalk", exclude=[ray, ray_fixed, rng, wl]):
            ray = loop_ray(ray_var, ray_fixed)
            rng.set_loop_state(rng_state)
            si, shape = geo.intersect(ray, active)
            hit = active & si.is_valid()
            valid |= hit
            L, skip = add_unweighted_emission(L, scene, si, shape, ray, wl, active, hit, depth, beta,
                                              self.hide_emitters)

            go = hit & ~skip & (depth + 1 < self.max_depth)
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, go)
            null = bsdfs.is_null(bsdf_id, go)
            wp = mi.warp.square_to_uniform_sphere(rng.next_2d())
            ctx = ShadingContext(si, wl)
            f = bsdfs.eval_pdf(bsdf_id, ctx, si.to_local(wp), go & ~null)[0]
            beta[go & ~null] = beta * f * (4.0 * math.pi)
            through = skip | null
            ray = dr.select(through, si.spawn_ray(ray.d), si.spawn_ray(wp))
            ray_var = ray_state(ray)[0]
            depth[hit & ~skip] = depth + 1
            active = through | (go & nonzero(beta))
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)
        return L, valid
