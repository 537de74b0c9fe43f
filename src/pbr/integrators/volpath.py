"""``volpath``: volumetric path tracing with null scattering and spectral MIS (pbrt-v4's
``VolPathIntegrator``; Mitsuba's ``volpath``/``volpathmis`` names select it too), and
``simplevolpath``, its reference estimator, on the shared volumetric walk
(:mod:`.volume`). Rescaled path probabilities, shadow rays and depth: docs/integrators.md.
"""

from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext, shading_context
from ..lights.lightsamplers import LIGHT_SAMPLERS
from ..spectrum import first_only
from . import subsurface, volume
from .base import INTEGRATORS, ConditionalState, SamplingIntegrator, depth_limit, mis_state, nonzero, nonzero_estimate, path_state


def _null_weights(f, r_u, r_l, T_acc, sigma_n, sigma_maj, inv_pdf, mask):
    """A null collision on ``mask`` lanes (in place): the weight ``f`` (throughput or
    transmittance) and the rescaled unidirectional probability ``r_u`` by
    ``T sigma_n / pdf``, the light-sampling one ``r_l`` by ``T sigma_maj / pdf``."""
    f[mask] = f * T_acc * sigma_n * inv_pdf
    r_u[mask] = r_u * T_acc * sigma_n * inv_pdf
    r_l[mask] = r_l * T_acc * sigma_maj * inv_pdf


class _MediumAware(SamplingIntegrator):
    """Integrators whose camera rays start in the sensor's medium."""

    _medium = 0

    def prepare(self, scene, sensor: int = 0) -> None:
        super().prepare(scene, sensor)
        self._medium = scene.sensors[sensor].medium


@INTEGRATORS.register("volpath", "volpathmis")
class VolPathIntegrator(_MediumAware):
    """``volpath`` / ``volpathmis``: volumetric path tracing with null scattering and
    spectral MIS (pbrt-v4's ``VolPathIntegrator``). Paths that reach
    ``max_null_collisions`` are ended and counted in :attr:`capped` (with a warning).

    ===================  ======  =======  =========================================================
    name                 type    default  meaning
    ===================  ======  =======  =========================================================
    max_depth            int     -1       longest path in real scattering events (in media or at
                                          non-null surfaces; -1 unlimited)
    rr_depth             int     5        depth from which Russian roulette may end a path
    hide_emitters        bool    false    camera rays pass through emitting surfaces and do not see
                                          the environment
    light_sampler        string  bvh      light choice of next-event estimation: 'uniform', 'power'
                                          or 'bvh' (pbrt-v4's light BVH)
    max_null_collisions  int     65536    null collisions a path segment or shadow ray may have
    absorption           string  weight   at a real collision: 'weight' (Mitsuba's: always scatter,
                                          weighted by the albedo sigma_s / sigma_t) or 'sample'
                                          (pbrt-v4's: absorb or scatter with probabilities
                                          sigma_a, sigma_s)
    regularize           bool    false    pbrt-v4's BSDF regularisation after the path's first
                                          non-specular bounce or medium scattering (see ``path``)
    ===================  ======  =======  =========================================================

    ``absorption``: both are unbiased. Mitsuba's weighting keeps a path alive through
    absorbing collisions (Russian roulette ends it); it is the default, as Mitsuba's
    render tests measure an image's noise against Mitsuba's own: with pbrt-v4's sampling,
    a coloured RGB albedo grid (Mitsuba's ``test_hetero_sigmat_albedo``) has 1.3x the
    per-pixel variance (median) and fails that test (0.9946 of the pixel-channels pass,
    0.9975 needed); with the weighting all 12 media scenes pass, none slower.
    """

    name = "volpath"

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", -1, min=-1)
        self.rr_depth = props.int("rr_depth", 5, min=0)
        self.hide_emitters = props.bool("hide_emitters", False)
        self.light_sampler_type = props.string("light_sampler", "bvh", choices=LIGHT_SAMPLERS)
        self.max_null = props.int("max_null_collisions", 1 << 16, min=1)
        self.weight_absorption = props.string("absorption", "weight", choices=("weight", "sample")) == "weight"
        self.regularize = props.bool("regularize", False)
        props.finish()
        self.capped = 0

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        self._capped = mi.UInt32(0)
        img = super().render(scene, sensor, seed, spp, progress)
        self.capped = int(self._capped[0])
        if self.capped:
            warnings.warn(f"volpath: {self.capped} paths reached max_null_collisions "
                          f"({self.max_null}) and were terminated (biased)", RuntimeWarning, stacklevel=2)
        return img

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if self.max_depth == 0:
            return mi.Spectrum(0.0), mi.Bool(False)
        if not hasattr(self, "_capped"):
            self._capped = mi.UInt32(0)
        return self._sample(scene, rng, ray, wl, active)

    def _count_null(self, n_null, null):
        """Count the null collisions ``null`` of each path; (new count, lanes that reach
        ``max_null``), the latter also added to the :attr:`capped` tally."""
        n_null = dr.select(null, n_null + 1, n_null)
        capped = null & (n_null >= self.max_null)
        dr.scatter_reduce(dr.ReduceOp.Add, self._capped, mi.UInt32(1), mi.UInt32(0), capped)
        return n_null, capped

    # -- collisions: delta tracking (paths) and ratio tracking (shadow rays) -----------------
    def _delta_tracking(self, state, c, rng, media, depth, max_depth):
        """A tentative collision of the path: medium emission, then absorption, real
        scattering or a null collision, chosen with the hero wavelength's probabilities;
        every wavelength keeps its rescaled path probabilities (r_u, r_l)."""
        L, beta, r_u, r_l, T_acc, p_sc, scattered, absorbed, n_null = state
        coll, sigma_maj = c.coll, c.sigma_maj
        T_acc *= c.T_maj
        mp = media.eval(c.m, c.p, c.wl, coll)
        s0 = sigma_maj[0]
        if media.has_le:
            # Medium emission, estimated at every collision (pbrt-v4).
            pdf_e = s0 * T_acc[0]
            em = coll & (depth < max_depth) & (pdf_e > 0)
            r_e = r_u * sigma_maj * T_acc * dr.rcp(pdf_e)
            L[em] = L + beta * T_acc * dr.rcp(pdf_e) * mp.sigma_a * mp.Le * dr.rcp(dr.mean(r_e))
        u_ev = rng.next_float32()
        # Real collisions that always scatter: probability sigma_t, weight sigma_s /
        # sigma_t (the albedo), per wavelength, so that the spectral MIS stays consistent.
        # Everywhere with absorption='weight' (Mitsuba's); else only where sigma_s exceeds
        # sigma_t (an albedo above 1, which Mitsuba's RGB albedo grids have at some
        # wavelengths) and absorption is sampled elsewhere (pbrt-v4's).
        if self.weight_absorption:
            p_real = mp.sigma_a + mp.sigma_s
            p_abs = mi.Float(0.0)
        else:
            p_real = mi.Spectrum(dr.select(mp.sigma_a < 0.0, mp.sigma_a + mp.sigma_s, mp.sigma_s))
            p_abs = dr.maximum(mp.sigma_a[0], 0.0) * dr.rcp(s0)
        p_sca = p_real[0] * dr.rcp(s0)
        is_abs = coll & (u_ev < p_abs)
        is_sca = coll & ~is_abs & (u_ev < p_abs + p_sca)
        is_null = coll & ~is_abs & ~is_sca
        # Real scattering: beta by T sigma_s / pdf, r_u by each wavelength's own pdf.
        pdf_s = T_acc[0] * p_real[0]
        inv_s = dr.select(pdf_s > 0, dr.rcp(pdf_s), 0.0)
        beta[is_sca] = beta * T_acc * mp.sigma_s * inv_s
        r_u[is_sca] = r_u * T_acc * p_real * inv_s
        p_sc[is_sca] = c.p
        # Null scattering: continue, reweighting every wavelength.
        sigma_n = dr.maximum(sigma_maj - mp.sigma_a - mp.sigma_s, 0.0)
        pdf_n = T_acc[0] * sigma_n[0]
        _null_weights(beta, r_u, r_l, T_acc, sigma_n, sigma_maj, dr.select(pdf_n > 0, dr.rcp(pdf_n), 0.0), is_null)
        T_acc[coll] = mi.Spectrum(1.0)
        n_null, capped = self._count_null(n_null, is_null)
        absorbed |= is_abs | capped
        scattered |= is_sca
        stop = is_abs | is_sca | capped | ~(nonzero(beta) & nonzero(r_u))
        return (L, beta, r_u, r_l, T_acc, p_sc, scattered, absorbed, n_null), stop

    def _ratio_tracking(self, state, c, rng, media):
        """A tentative collision of a shadow ray: weight every wavelength by the null
        fraction (ratio tracking), with pbrt-v4's Russian roulette on small
        transmittance."""
        T_ray, r_u, r_l, n_null, T_acc = state
        coll, sigma_maj = c.coll, c.sigma_maj
        T_acc *= c.T_maj
        mp = media.eval(c.m, c.p, c.wl, coll)
        sigma_n = dr.maximum(sigma_maj - mp.sigma_a - mp.sigma_s, 0.0)
        pdf = T_acc[0] * sigma_maj[0]
        _null_weights(T_ray, r_u, r_l, T_acc, sigma_n, sigma_maj, dr.select(pdf > 0, dr.rcp(pdf), 0.0), coll)
        T_acc[coll] = mi.Spectrum(1.0)
        # Russian roulette on small transmittance (pbrt-v4).
        tr = T_ray * dr.rcp(dr.mean(r_l + r_u))
        small = coll & (dr.max(tr) < 0.05)
        kill = small & (rng.next_float32() < 0.75)
        T_ray[kill] = mi.Spectrum(0.0)
        T_ray[small & ~kill] = T_ray * 4.0
        n_null, capped = self._count_null(n_null, coll)
        T_ray[capped] = mi.Spectrum(0.0)
        return (T_ray, r_u, r_l, n_null, T_acc), ~(dr.max(T_ray) > 0)

    def _shadow_segment(self, state, ray, medium, t_end, in_m, media, rng, wl):
        """Ratio tracking through one medium segment of a shadow ray (see
        :func:`.volume.transmittance`); state (T_ray, r_u, r_l, null collisions)."""
        T_ray, r_u, r_l, n_null, T_acc = volume.free_flight(
            media, rng, ray, medium, t_end, wl, in_m, tuple(state) + (mi.Spectrum(1.0),), self._ratio_tracking,
            (media,))
        f = volume.hero_ratio(T_acc)
        T_ray[in_m] = T_ray * f
        r_l[in_m] = r_l * f
        r_u[in_m] = r_u * f
        return T_ray, r_u, r_l, n_null

    # -- vertices ---------------------------------------------------------------------------
    @staticmethod
    def _vertex_lobe(scene, bsdf_id, ctx, active, medium, ray, sc):
        """The scattering function of a path vertex for :meth:`_next_event`: the BSDF of
        entry ``bsdf_id`` (evaluated toward the light and sampled at once), the medium's
        phase function on medium lanes ``sc``."""
        def lobe(wo_em, ls, u1, u2):
            f_em, pdf_em, bs = scene.bsdfs.eval_pdf_sample(bsdf_id, ctx, wo_em, u1, u2, active)
            if len(scene.media) > 0:
                f_em, pdf_em = volume.phase_nee(scene.media, medium, ray, ls.wi, sc, f_em, pdf_em)
            return f_em, pdf_em, bs
        return lobe

    def _next_event(self, scene, rng, wl, ref, si, shape, sc, p_sc, medium, nee, rs, L, beta, r_u, lobe):
        """Light sampling from a vertex ``ref`` (:func:`.volume.nee_reference`: ``p_sc`` on
        medium lanes ``sc``, the surface ``si`` of ``shape`` elsewhere) on lanes ``nee``
        (``rs``: those at surfaces), with the spectral MIS weight against ``lobe``'s density; ``lobe(wo, ls, u1, u2)`` gives
        (f |cos|, pdf) toward the light and a sample of the next direction. Returns (L
        with the light added, that sample)."""
        lights, media = scene.lights, scene.media
        u_light = rng.next_float32()
        u_pos = rng.next_2d()
        ls = lights.sample_Li(self.light_sampler, ref, u_light, u_pos, wl, nee)
        nee &= ls.pdf > 0
        wo_em = si.to_local(ls.wi)
        u1 = rng.next_float32()
        u2 = rng.next_2d()
        f_em, pdf_em, bs = lobe(wo_em, ls, u1, u2)
        # A shadow ray only where it can change the estimate (light_reaches' rule).
        nee = nonzero_estimate(f_em * ls.L, nee)
        sray, s_med = volume.shadow_ray(scene, shape, si, ls, sc, p_sc, medium, nee & rs)
        if len(media) > 0:
            T_ray, tr_u, tr_l, n_shadow = volume.transmittance(
                scene, sray, ls.p, s_med, nee, (mi.Spectrum(1.0), mi.Spectrum(1.0), mi.Spectrum(1.0), mi.UInt32(0)),
                self._shadow_segment, (media, rng, wl), wl=wl)
        else:
            # Without media only T changes along the shadow ray (null surfaces).
            T_ray, = volume.transmittance(scene, sray, ls.p, s_med, nee, (mi.Spectrum(1.0),),
                                          self._shadow_segment, (media, rng, wl), wl=wl)
            tr_u, tr_l = 1.0, 1.0
        rl_nee = r_u * ls.pdf * tr_l
        ru_nee = r_u * pdf_em * tr_u
        d_nee = dr.select(ls.delta, dr.mean(rl_nee), dr.mean(rl_nee + ru_nee))
        L[nee] = L + beta * f_em * T_ray * ls.L * dr.rcp(d_nee)
        return L, bs

    def _subsurface(self, scene, rng, wl, si, bsdf_id, bs, sss, L, beta, r_u, r_l, eta, prev_p, prev_n,
                    prev_delta, ray, medium, cont):
        """Lanes ``sss`` refracted into a surface (sample ``bs``), where it has a
        ``subsurface`` material: move the path to an exit point found by a probe ray,
        weighted by the BSSRDF's profile over its density (r_u by each wavelength's
        density over the hero's), sample the lights and the next direction there with the
        exit lobe S_w. Lanes with no exit point end. Returns the updated path state."""
        sss, found, si_x, shape_x, w_sp, ru_sp, eta_x = subsurface.probe(scene, rng, si, bsdf_id, wl, sss)
        beta[found] = beta * w_sp
        r_u[found] = r_u * ru_sp
        no = mi.Bool(False)
        ref = volume.nee_reference(si_x, no, si_x.p)
        L, bs_x = self._next_event(scene, rng, wl, ref, si_x, shape_x, no, si_x.p, medium, found, found, L, beta, r_u,
                                   subsurface.exit_lobe(eta_x, found))
        go = found & (bs_x.pdf > 0)
        beta[found] = beta * bs_x.weight
        r_l[found] = r_u * dr.rcp(bs_x.pdf)
        eta[found] = eta * dr.rcp(bs.eta)       # back outside
        prev_p[found] = si_x.p
        prev_n[found] = si_x.n
        prev_delta[found] = False
        wi = si_x.to_world(bs_x.wo)
        ray = dr.select(found, si_x.spawn_ray(wi), ray)
        if len(scene.media) > 0:
            medium = volume.enter(scene, shape_x, si_x, wi, medium, found)
        cont = dr.select(sss, go, cont)
        return L, beta, r_u, r_l, eta, prev_p, prev_n, prev_delta, ray, medium, cont

    # -- the estimator --------------------------------------------------------------------
    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active):
        geo, lights, bsdfs, media = scene.geometry, scene.lights, scene.bsdfs, scene.media
        has_media = len(media) > 0
        max_depth = depth_limit(self.max_depth)

        ray, active, L, beta, depth, valid = path_state(ray, active)
        prev_p, prev_n, prev_pdf, prev_delta = mis_state(ray)
        r_l = mi.Spectrum(1.0)
        eta = mi.Float(1.0)
        # Only what a bounce changes is loop state (see path's loop): not the wavelengths
        # nor the sample stream's constants, and the dispersion flag only with dispersion.
        # Without media the spectral MIS ratio r_u (1), the null-collision count and the
        # medium index (vacuum) never change: they are loop state only with media.
        terminated = mi.Bool(False) if bsdfs.dispersive else None
        # (A subsurface exit rescales r_u too.)
        cond = ConditionalState(r_u=(mi.Spectrum(1.0), has_media or bsdfs.has_subsurface),
                                n_null=(mi.UInt32(0), has_media),
                                medium=(mi.UInt32(self._medium), has_media))
        cond_state = cond.state
        # pbrt-v4's regularisation: on after the first non-specular bounce (state only with it)
        nonspecular = mi.Bool(False) if self.regularize else None
        rng_state = rng.loop_state()

        while dr.hint(active, label="volpath", exclude=[rng, wl, cond]):
            rng.set_loop_state(rng_state)
            r_u, n_null, medium = cond.values(cond_state)
            # camera rays (before the first scattering) are traced as coherent
            si, shape = geo.intersect(ray, active, coherent=depth == 0)
            hit = si.is_valid()
            t_hit = dr.select(hit, si.t, dr.inf)

            # -- free flight through the current medium (delta tracking) --------------
            scattered = mi.Bool(False)
            absorbed = mi.Bool(False)
            p_sc = mi.Point3f(0.0)
            # Plain Python ifs in this body (mode="scalar"): a transformed one would make the
            # variables it reads (rng, wl) variables of the body, unbound before it.
            if dr.hint(has_media, mode="scalar"):
                in_m = active & (medium > 0)
                L, beta, r_u, r_l, T_acc, p_sc, scattered, absorbed, n_null = volume.free_flight(
                    media, rng, ray, medium, t_hit, wl, in_m,
                    (L, beta, r_u, r_l, mi.Spectrum(1.0), p_sc, scattered, absorbed, n_null),
                    self._delta_tracking, (media, depth, max_depth))
                through = in_m & ~scattered & ~absorbed
                f = volume.hero_ratio(T_acc)
                beta[through] = beta * f
                r_u[through] = r_u * f
                r_l[through] = r_l * f
                absorbed |= in_m & (~nonzero(beta) | ~nonzero(r_u))
                n_null[active] = 0

            # -- surface reached (or the ray escaped) --------------------------------------
            surf = active & ~scattered & ~absorbed & hit
            light = lights.light_of_hit(scene, shape, si, surf)
            on_light = surf & (light > 0)
            skip = on_light & (depth == 0) if self.hide_emitters else mi.Bool(False)
            on_light &= ~skip
            Le = lights.L(light - 1, si, wl, on_light)
            pdf_light = lights.pdf_Li(self.light_sampler, light - 1, prev_p, prev_n, si, on_light & ~prev_delta)
            denom = dr.select(prev_delta, dr.mean(r_u), dr.mean(r_u + r_l * pdf_light))
            L[on_light] = L + beta * Le * dr.rcp(denom)
            if dr.hint(lights.has_infinite, mode="scalar"):
                escaped = active & ~scattered & ~absorbed & ~hit
                if dr.hint(self.hide_emitters, mode="scalar"):
                    escaped &= depth > 0
                for Le_inf, pdf_inf in lights.Le_escaped(ray.d, wl, prev_p, prev_n, escaped, self.light_sampler):
                    d_inf = dr.select(prev_delta, dr.mean(r_u), dr.mean(r_u + r_l * pdf_inf))
                    L[escaped] = L + beta * Le_inf * dr.rcp(d_inf)

            bsdf_id, skip, real, at_vertex, go_on, sc, rs = volume.classify(
                scene, shape, surf, scattered, skip, depth, max_depth)
            valid |= at_vertex
            rs_sample = rs
            lobe = mi.Bool(False)
            if dr.hint(bsdfs.has_null_lobes, mode="scalar"):
                # A null lobe (thindielectric's transmission) is no bounce (Mitsuba's
                # volpath): such surfaces are sampled at the depth limit too.
                lobe = real & bsdfs.has_null_lobe(bsdf_id, real) & (depth < max_depth)
                rs_sample = rs | lobe

            # -- next-event estimation from the vertex (surface or medium point) ----------
            ctx = shading_context(si, wl, nonspecular)
            smooth = rs & bsdfs.smooth(bsdf_id, rs, nonspecular)
            nee = smooth | sc
            ref = volume.nee_reference(si, sc, p_sc)
            L, bs = self._next_event(scene, rng, wl, ref, si, shape, sc, p_sc, medium, nee, rs, L, beta, r_u,
                                     self._vertex_lobe(scene, bsdf_id, ctx, rs_sample, medium, ray, sc))

            # -- continue: sample the BSDF or the phase function -------------------------
            wi_next, pdf_next, w_next, delta_next = volume.sample_direction(media, medium, ray, si, bs, sc, rng)
            if dr.hint(bsdfs.has_null_lobes, mode="scalar"):
                volume.cross_null_lobe(bs, lobe, beta, go_on, rs, at_vertex, skip)
            cont = go_on & (pdf_next > 0)
            if dr.hint(bsdfs.dispersive, mode="scalar"):
                term = rs & bs.terminate & ~terminated
                L[term] = first_only(L)
                beta[term] = first_only(beta)
                terminated |= term
            beta[cont] = beta * w_next
            r_l[cont] = r_u * dr.rcp(pdf_next)
            eta[rs] = eta * bs.eta
            prev_p[cont] = ref.p
            prev_n[cont] = ref.n
            prev_delta[cont] = delta_next
            if dr.hint(nonspecular is not None, mode="scalar"):
                nonspecular |= cont & ~delta_next     # a glossy or diffuse bounce, or a medium scattering
            ray, medium = volume.next_ray(scene, shape, si, ray, medium, wi_next, p_sc, sc, cont, rs, skip)
            depth[at_vertex] = depth + 1
            if dr.hint(bsdfs.has_subsurface, mode="scalar"):
                # Light refracted into a subsurface material leaves at an exit point found
                # by a probe ray (pbrt-v4's VolPathIntegrator; no bounce is counted).
                sss = cont & rs & (bs.wo.z * si.wi.z < 0)
                L, beta, r_u, r_l, eta, prev_p, prev_n, prev_delta, ray, medium, cont = self._subsurface(
                    scene, rng, wl, si, bsdf_id, bs, sss, L, beta, r_u, r_l, eta, prev_p, prev_n, prev_delta, ray,
                    medium, cont)

            # Russian roulette on the MIS-weighted throughput (detached probability).
            rr_w = dr.max(beta * dr.rcp(dr.mean(r_u))) * eta * eta
            q = dr.minimum(rr_w, 0.95)
            rr = cont & (depth >= self.rr_depth)
            survive = rng.next_float32() < q
            beta[rr] = beta * dr.rcp(q)
            active = skip | (cont & (~rr | survive) & nonzero(beta))
            cond_state = cond.update(r_u=r_u, n_null=n_null, medium=medium)
            rng_state = rng.loop_state()

        rng.set_loop_state(rng_state)
        return L, valid


@INTEGRATORS.register("simplevolpath")
class SimpleVolPathIntegrator(_MediumAware):
    """``simplevolpath`` (pbrt-v4's ``SimpleVolPathIntegrator``): a reference estimator
    with no light sampling and no spectral MIS. Only the first wavelength is traced (the
    others are terminated, as pbrt-v4 does); free flights use delta tracking, emission is
    found by hitting lights, surfaces scatter by BSDF sampling.

    =========  ====  =======  =====================================================
    name       type  default  meaning
    =========  ====  =======  =====================================================
    max_depth  int   5        longest path in real scattering events (-1 unlimited)
    =========  ====  =======  =====================================================
    """

    name = "simplevolpath"
    light_sampler_type = "uniform"   # unused: no light sampling

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", 5, min=-1)
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        return self._sample(scene, rng, ray, wl, active)

    @staticmethod
    def _delta_tracking(state, c, rng, media, depth, max_depth):
        """A tentative collision, first wavelength only: emission, then absorption or
        real scattering with probabilities sigma_a / sigma_maj and sigma_s / sigma_maj."""
        L, beta, p_sc, scattered, absorbed = state
        coll = c.coll
        mp = media.eval(c.m, c.p, c.wl, coll)
        s0 = c.sigma_maj[0]
        if media.has_le:
            L[coll & (depth < max_depth)] = L + beta * mp.sigma_a[0] * mp.Le[0] * dr.rcp(s0)
        u = rng.next_float32()
        p_abs = mp.sigma_a[0] * dr.rcp(s0)
        is_abs = coll & (u < p_abs)
        is_sca = coll & ~is_abs & (u < p_abs + mp.sigma_s[0] * dr.rcp(s0))
        p_sc[is_sca] = c.p
        absorbed |= is_abs
        scattered |= is_sca
        return (L, beta, p_sc, scattered, absorbed), is_abs | is_sca

    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active):
        geo, lights, bsdfs, media = scene.geometry, scene.lights, scene.bsdfs, scene.media
        max_depth = depth_limit(self.max_depth)
        L = mi.Float(0.0)
        beta = mi.Float(1.0)
        depth = mi.UInt32(0)
        # The medium index is loop state only with media (see volpath's loop).
        cond = ConditionalState(medium=(mi.UInt32(self._medium), len(media) > 0))
        cond_state = cond.state
        active = mi.Bool(active)
        valid = mi.Bool(False)
        ray = mi.Ray3f(ray)
        has_media = len(media) > 0
        # Not loop state (see volpath's loop): the wavelengths, the stream's constants.
        rng_state = rng.loop_state()
        while dr.hint(active, label="simplevolpath", exclude=[rng, wl, cond]):
            rng.set_loop_state(rng_state)
            medium, = cond.values(cond_state)
            si, shape = geo.intersect(ray, active)
            hit = si.is_valid()
            scattered = mi.Bool(False)
            absorbed = mi.Bool(False)
            p_sc = mi.Point3f(0.0)
            if dr.hint(has_media, mode="scalar"):
                L, beta, p_sc, scattered, absorbed = volume.free_flight(
                    media, rng, ray, medium, dr.select(hit, si.t, dr.inf), wl, active & (medium > 0),
                    (L, beta, p_sc, scattered, absorbed), self._delta_tracking, (media, depth, max_depth))
            surf = active & ~scattered & ~absorbed & hit
            light = lights.light_of_hit(scene, shape, si, surf)
            on = surf & (light > 0)
            L[on] = L + beta * lights.L(light - 1, si, wl, on)[0]
            if dr.hint(lights.has_infinite, mode="scalar"):
                esc = active & ~scattered & ~absorbed & ~hit
                for Le_inf, _ in lights.Le_escaped(ray.d, wl, ray.o, mi.Normal3f(0.0), esc):
                    L[esc] = L + beta * Le_inf[0]
            bsdf_id, skip, real, at_vertex, go_on, sc, rs = volume.classify(
                scene, shape, surf, scattered, mi.Bool(False), depth, max_depth)
            valid |= at_vertex
            ctx = ShadingContext(si, wl)
            bs = bsdfs.sample(bsdf_id, ctx, rng.next_float32(), rng.next_2d(), rs)
            wi, pdf, weight, delta = volume.sample_direction(media, medium, ray, si, bs, sc, rng)
            cont = go_on & (pdf > 0)
            beta[cont] = beta * weight[0]
            ray, medium = volume.next_ray(scene, shape, si, ray, medium, wi, p_sc, sc, cont, rs, skip)
            depth[at_vertex] = depth + 1
            active = skip | (cont & nonzero(beta))
            cond_state = cond.update(medium=medium)
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)
        # Only the first wavelength was traced: it stands for all four.
        return first_only(mi.Spectrum(L)), valid
