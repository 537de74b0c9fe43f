"""``simplepath``: pbrt-v4's SimplePathIntegrator, a path tracer without MIS.

``samplelights`` (default true): at each vertex one light, picked uniformly, is sampled
for direct light; emission found by a path is then counted only after a specular
bounce (or on camera rays), so no light is counted twice. ``samplebsdf`` (default true):
the path continues by BSDF sampling; otherwise by a uniform direction on the sphere
(BSDFs that reflect and transmit) or on the hemisphere of the side the BSDF scatters to
(density 1/(2 pi)), and delta lobes are never followed. All four combinations are
valid; without ``samplelights`` delta lights (point, spot, directional) are never found.
There is no Russian roulette. ``null`` surfaces are crossed as delta transmissions
(they count as a vertex, as in pbrt-v4).

Depth: pbrt-v4's ``maxdepth`` (default 5) or Mitsuba's ``max_depth`` = ``maxdepth`` + 1
(see :func:`pbr.integrators.base.pbrt_max_depth`). ``hide_emitters`` (Mitsuba's):
camera rays pass through emitting surfaces and do not see the environment.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import REFLECTION, TRANSMISSION, ShadingContext
from ..spectrum import first_only
from .base import INTEGRATORS, SamplingIntegrator, light_reaches, loop_ray, nonzero, path_state, pbrt_max_depth, ray_state
from .direct import add_unweighted_emission

# How a direction is drawn without BSDF sampling (per BSDF entry).
HEMI_SAME, HEMI_OTHER, SPHERE = 0, 1, 2


@INTEGRATORS.register("simplepath")
class SimplePathIntegrator(SamplingIntegrator):
    """``simplepath`` (pbrt-v4's ``SimplePathIntegrator``): a path tracer without MIS; lights
    are picked uniformly. Surfaces only.

    =============  ====  =======  ============================================================
    name           type  default  meaning
    =============  ====  =======  ============================================================
    maxdepth       int   5        pbrt-v4's depth: bounces (0: emitters seen directly)
    max_depth      int   -        Mitsuba's depth instead (= maxdepth + 1)
    samplelights   bool  true     sample one light per vertex (emission found by the path then
                                  counts only after specular bounces)
    samplebsdf     bool  true     continue by BSDF sampling (else uniformly on the sphere or
                                  hemisphere)
    hide_emitters  bool  false    camera rays pass through emitting surfaces and do not see
                                  the environment
    =============  ====  =======  ============================================================
    """

    name = "simplepath"
    surfaces_only = True
    light_sampler_type = "uniform"   # pbrt-v4's SimplePath picks lights uniformly

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = pbrt_max_depth(props)
        self.sample_lights = props.bool("samplelights", True)
        self.sample_bsdf = props.bool("samplebsdf", True)
        self.hide_emitters = props.bool("hide_emitters", False)
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if self.max_depth == 0:
            return mi.Spectrum(0.0), dr.zeros(mi.Bool, dr.width(active))
        uniform_kind = None
        if not self.sample_bsdf:
            kinds = [SPHERE if (f & REFLECTION and f & TRANSMISSION) else HEMI_OTHER if f & TRANSMISSION
                     else HEMI_SAME for f in scene.bsdfs.entry_flags()]
            uniform_kind = mi.UInt32(kinds)
        return self._sample(scene, rng, ray, wl, active, uniform_kind)

    @staticmethod
    def _uniform_direction(si, wo, kind, u):
        """(world direction, density) drawn uniformly on the sphere or on the hemisphere
        about the geometric normal on the side ``kind`` asks for relative to ``wo``."""
        d = mi.warp.square_to_uniform_sphere(u)
        n = si.n
        same = dr.dot(wo, n) * dr.dot(d, n) > 0
        flip = ((kind == HEMI_SAME) & ~same) | ((kind == HEMI_OTHER) & same)
        pdf = dr.select(kind == SPHERE, 0.25 / math.pi, 0.5 / math.pi)
        return dr.select(flip, -d, d), pdf

    def _next_direction(self, scene, rng, si, ctx, bsdf_id, wo, uniform_kind, specular, terminated, active):
        """(world direction, throughput weight, specular flag, dispersion-terminated flag)
        of the path's next segment, by BSDF sampling or uniformly."""
        bsdfs = scene.bsdfs
        u1 = rng.next_float32()
        u2 = rng.next_2d()
        if not self.sample_bsdf:
            kind = dr.gather(mi.UInt32, uniform_kind, bsdf_id, active)
            wi, pdf = self._uniform_direction(si, wo, kind, u2)
            weight = bsdfs.eval_pdf(bsdf_id, ctx, si.to_local(wi), active)[0] / pdf
            return wi, weight, dr.select(active, False, specular), terminated
        bs = bsdfs.sample(bsdf_id, ctx, u1, u2, active)
        weight = dr.select(bs.pdf > 0, bs.weight, 0.0)
        if bsdfs.dispersive:
            # Wavelength-dependent refraction: the first wavelength stands for all.
            term = active & bs.terminate & ~terminated
            weight = dr.select(term, first_only(weight), weight)
            terminated = terminated | term
        return si.to_world(bs.wo), weight, dr.select(active, bs.delta, specular), terminated

    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active, uniform_kind):
        geo, lights, bsdfs = scene.geometry, scene.lights, scene.bsdfs
        ray, active, L, beta, depth, valid = path_state(ray, active)
        specular = mi.Bool(True)
        # Loop state: only what a bounce changes (see path); the ifs on Python values
        # are plain ifs, so that the excluded variables they read stay outside.
        terminated = mi.Bool(False) if bsdfs.dispersive and self.sample_bsdf else None
        ray_var, ray_fixed = ray_state(ray)
        rng_state = rng.loop_state()
        while dr.hint(active, label="simplepath", exclude=[ray, ray_fixed, rng, wl, uniform_kind]):
            ray = loop_ray(ray_var, ray_fixed)
            rng.set_loop_state(rng_state)
            si, shape = geo.intersect(ray, active, coherent=depth == 0)   # camera rays: coherent
            hit = active & si.is_valid()
            valid |= hit
            # Emission is counted where light sampling could not have found it.
            count = specular if self.sample_lights else mi.Bool(True)
            L, skip = add_unweighted_emission(L, scene, si, shape, ray, wl, active, hit, depth, beta,
                                              self.hide_emitters, count)

            go = hit & ~skip & (depth + 1 < self.max_depth)
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, go)
            null = bsdfs.is_null(bsdf_id, go)
            scatter = go & ~null
            ctx = ShadingContext(si, wl)

            if dr.hint(self.sample_lights, mode="scalar"):
                u_light = rng.next_float32()
                u_pos = rng.next_2d()
                lit = scatter & bsdfs.smooth(bsdf_id, scatter)
                ls = lights.sample_Li(self.light_sampler, si, u_light, u_pos, wl, lit)
                em = lit & (ls.pdf > 0)
                f_em = bsdfs.eval_pdf(bsdf_id, ctx, si.to_local(ls.wi), em)[0]
                Ld = beta * f_em * ls.L / ls.pdf
                L += dr.select(light_reaches(geo, si, ls.p, Ld, em), Ld, 0.0)

            wi, weight, specular, terminated = self._next_direction(
                scene, rng, si, ctx, bsdf_id, -ray.d, uniform_kind, specular, terminated, scatter)
            beta[scatter] = beta * weight
            specular |= null | skip
            through = skip | null
            ray = dr.select(through, si.spawn_ray(ray.d), si.spawn_ray(wi))
            ray_var = ray_state(ray)[0]
            depth[hit & ~skip] = depth + 1
            active = through | (scatter & nonzero(beta))
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)
        return L, valid
