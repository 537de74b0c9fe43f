"""``prbvolpath``: differentiable volumetric path tracing (Mitsuba's ``prbvolpath``
estimator, Path Replay Backpropagation through participating media, Vicini et al. 2021)
on the shared volumetric walk (:mod:`.volume`). The estimator and how its derivatives
are propagated: docs/integrators.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from ..lights.lightsamplers import LIGHT_SAMPLERS
from ..plugins.props import SceneError
from ..sampling import power_heuristic
from ..spectrum import first_only
from . import volume
from .base import (INTEGRATORS, BACKWARD, FORWARD, PRIMAL, ConditionalState, depth_limit, emitted_mis,
                   forward_derivative, mis_state, nonzero, nonzero_estimate, path_state)
from .volpath import _MediumAware


def _ratio(w):
    """w / detach(w) (0 where w is 0): the factor whose gradient is dw / w."""
    wd = dr.detach(w)
    return dr.select(wd != 0, w * dr.rcp(wd), 0.0)


@INTEGRATORS.register("prbvolpath")
class PRBVolPathIntegrator(_MediumAware):
    """``prbvolpath``: differentiable volumetric path tracing (Mitsuba's ``prbvolpath``
    estimator, Path Replay Backpropagation through media; hero wavelength only). No
    emissive media.

    ===================  ======  =======  =========================================================
    name                 type    default  meaning
    ===================  ======  =======  =========================================================
    max_depth            int     6        longest path in real scattering events (-1 unlimited)
    rr_depth             int     5        depth from which Russian roulette may end a path
    hide_emitters        bool    false    camera rays pass through emitting surfaces and do not see
                                          the environment
    light_sampler        string  bvh      light choice of next-event estimation: 'uniform', 'power'
                                          or 'bvh' (pbrt-v4's light BVH)
    majorant_factor      float   1.1      grid majorants are multiplied by it (>= 1), so that null
                                          collisions carry the transmittance's derivative
    max_null_collisions  int     65536    null collisions a path segment or shadow ray may have
    ===================  ======  =======  =========================================================
    """

    name = "prbvolpath"
    differentiable = True
    geometry_gradients = True   # interior derivatives w.r.t. the geometry (see path)

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", 6, min=-1)
        self.rr_depth = props.int("rr_depth", 5, min=0)
        self.hide_emitters = props.bool("hide_emitters", False)
        self.light_sampler_type = props.string("light_sampler", "bvh", choices=LIGHT_SAMPLERS)
        self.majorant_factor = props.float("majorant_factor", 1.1, min=1.0)
        self.max_null = props.int("max_null_collisions", 1 << 16, min=1)
        props.finish()

    def check(self, scene) -> None:
        super().check(scene)
        if getattr(scene.media, "has_le", False):
            raise SceneError(f"{self.path}: prbvolpath does not support emissive media (Le); use volpath")

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if self.max_depth == 0:
            return mi.Spectrum(0.0), mi.Bool(False)
        return self._sample(scene, rng, ray, wl, mode, dL, L_in, active)

    # -- helpers ----------------------------------------------------------------------
    @staticmethod
    def _grid_lanes(media, m, active):
        if not media.has_grid:
            return mi.Bool(False)
        return active & dr.gather(mi.Bool, media.is_grid, m, active)

    @staticmethod
    def _propagate(mode, dL, mask, a, b, dL_fwd):
        """Send ``dL * Lo`` backward, or add the forward derivative of ``Lo``, where
        ``Lo = a * b`` on ``mask`` (recorded here: outside, AD is suspended)."""
        with dr.resume_grad():
            Lo = dr.select(mask, a * b, 0.0)
            return PRBVolPathIntegrator._send(mode, dL, Lo, dL_fwd)

    @staticmethod
    def _send(mode, dL, Lo, dL_fwd):
        if mode == BACKWARD:
            # Some factors need not depend on the differentiated parameters (e.g. the
            # transmittance when only an albedo is differentiated).
            dr.backward_from(dL * Lo, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
            return dL_fwd
        return dL_fwd + forward_derivative(Lo)

    # -- collisions: the path's free flight and a shadow ray's ratio tracking -------------
    def _real_or_null(self, state, c, rng, media, homog, mode, dL, L):
        """A tentative collision of the path: real (scatter, weight sigma_s / (sigma_maj
        P)) with probability P = mean(sigma_t / sigma_maj), null otherwise; the weight of
        the step is recomputed attached and its derivative propagated (adjoint modes)."""
        beta, p_sc, scattered, n_null, dL_fwd = state
        primal = mode == PRIMAL
        coll, T_maj, sigma_maj = c.coll, c.T_maj, c.sigma_maj
        with dr.resume_grad(when=not primal):
            mp = media.eval(c.m, c.p, c.wl, c.going)
            st = mp.sigma_a + mp.sigma_s
            st_d = dr.detach(st)
            P = dr.clip(dr.mean(st_d * dr.select(sigma_maj > 0, dr.rcp(sigma_maj), 0.0)), 0.0, 1.0)
            u_ev = rng.next_float32()
            real = coll & (u_ev < P)
            null = coll & ~real
            # Homogeneous: the majorant is sigma_t itself, attached.
            maj = dr.select(homog, st, sigma_maj)
            T_att = dr.select(homog, dr.exp(-st * (c.t - c.t_prev)), T_maj)
            pdf = T_maj[0] * dr.select(coll, sigma_maj[0], 1.0)
            ev = dr.select(real, mp.sigma_s * dr.rcp(P), dr.select(null, (maj - st) * dr.rcp(1.0 - P), 1.0))
            w = T_att * ev * dr.select(pdf > 0, dr.rcp(pdf), 0.0)
            f = _ratio(w)
        if not primal:
            dL_fwd = self._propagate(mode, dL, c.going, L, f, dL_fwd)
        beta[c.going] = beta * dr.detach(w)
        p_sc[real] = c.p
        scattered |= real
        n_null = dr.select(null, n_null + 1, n_null)
        capped = null & (n_null >= self.max_null)
        beta[capped] = mi.Spectrum(0.0)
        return (beta, p_sc, scattered, n_null, dL_fwd), real | capped | ~nonzero(beta)

    def _ratio_tracking(self, state, c, rng, media, mode, dL, adj):
        """A tentative collision of a shadow ray in a grid medium: the transmittance is
        weighted by the null fraction, recomputed attached (adjoint modes: its derivative
        times ``adj`` is propagated)."""
        T, n_null, dL_fwd, T_acc = state
        primal = mode == PRIMAL
        coll, sigma_maj = c.coll, c.sigma_maj
        T_acc *= c.T_maj
        with dr.resume_grad(when=not primal):
            mp = media.eval(c.m, c.p, c.wl, coll)
            pdf = T_acc[0] * sigma_maj[0]
            w = T_acc * (sigma_maj - mp.sigma_a - mp.sigma_s) * dr.select(pdf > 0, dr.rcp(pdf), 0.0)
            f = _ratio(w)
        if not primal:
            dL_fwd = self._propagate(mode, dL, coll, adj, f, dL_fwd)
        T[coll] = T * dr.detach(w)
        T_acc[coll] = mi.Spectrum(1.0)
        n_null = dr.select(coll, n_null + 1, n_null)
        T[coll & (n_null >= self.max_null)] = mi.Spectrum(0.0)
        return (T, n_null, dL_fwd, T_acc), ~(dr.max(T) > 0)

    def _shadow_segment(self, state, ray, medium, t_end, in_m, media, wl, rng, mode, dL, adj):
        """Transmittance through one medium segment of a shadow ray (see
        :func:`.volume.transmittance`): exact in homogeneous media, ratio tracking in
        grids. In the adjoint modes, the derivative of ``adj * T`` (adj: the detached
        contribution this T multiplies) is propagated factor by factor (``dL``: the
        adjoint radiance). State: (T, null collisions, forward derivative)."""
        T, n_null, dL_fwd = state
        primal = mode == PRIMAL
        m = medium - 1
        grid = self._grid_lanes(media, m, in_m)
        homog = in_m & ~grid
        with dr.resume_grad(when=not primal):
            st = media.eval(m, ray.o, wl, homog)
            w = dr.exp(-(st.sigma_a + st.sigma_s) * t_end)
            f = _ratio(w)
        if not primal:
            dL_fwd = self._propagate(mode, dL, homog, adj, f, dL_fwd)
        T[homog] = T * dr.detach(w)
        T, n_null, dL_fwd, T_acc = volume.free_flight(
            media, rng, ray, medium, t_end, wl, grid, (T, n_null, dL_fwd, mi.Spectrum(1.0)), self._ratio_tracking,
            (media, mode, dL, adj), factor=self.majorant_factor)
        T[grid] = T * volume.hero_ratio(T_acc)
        return T, n_null, dL_fwd

    def _null_crossing(self, state, w, lanes, mode, dL, adj):
        """A shadow ray crosses a null lobe (a thin dielectric) with weight ``w``
        (attached in the adjoint modes: its derivative times ``adj`` is propagated)."""
        T, n_null, dL_fwd = state
        if mode != PRIMAL:
            with dr.resume_grad():
                f = _ratio(w)
            dL_fwd = self._propagate(mode, dL, lanes, adj, f, dL_fwd)
        T[lanes] = T * dr.detach(w)
        return T, n_null, dL_fwd

    def _transmittance(self, scene, rng, sray, p_light, medium, wl, mode, dL, adj, dL_fwd, active):
        """(transmittance from ``sray.o`` to ``p_light``, forward derivative)."""
        state = (mi.Spectrum(1.0), mi.UInt32(0), dL_fwd)
        T, _, dL_fwd = volume.transmittance(scene, sray, p_light, medium, active, state, self._shadow_segment,
                                            (scene.media, wl, rng, mode, dL, adj), wl=wl,
                                            crossing=self._null_crossing, crossing_args=(mode, dL, adj))
        return T, dL_fwd

    # -- the estimator --------------------------------------------------------------------
    @dr.syntax
    def _sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        geo, lights, bsdfs, media = scene.geometry, scene.lights, scene.bsdfs, scene.media
        primal = mode == PRIMAL
        has_media = len(media) > 0
        max_depth = depth_limit(self.max_depth)

        ray, active, L, beta, depth, valid = path_state(ray, active, None if primal else L_in)
        prev_p, prev_n, prev_pdf, prev_delta = mis_state(ray)
        dL = mi.Spectrum(0.0) if dL is None else mi.Spectrum(dL)
        eta = mi.Float(1.0)
        # Loop state holds only what a bounce changes (see path's loop): not the
        # wavelengths, the adjoint dL nor the sample stream's constants; the forward
        # derivative only in forward mode, the medium index and null-collision count only
        # with media, the dispersion flag only with dispersion.
        cond = ConditionalState(dL_fwd=(mi.Spectrum(0.0), mode == FORWARD),
                                medium=(mi.UInt32(self._medium), has_media), n_null=(mi.UInt32(0), has_media),
                                terminated=(mi.Bool(False), bsdfs.dispersive and primal))
        cond_state = cond.state
        rng_state = rng.loop_state()

        # The body's ifs on Python values are plain ifs (mode="scalar"), so that the
        # excluded variables they read stay outside the loop.
        while dr.hint(active, label="prbvolpath", exclude=[rng, wl, dL, cond]):
            rng.set_loop_state(rng_state)
            dL_fwd, medium, n_null, terminated = cond.values(cond_state)
            # Replays differentiate the hit w.r.t. the geometry (it moves along the ray).
            si, shape = geo.intersect(ray, active, attached=not primal, coherent=depth == 0)  # camera rays
            hit = si.is_valid()
            t_hit = dr.select(hit, si.t, dr.inf)

            # -- free flight (delta tracking with real/null events) ----------------------
            scattered = mi.Bool(False)
            p_sc = mi.Point3f(0.0)
            if dr.hint(has_media, mode="scalar"):
                in_m = active & (medium > 0)
                homog = in_m & ~self._grid_lanes(media, medium - 1, in_m)
                beta, p_sc, scattered, n_null, dL_fwd = volume.free_flight(
                    media, rng, ray, medium, t_hit, wl, in_m, (beta, p_sc, scattered, n_null, dL_fwd),
                    self._real_or_null, (media, homog, mode, dL, L), factor=self.majorant_factor)
                n_null[active] = 0

            # -- surface reached (or the ray escaped): emission, MIS-weighted ---------------
            surf = active & ~scattered & hit & nonzero(beta)
            light = lights.light_of_hit(scene, shape, si, surf)
            on_light = surf & (light > 0)
            skip = on_light & (depth == 0) if self.hide_emitters else mi.Bool(False)
            on_light &= ~skip
            escaped = active & ~scattered & ~hit & nonzero(beta)
            if dr.hint(self.hide_emitters, mode="scalar"):
                escaped &= depth > 0
            with dr.resume_grad(when=not primal):
                Le = beta * emitted_mis(scene, self.light_sampler, light, si, ray.d, wl, on_light, escaped,
                                        prev_p, prev_n, prev_pdf, prev_delta)
            if dr.hint(primal, mode="scalar"):
                L = L + Le
            else:
                L = L - dr.detach(Le)
                dL_fwd = self._propagate(mode, dL, True, Le, 1.0, dL_fwd)

            bsdf_id, skip, real, at_vertex, go_on, sc, rs = volume.classify(
                scene, shape, surf, scattered, skip, depth, max_depth)
            valid |= at_vertex
            rs_sample = rs
            lobe = mi.Bool(False)
            crossed = mi.Bool(False)
            if dr.hint(bsdfs.has_null_lobes, mode="scalar"):
                # A null lobe (thindielectric's transmission) is no bounce (Mitsuba's
                # volumetric integrators): such surfaces are sampled at the depth limit too.
                lobe = real & bsdfs.has_null_lobe(bsdf_id, real) & (depth < max_depth)
                rs_sample = rs | lobe

            # -- next-event estimation ---------------------------------------------------------
            ctx = ShadingContext(si, wl)
            nee = (rs & bsdfs.smooth(bsdf_id, rs)) | sc
            u_light = rng.next_float32()
            u_pos = rng.next_2d()
            u1 = rng.next_float32()
            u2 = rng.next_2d()
            with dr.resume_grad(when=not primal):
                ref = volume.nee_reference(si, sc, p_sc)   # attached: the hit may move
                ls = lights.sample_Li(self.light_sampler, ref, u_light, u_pos, wl, nee)
                wo_em = si.to_local(ls.wi)
                f_em, pdf_em, bs = bsdfs.eval_pdf_sample(bsdf_id, ctx, wo_em, u1, u2, rs_sample)
                if dr.hint(has_media, mode="scalar"):
                    f_em, pdf_em = volume.phase_nee(media, medium, ray, ls.wi, sc, f_em, pdf_em)
                # (MIS weight detached; the attached density carries the derivative of an
                # area light sample's solid-angle measure when the shading point moves)
                w_em = dr.select(ls.delta, 1.0, power_heuristic(dr.detach(ls.pdf), dr.detach(pdf_em)))
                Ld_unocc = dr.select(nee & (ls.pdf > 0), beta * f_em * ls.L * (w_em / ls.pdf), 0.0)
                f_sampled = bs.weight * bs.pdf     # delta lobes and stochastic BSDFs (see prb)
            replay_sample = bs.delta | bsdfs.stochastic(bsdf_id, rs)
            bs = dr.detach(bs)
            sray, s_med = volume.shadow_ray(scene, shape, si, ls, sc, p_sc, medium, nee & rs)
            nee &= ls.pdf > 0
            if dr.hint(primal, mode="scalar"):
                # A shadow ray only where it can change the estimate (light_reaches' rule;
                # derivative passes trace them all: a zero estimate may have a derivative).
                nee = nonzero_estimate(Ld_unocc, nee)
            state = rng.copy()
            T_sh, _ = self._transmittance(scene, rng, sray, ls.p, s_med, wl, PRIMAL, dL, dL, dL_fwd, nee)
            if dr.hint(primal, mode="scalar"):
                L = L + dr.detach(Ld_unocc) * T_sh
            else:
                Ld = dr.detach(Ld_unocc) * T_sh
                L = L - Ld
                # Replay the shadow ray's random numbers for the transmittance derivative.
                rng2 = state.copy()
                _, dL_fwd = self._transmittance(scene, rng2, sray, ls.p, s_med, wl, mode, dL, Ld, dL_fwd, nee)

            # -- continue: BSDF or phase function sampling ----------------------------------------
            wi_next, pdf_next, w_next, delta_next = volume.sample_direction(media, medium, ray, si, bs, sc, rng)
            if dr.hint(bsdfs.has_null_lobes, mode="scalar"):
                # (The lobe weight's derivative, from specular_transmittance only, is not propagated.)
                crossed = volume.cross_null_lobe(bs, lobe, beta, go_on, rs, at_vertex, skip)
            cont = go_on & (pdf_next > 0)
            if dr.hint(not primal, mode="scalar"):
                with dr.resume_grad():
                    f_bs, _ = bsdfs.eval_pdf(bsdf_id, ctx, bs.wo, rs & cont & ~replay_sample)
                    f_bs = dr.select(replay_sample, f_sampled, f_bs)
                    f_det = bs.weight * bs.pdf
                    ratio = dr.select(f_det != 0, f_bs * dr.rcp(dr.detach(f_det)), 0.0)
                    # (lanes that crossed a null lobe: the lobe's weight times its choice
                    # probability, as for the delta lobes)
                    Lr = dr.select((rs & cont) | crossed, L * dr.replace_grad(mi.Spectrum(1.0), ratio), 0.0)
                    # One traversal for the light sample and the continuation: they share
                    # the BSDF query's graph (f_em and f_sampled), which a first traversal
                    # would clear.
                    dL_fwd = self._send(mode, dL, Lr + Ld_unocc * T_sh, dL_fwd)
            if dr.hint(bsdfs.dispersive and primal, mode="scalar"):
                term = rs & bs.terminate & ~terminated
                L[term] = first_only(L)
                beta[term] = first_only(beta)
                terminated |= term
            beta[cont] = beta * w_next
            eta[rs] = eta * bs.eta
            prev_p[cont] = ref.p
            prev_n[cont] = ref.n
            prev_pdf[cont] = pdf_next
            prev_delta[cont] = delta_next
            ray, medium = volume.next_ray(scene, shape, si, ray, medium, wi_next, p_sc, sc, cont, rs, skip)
            depth[at_vertex] = depth + 1

            # Russian roulette (detached survival probability).
            q = dr.minimum(dr.max(beta) * eta * eta, 0.95)
            rr = cont & (depth >= self.rr_depth)
            survive = rng.next_float32() < q
            beta[rr] = beta * dr.rcp(q)
            active = skip | (cont & (~rr | survive) & nonzero(beta))
            cond_state = cond.update(dL_fwd=dL_fwd, medium=medium, n_null=n_null, terminated=terminated)
            rng_state = rng.loop_state()

        rng.set_loop_state(rng_state)
        dL_fwd = cond.values(cond_state)[0]

        return (L if primal else dL_fwd), valid
