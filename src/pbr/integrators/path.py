"""``path``: unidirectional path tracing with next-event estimation and MIS.

At each vertex: emission found by BSDF sampling is weighted by the power heuristic
against light sampling; one light is sampled (via the scene's light sampler) and
weighted against BSDF sampling; the path continues by BSDF sampling, with Russian
roulette from ``rr_depth`` on. ``max_depth`` has Mitsuba's meaning (-1: unlimited,
1: only emitters seen directly, 2: direct lighting); so has ``hide_emitters``: camera
rays pass through area lights (showing what lies behind them).

The same routine is the PRB adjoint: in ``FORWARD``/``BACKWARD`` mode it replays a
path whose primal radiance is ``L_in`` and, at each vertex, differentiates the emitted,
directly lit and (through the BSDF ratio f/f_detached) reflected radiance.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .. import dispatch
from ..bsdfs.base import shading_context
from ..lights.lightsamplers import LIGHT_SAMPLERS
from ..sampling import power_heuristic
from ..spectrum import first_only
from .base import (INTEGRATORS, BACKWARD, PRIMAL, SamplingIntegrator, depth_limit, emitted_mis, forward_derivative,
                   light_reaches, loop_ray, nonzero, nonzero_estimate, mis_state, path_state, ray_state)


def face_the_ray(si, ray, mask):
    """``si`` with its shading normal turned toward the ray's origin where it faces away
    although the surface is seen (``mask``): near a silhouette, interpolated normals of
    a mesh can face away from the viewer on faces that are seen edge-on, which makes a
    thin dark rim inside the silhouette. Radiance beside a silhouette is estimated past
    that rim (the rim moves with the silhouette, so its two boundaries add up to one
    jump, from the radiance inside the rim to the background's; Mitsuba's projective
    integrators make the same correction)."""
    alpha = dr.dot(si.sh_frame.n, ray.d)
    eps = 1e-5
    wrong = mask & (alpha > -eps)
    n = dr.normalize(si.sh_frame.n - (alpha + eps) * ray.d)
    si.sh_frame = dr.select(wrong, mi.Frame3f(n), si.sh_frame)
    si.wi = dr.select(wrong, si.sh_frame.to_local(-ray.d), si.wi)
    return si


@INTEGRATORS.register("path")
class PathIntegrator(SamplingIntegrator):
    """``path``: unidirectional path tracing with next-event estimation and MIS
    (pbrt-v4's ``PathIntegrator``, Mitsuba's ``path``); its adjoint passes are PRB.

    =============  ======  =======  =============================================================
    name           type    default  meaning
    =============  ======  =======  =============================================================
    max_depth      int     -1       longest path in segments (Mitsuba's: -1 unlimited, 1 emitters
                                    seen directly, 2 direct light)
    rr_depth       int     5        depth from which Russian roulette may end a path
    hide_emitters  bool    false    camera rays pass through emitting surfaces and do not see
                                    the environment (not through null surfaces either, as
                                    Mitsuba's path)
    light_sampler  string  bvh      light choice of next-event estimation: 'uniform', 'power'
                                    or 'bvh' (pbrt-v4's light BVH)
    regularize     bool    false    pbrt-v4's BSDF regularisation: after the path's first
                                    non-specular bounce, microfacet alpha below 0.3 becomes
                                    clamp(2 alpha, 0.1, 0.3) and smooth conductors and
                                    dielectrics rough (alpha 0.1): caustics converge faster,
                                    biased
    =============  ======  =======  =============================================================
    """

    name = "path"
    default_max_depth = -1
    differentiable = True
    # Interior derivatives w.r.t. the geometry (hits move with the shapes); boundary terms
    # (visibility) are the projective integrators'.
    geometry_gradients = True
    # How a light sample moves when the shading point does: False, it stays on the light
    # (area measure, as Mitsuba's prb); True, its direction stays (solid angle: what the
    # projective integrators' boundary terms are consistent with).
    solid_angle_nee = False
    # Turn the first hit's shading normal toward the ray where it faces away (set by the
    # projective integrators while they estimate radiance beside a silhouette).
    face_first_hit = False
    next_event = True   # light sampling at each vertex, MIS-weighted against BSDF sampling
    # hide_emitters also hides the environment behind null lobes (null, mask cut-outs,
    # thindielectric's transmission): Mitsuba's path counts a ray valid only once it has
    # met a surface whose sampled lobe is not null; its prb and prb_basic hide the
    # environment at depth 0 only.
    hide_through_null = True
    regularize = False

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", self.default_max_depth, min=-1)
        self.rr_depth = props.int("rr_depth", 5, min=0)
        self.hide_emitters = props.bool("hide_emitters", False)
        self.light_sampler_type = props.string("light_sampler", "bvh", choices=LIGHT_SAMPLERS)
        self.regularize = props.bool("regularize", False)
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if self.max_depth == 0:
            return mi.Spectrum(0.0), mi.Bool(False)
        return self._sample(scene, rng, ray, wl, mode, dL, L_in, active)

    @dr.syntax
    def _sample(self, scene, rng, ray, wl, mode, dL, L_in, active, depth0=None):
        """``depth0``: the number of path vertices before ``ray``'s origin (per lane; 0, the
        camera, when None): the rest of a longer path, which ``max_depth`` and Russian
        roulette count from there (the projective integrators' radiance beside an edge)."""
        primal = mode == PRIMAL
        geo, lights, bsdfs = scene.geometry, scene.lights, scene.bsdfs
        max_depth = depth_limit(self.max_depth)

        ray, active, L, beta, depth, valid = path_state(ray, active, None if primal else L_in)
        from_camera = depth0 is None
        if depth0 is not None:
            depth = mi.UInt32(depth0)
        else:
            depth0 = 0
        prev_p, prev_n, prev_pdf, prev_delta = mis_state(ray)
        # The loop state holds only what a bounce changes: Dr.Jit traces the body a second
        # time to drop state variables that come back unchanged (a render's largest fixed
        # cost). So the ray's time and wavelengths, the sample stream's constants, the
        # wavelengths and a replay's adjoint radiance dL stay outside it, and the forward
        # derivative, the relative IOR and the dispersion flag are state only where they
        # can change.
        dL_fwd = None if primal or mode == BACKWARD else mi.Spectrum(0.0)
        eta = mi.Float(1.0) if bsdfs.refracts else None
        dispersive = bsdfs.dispersive
        terminated = mi.Bool(False) if dispersive else None
        seen = mi.Bool(False)     # a surface whose sampled lobe is not null (hide_emitters)
        # pbrt-v4's regularisation: on after the first non-specular bounce (state only with it)
        nonspecular = mi.Bool(False) if self.regularize else None
        ray_var, ray_fixed = ray_state(ray)
        rng_state = rng.loop_state()

        # The camera rays attached to a differentiated camera pose (replays only).
        ray_ad = None if primal else self.primary_ray_ad

        # The body's ifs on Python values are plain ifs (mode="scalar"): a transformed if
        # would make the variables it reads (dL) variables of the body, unbound before it.
        while dr.hint(active, label="path", exclude=[ray, ray_fixed, rng, wl, dL]):
            ray = loop_ray(ray_var, ray_fixed)
            rng.set_loop_state(rng_state)
            # Replays differentiate the hit w.r.t. the geometry (it moves along the ray).
            r_ad = None
            if dr.hint(ray_ad is not None, mode="scalar"):
                with dr.resume_grad():
                    r_ad = dr.select(depth == 0, ray_ad, ray)
            # Camera rays (depth 0 of a path from the camera) are traced as coherent.
            si, shape = geo.intersect(ray, active, attached=not primal, ray_ad=r_ad,
                                      coherent=(depth == 0) if from_camera else False)
            hit = active & si.is_valid()
            if dr.hint(self.face_first_hit, mode="scalar"):
                si = face_the_ray(si, ray, hit & (depth == depth0))
            valid |= hit

            # Emission found by BSDF sampling (or seen directly), MIS-weighted.
            light = lights.light_of_hit(scene, shape, si, hit)
            on_light = hit & (light > 0)
            # hide_emitters (Mitsuba's meaning): camera rays pass through area lights.
            skip = on_light & (depth == 0) if self.hide_emitters else mi.Bool(False)
            on_light &= ~skip
            # Rays leaving the scene see the infinite lights (MIS against NEE).
            escaped = active & ~si.is_valid()
            if dr.hint(self.hide_emitters, mode="scalar"):
                escaped &= seen if self.hide_through_null else depth > 0
            with dr.resume_grad(when=not primal):
                # Without next-event estimation only BSDF sampling finds emitters: weight 1
                # (what emitted_mis gives after a delta vertex).
                Le = beta * emitted_mis(scene, self.light_sampler, light, si, ray.d, wl, on_light, escaped, prev_p,
                                        prev_n, prev_pdf, prev_delta if self.next_event else mi.Bool(True))

            active_next = hit & ~skip & (depth + 1 < max_depth)
            ctx = shading_context(si, wl, nonspecular)
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, active_next)

            # Next-event estimation: one light sample, MIS-weighted against the BSDF.
            u_light = rng.next_float32()
            u_pos = rng.next_2d()
            smooth = active_next & bsdfs.smooth(bsdf_id, active_next, nonspecular) & self.next_event
            with dr.resume_grad(when=not primal):
                # Attached: the sampled radiance ls.L depends on emitter parameters.
                # In a conditional: packets with no smooth lane (all on delta lobes) skip it.
                ls = dispatch.when_any(smooth, lambda: lights.sample_Li(self.light_sampler, si, u_light, u_pos, wl,
                                                                        smooth), label="light sample")
            # The attached density keeps the derivative of the solid-angle measure of an
            # area light's sample (dist^2 / cos) when the shading point moves; the light's
            # tables are detached, so it carries no other derivative.
            pdf_Li = dr.detach(ls.pdf) if self.solid_angle_nee else ls.pdf
            ls.pdf = dr.detach(ls.pdf)
            em = smooth & (ls.pdf > 0)
            # The BSDF is evaluated toward the light and sampled (to continue the path)
            # in one call, so texture lookups are shared; the shadow ray comes after it.
            u1 = rng.next_float32()
            u2 = rng.next_2d()
            with dr.resume_grad(when=not primal):
                # attached: the hit and its frame may move (with solid_angle_nee the
                # direction toward a light that is not a delta is kept fixed)
                wo_em = si.to_local(dr.select(ls.delta, ls.wi, dr.detach(ls.wi)) if self.solid_angle_nee else ls.wi)
                f_em, pdf_em, bs = bsdfs.eval_pdf_sample(bsdf_id, ctx, wo_em, u1, u2, active_next)
                # The MIS weight is detached (as Mitsuba's): the BSDF-sampled half of
                # the same integral carries a detached weight, so an attached one here
                # would add d(w_em) without its counterpart -d(w_em) (biased gradients
                # for any parameter the BSDF pdf depends on: eta, alpha).
                w_em = dr.select(ls.delta, 1.0, power_heuristic(ls.pdf, dr.detach(pdf_em)))
                Ld = beta * f_em * ls.L * (w_em / pdf_Li)      # unoccluded
                # A delta lobe cannot be evaluated toward a direction; its attached value
                # is the sample's weight times the lobe's choice probability (e.g. the
                # Fresnel reflectance of a smooth dielectric). A stochastic BSDF's eval
                # is another random estimate than the sample's weight: there too the
                # sample's own weight is differentiated (its pdf is detached).
                f_sampled = bs.weight * bs.pdf
            if dr.hint(primal, mode="scalar"):
                # The shadow ray is traced at the end of the body (below): there fewer
                # values are live across the trace, which must preserve each of them
                # (door's LLVM IR: 48 + 16 float vectors instead of 54 + 18; docs/performance.md).
                em = nonzero_estimate(Ld, em)
                shadow_ray = si.spawn_ray_to(ls.p)
            else:
                em = light_reaches(geo, si, ls.p, Ld, em, skip_zero=False)
                with dr.resume_grad():
                    Ld = dr.select(em, Ld, 0.0)
            replay_sample = bs.delta | bsdfs.stochastic(bsdf_id, active_next)
            bs = dr.detach(bs)
            seen |= hit & ~skip & ~bs.null
            cont = active_next & (bs.pdf > 0)

            if dr.hint(primal, mode="scalar"):
                L = L + Le
                if dr.hint(dispersive, mode="scalar"):
                    # Wavelength-dependent refraction: only the first wavelength goes on,
                    # standing for all four (pbrt-v4's TerminateSecondary, applied to the
                    # radiance and throughput instead of the wavelength densities).
                    term = hit & bs.terminate & ~terminated
                    beta[term] = first_only(beta)
                    terminated |= term
            else:
                L = L - Le - Ld
                with dr.resume_grad():
                    f_bs, _ = bsdfs.eval_pdf(bsdf_id, ctx, bs.wo, cont & ~replay_sample)
                    f_bs = dr.select(replay_sample, f_sampled, f_bs)
                    f_det = bs.weight * bs.pdf
                    ratio = dr.select(f_det != 0, f_bs * dr.rcp(dr.detach(f_det)), 0.0)
                    Lr = L * dr.replace_grad(mi.Spectrum(1.0), ratio)
                    Lo = Le + Ld + dr.select(cont, Lr, 0.0)
                    if dr.hint(mode == BACKWARD, mode="scalar"):
                        # AllowNoGrad: a parameter may not reach this vertex at all.
                        dr.backward_from(dL * Lo, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
                    else:
                        dL_fwd += forward_derivative(Lo)

            beta[~skip] = beta * bs.weight
            if dr.hint(eta is not None, mode="scalar"):
                eta[~skip] = eta * bs.eta
            prev_p = mi.Point3f(dr.detach(si.p))
            prev_n = mi.Normal3f(dr.detach(si.n))
            prev_pdf = mi.Float(bs.pdf)
            prev_delta = skip | bs.delta
            if dr.hint(nonspecular is not None, mode="scalar"):
                nonspecular |= cont & ~bs.delta
            ray = dr.select(skip, si.spawn_ray(ray.d), si.spawn_ray(si.to_world(bs.wo)))
            ray_var = ray_state(ray)[0]
            if dr.hint(primal, mode="scalar"):
                # A new scope: Dr.Jit schedules a kernel's operations by scope, then
                # depth-first from the loop state; without it the trace is emitted where
                # the depth-first walk first needs it (right after the light sample).
                dr.detail.new_scope(dr.backend_v(L))
                em &= ~geo.occluded(shadow_ray, em)
                L = L + dr.select(em, Ld, 0.0)
                if dr.hint(dispersive, mode="scalar"):
                    L[term] = first_only(L)
            depth[hit & ~skip] = depth + 1

            # Russian roulette (the survival probability is detached, as in Mitsuba).
            b_max = dr.max(beta)
            q = dr.minimum(b_max * eta * eta if eta is not None else b_max, 0.95)
            rr = (depth >= self.rr_depth) & ~skip
            survive = rng.next_float32() < q
            beta[rr] = beta * dr.rcp(dr.detach(q))
            active = skip | (cont & (~rr | survive) & nonzero(beta))
            rng_state = rng.loop_state()

        rng.set_loop_state(rng_state)
        return (L if primal else mi.Spectrum(0.0) if dL_fwd is None else dL_fwd), valid


@INTEGRATORS.register("prb_basic")
class PRBBasicIntegrator(PathIntegrator):
    """``prb_basic`` (Mitsuba's): Path Replay Backpropagation of the most basic path
    tracer, BSDF sampling only: no next-event estimation, no MIS, no Russian roulette.
    The same loop as ``path`` with those parts off, so its derivatives are ``prb``'s. Not
    an alias of ``simplepath`` with ``samplelights=false``: that one counts pbrt-v4's
    depth (one bounce fewer for the same number) and has no derivatives.

    =============  ====  =======  ============================================================
    name           type  default  meaning
    =============  ====  =======  ============================================================
    max_depth      int   6        longest path in segments (Mitsuba's: -1 unlimited, 1 emitters
                                  seen directly, 2 direct light)
    rr_depth       int   5        accepted and ignored, as Mitsuba's prb_basic does
    hide_emitters  bool  false    camera rays pass through emitting surfaces and do not see
                                  the environment
    =============  ====  =======  ============================================================
    """

    name = "prb_basic"
    default_max_depth = 6
    next_event = False
    hide_through_null = False
    light_sampler_type = "uniform"   # no light is sampled

    def __init__(self, props):
        SamplingIntegrator.__init__(self, props)
        self.max_depth = props.int("max_depth", self.default_max_depth, min=-1)
        props.int("rr_depth", 5, min=1)
        self.rr_depth = 0xFFFFFFFF
        self.hide_emitters = props.bool("hide_emitters", False)
        props.finish()


@INTEGRATORS.register("prb")
class PRBIntegrator(PathIntegrator):
    """``prb`` (Mitsuba's name): ``path``'s estimator and parameters, with Mitsuba's
    default ``max_depth`` of 6; the adjoint passes are Path Replay Backpropagation.
    """

    name = "prb"
    default_max_depth = 6
    hide_through_null = False
