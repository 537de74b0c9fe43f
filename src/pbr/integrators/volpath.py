"""``volpath``: volumetric path tracing with null scattering and spectral MIS (pbrt-v4's
VolPathIntegrator; Mitsuba's ``volpath``/``volpathmis`` names select it too).

Free flights are sampled against the medium majorant with the first (hero) wavelength;
every wavelength keeps its own *rescaled path probabilities* ``r_u`` (unidirectional:
the density of having sampled this path with that wavelength's coefficients) and
``r_l`` (the same path ending in light sampling). Contributions are divided by the
average of these over the wavelengths, which is one-sample MIS across wavelengths:
chromatic media (``sigma_t`` varying with wavelength) do not produce the fireflies that
hero-wavelength-only tracking gives. The same ratios give the MIS weights between light
sampling and BSDF/phase sampling (the balance heuristic).

Shadow rays estimate transmittance by ratio tracking through media and ``null``
surfaces (with pbrt-v4's Russian roulette once it is small). Every null collision is
bounded per segment (``max_null``); paths that reach the bound are terminated and
counted in :attr:`VolPathIntegrator.capped` (a warning reports them).

Conventions: ``max_depth`` as Mitsuba's volpath (real scattering events, in media or at
non-null surfaces, count; null surfaces do not; -1 is unlimited); ``hide_emitters``:
camera rays pass through area lights. Surfaces whose BSDF is ``null`` are medium
boundaries: paths and shadow rays cross them unchanged.
"""

from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from ..lights.lightsamplers import LIGHT_SAMPLERS
from ..media import majorant
from ..spectrum import first_only
from .base import INTEGRATORS, SamplingIntegrator, PRIMAL

SHADOW_EPSILON = 1e-4


def _hero_ratio(T_maj):
    """T_maj / T_maj[0]: the weight of a segment passed without a collision, sampled
    with the hero wavelength's probability T_maj[0] (0 where that is 0)."""
    t0 = T_maj[0]
    return dr.select(t0 > 0, T_maj * dr.rcp(t0), 0.0)


class _MediumAware(SamplingIntegrator):
    """Integrators whose camera rays start in the sensor's medium."""

    _medium = 0

    def _plan(self, scene, sensor, spp):
        self._medium = scene.sensors[sensor].medium
        return super()._plan(scene, sensor, spp)


@INTEGRATORS.register("volpath", "volpathmis")
class VolPathIntegrator(_MediumAware):
    name = "volpath"

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", -1, min=-1)
        self.rr_depth = props.int("rr_depth", 5, min=0)
        self.hide_emitters = props.bool("hide_emitters", False)
        self.light_sampler = props.string("light_sampler", "bvh", choices=LIGHT_SAMPLERS)
        self.max_null = props.int("max_null_collisions", 1 << 16, min=1)
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

    def render_backward(self, *a, **k):
        raise NotImplementedError("volpath: gradients through participating media are not implemented yet")

    render_forward = render_backward

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if mode != PRIMAL:
            self.render_backward()
        if self.max_depth == 0:
            return mi.Spectrum(0.0), mi.Bool(False)
        if not hasattr(self, "_capped"):
            self._capped = mi.UInt32(0)
        return self._sample(scene, rng, ray, wl, active)

    # -- helpers ----------------------------------------------------------------------
    @staticmethod
    def _enter(scene, shape, si, d, medium, active):
        """The medium after crossing surface ``si`` of ``shape`` along world direction ``d``."""
        trans = active & dr.gather(mi.Bool, scene.shape_transition, shape, active)
        inside = dr.gather(mi.UInt32, scene.shape_interior, shape, trans)
        outside = dr.gather(mi.UInt32, scene.shape_exterior, shape, trans)
        return dr.select(trans, dr.select(dr.dot(d, si.n) > 0, outside, inside), medium)

    @staticmethod
    def _cross_null(scene, shape, si, ray, p_light, medium, hit):
        """A shadow ray toward ``p_light`` meets surface ``si``: (lanes that pass it,
        being ``null`` surfaces, the medium beyond, the ray continuing behind it)."""
        bid = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
        passable = hit & scene.bsdfs.is_null(bid, hit)
        medium = VolPathIntegrator._enter(scene, shape, si, ray.d, medium, passable)
        nxt = VolPathIntegrator._aim(si.spawn_ray(dr.normalize(p_light - si.p)), p_light)
        return passable, medium, dr.select(passable, nxt, ray)

    @staticmethod
    def _aim(ray, p_light):
        """``ray`` re-aimed from its origin at ``p_light``. A spawned ray's origin is
        offset along the surface normal; keeping the direction taken from the unshifted
        point makes a shadow ray meet the light's own surface short of ``p_light``
        (which then counts as an occluder: up to half the direct light was lost with the
        light 0.1 above a floor), or drift past it after crossing null surfaces."""
        ray.d = dr.normalize(p_light - ray.o)
        return ray

    def _count_null(self, n_null, null):
        """Count the null collisions ``null`` of each path; (new count, lanes that reach
        ``max_null``), the latter also added to the :attr:`capped` tally."""
        n_null = dr.select(null, n_null + 1, n_null)
        capped = null & (n_null >= self.max_null)
        dr.scatter_reduce(dr.ReduceOp.Add, self._capped, mi.UInt32(1), mi.UInt32(0), capped)
        return n_null, capped

    @dr.syntax
    def _transmittance(self, scene, rng, ray, p_light, medium, wl, active):
        """Ratio-tracking transmittance from ``ray.o`` to ``p_light`` through media and
        null surfaces: (T_ray, r_u, r_l) with pbrt-v4's rescaled probabilities."""
        geo, media = scene.geometry, scene.media
        T_ray = mi.Spectrum(1.0)
        r_u = mi.Spectrum(1.0)
        r_l = mi.Spectrum(1.0)
        going = mi.Bool(active)
        med = mi.UInt32(medium)
        ray = mi.Ray3f(ray)
        n_null = mi.UInt32(0)
        has_media = len(media) > 0
        while dr.hint(going, label="volpath_shadow"):
            remaining = dr.norm(p_light - ray.o)
            si, shape = geo.intersect(ray, going)
            hit = going & si.is_valid() & (si.t < remaining * (1.0 - SHADOW_EPSILON))
            t_end = dr.select(hit, si.t, remaining)
            if has_media:
                in_m = going & (med > 0)
                m = med - 1
                it = majorant.start(media, m, ray, t_end, in_m)
                T_acc = mi.Spectrum(1.0)
                inner = mi.Bool(in_m)
                while dr.hint(inner, label="volpath_ratio_tracking"):
                    coll, T_maj, sigma_maj, done = majorant.step(media, it, m, wl, rng.next_float32(), inner)
                    T_acc *= T_maj
                    mp = media.eval(m, ray.o + ray.d * it.t, wl, coll)
                    sigma_n = dr.maximum(sigma_maj - mp.sigma_a - mp.sigma_s, 0.0)
                    pdf = T_acc[0] * sigma_maj[0]
                    inv = dr.select(pdf > 0, dr.rcp(pdf), 0.0)
                    T_ray[coll] = T_ray * T_acc * sigma_n * inv
                    r_l[coll] = r_l * T_acc * sigma_maj * inv
                    r_u[coll] = r_u * T_acc * sigma_n * inv
                    T_acc[coll] = mi.Spectrum(1.0)
                    # Russian roulette on small transmittance (pbrt-v4).
                    tr = T_ray * dr.rcp(dr.mean(r_l + r_u))
                    small = coll & (dr.max(tr) < 0.05)
                    kill = small & (rng.next_float32() < 0.75)
                    T_ray[kill] = mi.Spectrum(0.0)
                    T_ray[small & ~kill] = T_ray * 4.0
                    n_null, capped = self._count_null(n_null, coll)
                    T_ray[capped] = mi.Spectrum(0.0)
                    inner &= ~done & (dr.max(T_ray) > 0)
                f = _hero_ratio(T_acc)
                T_ray[in_m] = T_ray * f
                r_l[in_m] = r_l * f
                r_u[in_m] = r_u * f
            passable, med, ray = self._cross_null(scene, shape, si, ray, p_light, med, hit)
            T_ray[hit & ~passable] = mi.Spectrum(0.0)
            going &= passable & (dr.max(T_ray) > 0)
        return T_ray, r_u, r_l

    # -- the estimator --------------------------------------------------------------------
    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active):
        geo, lights, bsdfs, tex, media = scene.geometry, scene.lights, scene.bsdfs, scene.textures, scene.media
        has_media = len(media) > 0
        max_depth = self.max_depth if self.max_depth >= 0 else 0xFFFFFFFF

        L = mi.Spectrum(0.0)
        beta = mi.Spectrum(1.0)
        r_u = mi.Spectrum(1.0)
        r_l = mi.Spectrum(1.0)
        eta = mi.Float(1.0)
        depth = mi.UInt32(0)
        medium = mi.UInt32(self._medium)
        prev_p = mi.Point3f(ray.o)
        prev_n = mi.Normal3f(0.0)
        prev_delta = mi.Bool(True)
        valid = mi.Bool(False)
        terminated = mi.Bool(False)
        active = mi.Bool(active)
        ray = mi.Ray3f(ray)
        n_null = mi.UInt32(0)

        while dr.hint(active, label="volpath"):
            si, shape = geo.intersect(ray, active)
            hit = si.is_valid()
            t_hit = dr.select(hit, si.t, dr.inf)

            # -- free flight through the current medium (delta tracking) --------------
            scattered = mi.Bool(False)
            absorbed = mi.Bool(False)
            p_sc = mi.Point3f(0.0)
            if has_media:
                in_m = active & (medium > 0)
                m = medium - 1
                it = majorant.start(media, m, ray, t_hit, in_m)
                T_acc = mi.Spectrum(1.0)
                going = mi.Bool(in_m)
                while dr.hint(going, label="volpath_delta_tracking"):
                    coll, T_maj, sigma_maj, done = majorant.step(media, it, m, wl, rng.next_float32(), going)
                    T_acc *= T_maj
                    p = ray.o + ray.d * it.t
                    mp = media.eval(m, p, wl, coll)
                    s0 = sigma_maj[0]
                    if media.has_le:
                        # Medium emission, estimated at every collision (pbrt-v4).
                        pdf_e = s0 * T_acc[0]
                        em = coll & (depth < max_depth) & (pdf_e > 0)
                        r_e = r_u * sigma_maj * T_acc * dr.rcp(pdf_e)
                        L[em] = L + beta * T_acc * dr.rcp(pdf_e) * mp.sigma_a * mp.Le * dr.rcp(dr.mean(r_e))
                    u_ev = rng.next_float32()
                    p_abs = mp.sigma_a[0] * dr.rcp(s0)
                    p_sca = mp.sigma_s[0] * dr.rcp(s0)
                    is_abs = coll & (u_ev < p_abs)
                    is_sca = coll & ~is_abs & (u_ev < p_abs + p_sca)
                    is_null = coll & ~is_abs & ~is_sca
                    # Real scattering: beta and r_u by T sigma_s / pdf.
                    pdf_s = T_acc[0] * mp.sigma_s[0]
                    w_s = T_acc * mp.sigma_s * dr.select(pdf_s > 0, dr.rcp(pdf_s), 0.0)
                    beta[is_sca] = beta * w_s
                    r_u[is_sca] = r_u * w_s
                    p_sc[is_sca] = p
                    # Null scattering: continue, reweighting every wavelength.
                    sigma_n = dr.maximum(sigma_maj - mp.sigma_a - mp.sigma_s, 0.0)
                    pdf_n = T_acc[0] * sigma_n[0]
                    inv_n = dr.select(pdf_n > 0, dr.rcp(pdf_n), 0.0)
                    beta[is_null] = beta * T_acc * sigma_n * inv_n
                    r_u[is_null] = r_u * T_acc * sigma_n * inv_n
                    r_l[is_null] = r_l * T_acc * sigma_maj * inv_n
                    T_acc[coll] = mi.Spectrum(1.0)
                    n_null, capped = self._count_null(n_null, is_null)
                    absorbed |= is_abs | capped
                    scattered |= is_sca
                    going &= ~done & ~is_abs & ~is_sca & ~capped & (dr.max(beta) > 0) & (dr.max(r_u) > 0)
                through = in_m & ~scattered & ~absorbed
                f = _hero_ratio(T_acc)
                beta[through] = beta * f
                r_u[through] = r_u * f
                r_l[through] = r_l * f
                absorbed |= in_m & ((dr.max(beta) <= 0) | (dr.max(r_u) <= 0))
                n_null[active] = 0

            # -- surface reached (or the ray escaped) --------------------------------------
            surf = active & ~scattered & ~absorbed & hit
            light = lights.light_of_hit(scene, shape, si, surf)
            on_light = surf & (light > 0)
            skip = on_light & (depth == 0) if self.hide_emitters else mi.Bool(False)
            on_light &= ~skip
            Le = lights.L(light - 1, si, wl, on_light)
            pdf_light = lights.pdf_Li(light - 1, prev_p, prev_n, si, on_light & ~prev_delta)
            denom = dr.select(prev_delta, dr.mean(r_u), dr.mean(r_u + r_l * pdf_light))
            L[on_light] = L + beta * Le * dr.rcp(denom)
            if lights.has_infinite:
                escaped = active & ~scattered & ~absorbed & ~hit
                if self.hide_emitters:
                    escaped &= depth > 0
                for Le_inf, pdf_inf in lights.Le_escaped(ray.d, wl, prev_p, prev_n, escaped):
                    d_inf = dr.select(prev_delta, dr.mean(r_u), dr.mean(r_u + r_l * pdf_inf))
                    L[escaped] = L + beta * Le_inf * dr.rcp(d_inf)

            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, surf)
            skip |= surf & bsdfs.is_null(bsdf_id, surf)
            real = surf & ~skip
            valid |= real | scattered
            # Depth: a real scattering event (medium or surface) is one more vertex.
            at_vertex = real | scattered
            go_on = at_vertex & (depth + 1 < max_depth)
            sc = go_on & scattered
            rs = go_on & real

            # -- next-event estimation from the vertex (surface or medium point) ----------
            ctx = ShadingContext(si, wl, tex)
            smooth = rs & bsdfs.smooth(bsdf_id, rs)
            nee = smooth | sc
            ref = dr.zeros(mi.SurfaceInteraction3f)
            ref.p = dr.select(sc, p_sc, si.p)
            ref.n = dr.select(sc, mi.Normal3f(0.0), si.n)
            ref.time = si.time
            u_light = rng.next_float32()
            u_pos = mi.Point2f(rng.next_float32(), rng.next_float32())
            ls = lights.sample_Li(ref, u_light, u_pos, wl, nee)
            nee &= ls.pdf > 0
            wo_em = si.to_local(ls.wi)
            u1 = rng.next_float32()
            u2 = mi.Point2f(rng.next_float32(), rng.next_float32())
            f_em, pdf_em, bs = bsdfs.eval_pdf_sample(bsdf_id, ctx, wo_em, u1, u2, rs)
            if has_media:
                wo_m = -ray.d
                f_ph = media.phase_eval(medium - 1, wo_m, ls.wi, sc)
                f_em = dr.select(sc, mi.Spectrum(f_ph), f_em)
                pdf_em = dr.select(sc, f_ph, pdf_em)
            sray = si.spawn_ray(ls.wi)
            sray.o[sc] = p_sc
            sray = self._aim(sray, ls.p)
            s_med = medium
            if has_media:
                s_med = self._enter(scene, shape, si, ls.wi, medium, nee & rs)
            T_ray, tr_u, tr_l = self._transmittance(scene, rng, sray, ls.p, s_med, wl, nee)
            rl_nee = r_u * ls.pdf * tr_l
            ru_nee = r_u * pdf_em * tr_u
            d_nee = dr.select(ls.delta, dr.mean(rl_nee), dr.mean(rl_nee + ru_nee))
            L[nee] = L + beta * f_em * T_ray * ls.L * dr.rcp(d_nee)

            # -- continue: sample the BSDF or the phase function -------------------------
            wi_next = si.to_world(bs.wo)
            pdf_next = mi.Float(bs.pdf)
            w_next = mi.Spectrum(bs.weight)
            delta_next = mi.Bool(bs.delta)
            if has_media:
                wph, pph = media.phase_sample(medium - 1, -ray.d, mi.Point2f(rng.next_float32(), rng.next_float32()), sc)
                wi_next = dr.select(sc, wph, wi_next)
                pdf_next = dr.select(sc, pph, pdf_next)
                w_next = dr.select(sc, mi.Spectrum(1.0), w_next)
                delta_next = delta_next & ~sc
            cont = go_on & (pdf_next > 0)
            if bsdfs.dispersive:
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
            new_ray = si.spawn_ray(wi_next)
            new_ray.o[sc] = p_sc
            if has_media:
                medium = self._enter(scene, shape, si, wi_next, medium, cont & rs)
                medium = self._enter(scene, shape, si, ray.d, medium, skip)
            ray = dr.select(cont, new_ray, dr.select(skip, si.spawn_ray(ray.d), ray))
            depth[at_vertex] = depth + 1

            # Russian roulette on the MIS-weighted throughput (detached probability).
            rr_w = dr.max(beta * dr.rcp(dr.mean(r_u))) * eta * eta
            q = dr.minimum(rr_w, 0.95)
            rr = cont & (depth >= self.rr_depth)
            survive = rng.next_float32() < q
            beta[rr] = beta * dr.rcp(q)
            active = skip | (cont & (~rr | survive) & (dr.max(beta) > 0))

        return L, valid


@INTEGRATORS.register("simplevolpath")
class SimpleVolPathIntegrator(_MediumAware):
    """``simplevolpath`` (pbrt-v4's SimpleVolPathIntegrator): a reference estimator with
    no light sampling and no spectral MIS. Only the first wavelength is traced (the
    others are terminated, as pbrt-v4 does); free flights use delta tracking, emission
    is found by hitting lights, surfaces scatter by BSDF sampling."""

    name = "simplevolpath"

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", 5, min=-1)
        props.finish()
        self.light_sampler = "uniform"

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if mode != PRIMAL:
            raise NotImplementedError("simplevolpath: no gradients (use volpath)")
        return self._sample(scene, rng, ray, wl, active)

    @dr.syntax
    def _sample(self, scene, rng, ray, wl, active):
        geo, lights, bsdfs, tex, media = scene.geometry, scene.lights, scene.bsdfs, scene.textures, scene.media
        max_depth = self.max_depth if self.max_depth >= 0 else 0xFFFFFFFF
        L = mi.Float(0.0)
        beta = mi.Float(1.0)
        depth = mi.UInt32(0)
        medium = mi.UInt32(self._medium)
        active = mi.Bool(active)
        valid = mi.Bool(False)
        ray = mi.Ray3f(ray)
        has_media = len(media) > 0
        while dr.hint(active, label="simplevolpath"):
            si, shape = geo.intersect(ray, active)
            hit = si.is_valid()
            scattered = mi.Bool(False)
            absorbed = mi.Bool(False)
            p_sc = mi.Point3f(0.0)
            if has_media:
                in_m = active & (medium > 0)
                m = medium - 1
                it = majorant.start(media, m, ray, dr.select(hit, si.t, dr.inf), in_m)
                going = mi.Bool(in_m)
                while dr.hint(going, label="simplevolpath_tracking"):
                    coll, _, sigma_maj, done = majorant.step(media, it, m, wl, rng.next_float32(), going)
                    p = ray.o + ray.d * it.t
                    mp = media.eval(m, p, wl, coll)
                    s0 = sigma_maj[0]
                    if media.has_le:
                        L[coll & (depth < max_depth)] = L + beta * mp.sigma_a[0] * mp.Le[0] * dr.rcp(s0)
                    u = rng.next_float32()
                    p_abs = mp.sigma_a[0] * dr.rcp(s0)
                    is_abs = coll & (u < p_abs)
                    is_sca = coll & ~is_abs & (u < p_abs + mp.sigma_s[0] * dr.rcp(s0))
                    p_sc[is_sca] = p
                    absorbed |= is_abs
                    scattered |= is_sca
                    going &= ~done & ~is_abs & ~is_sca
            surf = active & ~scattered & ~absorbed & hit
            light = lights.light_of_hit(scene, shape, si, surf)
            on = surf & (light > 0)
            L[on] = L + beta * lights.L(light - 1, si, wl, on)[0]
            if lights.has_infinite:
                esc = active & ~scattered & ~absorbed & ~hit
                for Le_inf, _ in lights.Le_escaped(ray.d, wl, ray.o, mi.Normal3f(0.0), esc):
                    L[esc] = L + beta * Le_inf[0]
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, surf)
            skip = surf & bsdfs.is_null(bsdf_id, surf)
            real = surf & ~skip
            valid |= real | scattered
            go_on = (real | scattered) & (depth + 1 < max_depth)
            ctx = ShadingContext(si, wl, tex)
            bs = bsdfs.sample(bsdf_id, ctx, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()),
                              go_on & real)
            wi = si.to_world(bs.wo)
            w = bs.weight[0]
            pdf = mi.Float(bs.pdf)
            if has_media:
                wph, pph = media.phase_sample(medium - 1, -ray.d, mi.Point2f(rng.next_float32(), rng.next_float32()),
                                              go_on & scattered)
                wi = dr.select(scattered, wph, wi)
                w = dr.select(scattered, 1.0, w)
                pdf = dr.select(scattered, pph, pdf)
            cont = go_on & (pdf > 0)
            beta[cont] = beta * w
            new_ray = si.spawn_ray(wi)
            new_ray.o[scattered] = p_sc
            if has_media:
                medium = VolPathIntegrator._enter(scene, shape, si, wi, medium, cont & real)
                medium = VolPathIntegrator._enter(scene, shape, si, ray.d, medium, skip)
            ray = dr.select(cont, new_ray, dr.select(skip, si.spawn_ray(ray.d), ray))
            depth[real | scattered] = depth + 1
            active = skip | (cont & (beta > 0))
        # Only the first wavelength was traced: it stands for all four.
        return first_only(mi.Spectrum(L)), valid
