"""``direct``: direct illumination only (Mitsuba's ``direct``).

At the surface a camera ray sees, ``emitter_samples`` light samples and
``bsdf_samples`` BSDF samples estimate the light arriving straight from the emitters,
combined by multi-sample MIS (Veach's power heuristic on the densities scaled by the
sample counts, as Mitsuba). With one of the counts 0 the other technique gets weight 1.
Light sampling is skipped at surfaces without a smooth (non-delta) lobe; BSDF samples
are taken everywhere, so mirrors and glass show the emitters they reflect.

One difference from Mitsuba 3.9: Mitsuba adds a *delta* light's sample (point, spot,
directional lights) with weight 1 for each of the ``emitter_samples``, so such lights
come out ``emitter_samples`` times too bright; here every light sample has weight
1 / ``emitter_samples``.

``hide_emitters`` has Mitsuba's meaning: camera rays pass through emitting surfaces
and do not see the environment.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from ..lights.lightsamplers import LIGHT_SAMPLERS
from ..sampling import power_heuristic
from ..spectrum import first_only
from .base import INTEGRATORS, SamplingIntegrator, light_reaches


@dr.syntax
def intersect_camera_ray(scene, ray, active, hide_emitters: bool):
    """(si, shape) of the first surface a camera ray sees; with ``hide_emitters`` the ray
    passes through emitting surfaces (Mitsuba's ``hide_emitters``)."""
    geo, lights = scene.geometry, scene.lights
    si, shape = geo.intersect(ray, active, coherent=True)
    if hide_emitters:
        skip = active & si.is_valid() & (lights.light_of_hit(scene, shape, si, active) > 0)
        while dr.hint(skip, label="skip_emitters"):
            si_next, shape_next = geo.intersect(si.spawn_ray(ray.d), skip)
            si = dr.select(skip, si_next, si)
            shape = dr.select(skip, shape_next, shape)
            skip &= si.is_valid() & (lights.light_of_hit(scene, shape, si, skip) > 0)
    return si, shape


def hit_emission(scene, si, shape, wl, active):
    """(radiance an emitting surface sends toward ``si.wi``, its light index + 1; 0 where
    the surface does not emit)."""
    lights = scene.lights
    hit = active & si.is_valid()
    light = lights.light_of_hit(scene, shape, si, hit)
    return lights.L(light - 1, si, wl, hit & (light > 0)), dr.select(hit, light, 0)


def add_unweighted_emission(L, scene, si, shape, ray, wl, active, hit, depth, beta, hide_emitters, count=None):
    """``L`` plus the radiance a ray finds without MIS: ``beta`` times that of the emitter
    hit and, for rays that left the scene, of the infinite lights, on ``count`` lanes (all
    by default). What pbrt-v4's RandomWalk and SimplePath count at every vertex, and
    ``direct`` / ``whitted`` for camera rays (``beta`` 1). With ``hide_emitters`` camera
    rays pass through emitters and do not see the environment. Returns (L, the lanes
    passing through an emitter)."""
    lights = scene.lights
    count = mi.Bool(True) if count is None else count
    Le, light = hit_emission(scene, si, shape, wl, hit)
    skip = hit & (light > 0) & (depth == 0) if hide_emitters else mi.Bool(False)
    L += dr.select(count & ~skip, beta * Le, 0.0)
    if lights.has_infinite:
        escaped = active & ~hit & count
        if hide_emitters:
            escaped &= depth > 0
        for Le_inf, _ in lights.Le_escaped(ray.d, wl, ray.o, mi.Normal3f(0.0), escaped):
            L += dr.select(escaped, beta * Le_inf, 0.0)
    return L, skip


@INTEGRATORS.register("direct")
class DirectIntegrator(SamplingIntegrator):
    """``direct`` (Mitsuba's): direct illumination only, light and BSDF samples combined by
    multi-sample MIS. Surfaces only.

    ===============  ======  =======  ==========================================================
    name             type    default  meaning
    ===============  ======  =======  ==========================================================
    shading_samples  int     1        sets both sample counts below
    emitter_samples  int     1        light samples per camera sample (default: shading_samples)
    bsdf_samples     int     1        BSDF samples per camera sample (default: shading_samples)
    hide_emitters    bool    false    camera rays pass through emitting surfaces and do not see
                                      the environment
    light_sampler    string  bvh      light choice of next-event estimation: 'uniform', 'power'
                                      or 'bvh' (pbrt-v4's light BVH)
    ===============  ======  =======  ==========================================================
    """

    name = "direct"
    surfaces_only = True

    def __init__(self, props):
        super().__init__(props)
        if props.has("shading_samples") and (props.has("emitter_samples") or props.has("bsdf_samples")):
            raise props.error("shading_samples", "cannot be combined with 'emitter_samples' or 'bsdf_samples'")
        n = props.int("shading_samples", 1, min=0)
        self.emitter_samples = props.int("emitter_samples", n, min=0)
        self.bsdf_samples = props.int("bsdf_samples", n, min=0)
        if self.emitter_samples + self.bsdf_samples == 0:
            raise props.error("emitter_samples" if props.has("emitter_samples") else "shading_samples",
                              "at least one emitter or BSDF sample is needed")
        self.hide_emitters = props.bool("hide_emitters", False)
        self.light_sampler_type = props.string("light_sampler", "bvh", choices=LIGHT_SAMPLERS)
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        return self._sample(scene, rng, ray, wl, active)

    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active):
        geo, lights, bsdfs = scene.geometry, scene.lights, scene.bsdfs
        n_em, n_bs = self.emitter_samples, self.bsdf_samples
        frac_em, frac_bs = n_em / (n_em + n_bs), n_bs / (n_em + n_bs)
        inv_em, inv_bs = 1.0 / max(n_em, 1), 1.0 / max(n_bs, 1)   # (loops of 0 samples are still traced)
        infinite = lights.has_infinite
        ray = mi.Ray3f(ray)

        si, shape = intersect_camera_ray(scene, ray, active, self.hide_emitters)
        hit = active & si.is_valid()
        L = mi.Spectrum(0.0)
        if not self.hide_emitters:
            L, _ = add_unweighted_emission(L, scene, si, shape, ray, wl, active, hit, 0, 1.0, False)

        ctx = ShadingContext(si, wl)
        bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)

        # Light sampling (only where the BSDF has a smooth lobe).
        smooth = hit & bsdfs.smooth(bsdf_id, hit)
        # Loop state: only what an iteration changes (the rest would make Dr.Jit trace
        # each body twice, see path's loop); the stream carries its varying arrays.
        i = mi.UInt32(0)
        rng_state = rng.loop_state()
        while dr.hint(smooth & (i < n_em), label="direct_emitter", exclude=[rng, wl, si, ctx, bsdf_id, smooth]):
            rng.set_loop_state(rng_state)
            u_light = rng.next_float32()
            u_pos = rng.next_2d()
            ls = lights.sample_Li(self.light_sampler, si, u_light, u_pos, wl, smooth)
            em = smooth & (ls.pdf > 0)
            f, pdf_b = bsdfs.eval_pdf(bsdf_id, ctx, si.to_local(ls.wi), em)
            w = dr.select(ls.delta, 1.0, power_heuristic(ls.pdf * frac_em, pdf_b * frac_bs)) * inv_em
            Ld = f * ls.L * (w / ls.pdf)
            L += dr.select(light_reaches(geo, si, ls.p, Ld, em), Ld, 0.0)
            i += 1
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)

        # BSDF sampling: count what the sampled ray finds on an emitter.
        j = mi.UInt32(0)
        rng_state = rng.loop_state()
        while dr.hint(hit & (j < n_bs), label="direct_bsdf", exclude=[rng, wl, si, ctx, bsdf_id, hit]):
            rng.set_loop_state(rng_state)
            u1 = rng.next_float32()
            u2 = rng.next_2d()
            bs = bsdfs.sample(bsdf_id, ctx, u1, u2, hit)
            go = hit & (bs.pdf > 0) & dr.any(bs.weight != 0)
            ray_b = si.spawn_ray(si.to_world(bs.wo))
            si_b, shape_b = geo.intersect(ray_b, go)
            Le, light = hit_emission(scene, si_b, shape_b, wl, go)
            on = go & (light > 0)
            pdf_e = lights.pdf_Li(self.light_sampler, light - 1, si.p, si.n, si_b, on & ~bs.delta)
            w = power_heuristic(bs.pdf * frac_bs, dr.select(bs.delta, 0.0, pdf_e) * frac_em)
            Lb = dr.select(on, Le * w, 0.0)
            # Plain ifs (mode="scalar"): a transformed one would make the excluded
            # variables it reads variables of the body, unbound there.
            if dr.hint(infinite, mode="scalar"):
                esc = go & ~si_b.is_valid()
                for Le_inf, pdf_inf in lights.Le_escaped(ray_b.d, wl, si.p, si.n, esc, self.light_sampler):
                    w_inf = power_heuristic(bs.pdf * frac_bs, dr.select(bs.delta, 0.0, pdf_inf) * frac_em)
                    Lb += dr.select(esc, Le_inf * w_inf, 0.0)
            Lb = bs.weight * Lb * inv_bs
            if dr.hint(bsdfs.dispersive, mode="scalar"):
                Lb = dr.select(bs.terminate, first_only(Lb), Lb)
            L += dr.select(go, Lb, 0.0)
            j += 1
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)

        return L, hit
