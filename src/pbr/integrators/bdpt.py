"""``bdpt``: bidirectional path tracing with MIS over all strategies (pbrt-v4's
``BDPTIntegrator``). Light subpaths are generated and stored first (splatting the t = 1
strategies), then camera subpaths connect to them; MIS sums are kept along each subpath.
The strategies, the MIS recurrence and the vectorisation: docs/integrators.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..backend import Struct
from ..bsdfs.base import ShadingContext
from ..lights.directional import DirectionalLight
from ..lights.directionalarea import DirectionalAreaLight
from ..spectrum import first_only
from .base import INTEGRATORS, loop_ray, nonzero, nonzero_estimate, ray_state
from .lightpath import (LightTracingIntegrator, connect_to_camera, eval_importance, lens_sample,
                        sample_importance, shading_correction, start_light_path)

# Per-vertex flags of stored light vertices.
DELTA = 1        # the direction leaving the vertex was sampled from a Dirac-delta lobe
INFINITE = 2     # y_0 of an infinite or directional light (a direction, not a point)
TERMINATED = 4   # a dispersive refraction came before: only the first wavelength is valid

# Per-light kinds (for next-event estimation, where the light is known by its index).
DELTA_POSITION, DELTA_DIRECTION, INFINITE_LIGHT = 1, 2, 4

MAX_SAMPLES_PER_PASS = 1 << 18   # camera samples per pass (each stores its light subpath)

# Random numbers the subpaths draw (``rng.next_float32()``), which MLT's primary samples
# must hold: a light subpath 5 to start (light, position, direction) and 3 at each vertex
# it extends (the BSDF sample); a camera subpath 6 at each vertex (light choice and
# position for next-event estimation, then the BSDF sample). With a thin lens, each light
# vertex also draws the lens point of its camera connection (LENS_DIMS more).
LIGHT_START_DIMS, LIGHT_VERTEX_DIMS, CAMERA_VERTEX_DIMS, LENS_DIMS = 5, 3, 6, 2


class LightVertex(Struct):
    """A stored light-subpath vertex: the ray that found it (``o``, ``d``), its position
    ``p``, geometric normal ``n`` (0 for a point light), throughput ``beta``, forward
    density ``fwd`` (area measure; solid angle for y_0 of an infinite light), the MIS
    sum ``E`` (see the module docstring) and ``flags``."""

    _fields = {"o": "Point3f", "d": "Vector3f", "p": "Point3f", "n": "Normal3f", "beta": "Spectrum",
               "fwd": "Float", "E": "Float", "flags": "UInt32"}


# ------------------------------------------------------------------------ MIS weights

def remap0(pdf):
    """pbrt-v4's ``remap0``: a Dirac delta's density (stored as 0) counts as 1."""
    return dr.select(pdf != 0, pdf, 1.0)


def advance_sum(E_prev, rev_prev, fwd_prev, delta, delta_prev):
    """E_k from E_{k-1}: the sum over the hypothetical strategies that would end this
    subpath at or before vertex k, each the product of the ratios pdfRev/pdfFwd of the
    vertices between (``rev_prev``/``fwd_prev``: those of vertex k - 1)."""
    term = dr.select(delta | delta_prev, 0.0, 1.0)
    return term + remap0(rev_prev) / remap0(fwd_prev) * E_prev


def side_sum(rev_end, fwd_end, rev_prev, fwd_prev, delta_prev, E_prev):
    """One subpath's part of pbrt-v4's ``sumRi`` for a strategy that ends it at vertex
    ``end`` (its predecessor: ``prev``). ``rev_end`` and ``rev_prev`` are the reverse
    densities the connection gives them; the end vertex counts as non-delta."""
    inner = dr.select(delta_prev, 0.0, 1.0) + remap0(rev_prev) / remap0(fwd_prev) * E_prev
    return remap0(rev_end) / remap0(fwd_end) * inner


def mis_weight(sum_camera, sum_light):
    """Balance-heuristic weight of a strategy: 1 / (1 + sum of the other strategies'
    density ratios)."""
    return dr.rcp(1.0 + sum_camera + sum_light)


class Strategies:
    """The strategies (s, t) one BDPT evaluation computes, and the weight each gets.

    ``Strategies(maxdepth)``: all of them, MIS-weighted (the BDPT estimator).
    ``Strategies(maxdepth, s, t)``: one strategy per lane (``mi.UInt32`` s and t, per lane
    or of width 1): pbrt-v4's MLT picks one per Markov chain and iteration, and
    ``render_strategies`` one per image. The other strategies' work (shadow rays,
    connections) is masked off and, with ``truncate``, the subpaths stop at the vertices
    the strategy joins (light vertices y_0 .. y_{s-1}, camera vertices z_0 .. z_{t-1});
    without it they keep their full length and use the same random numbers as the full
    estimator. ``weighted=False`` drops the MIS weight (pbrt-v4's ``visualizestrategies``).
    """

    def __init__(self, maxdepth, s=None, t=None, weighted=True, truncate=True):
        self.every = s is None
        self.s, self.t, self.weighted = s, t, weighted
        # Vertices each subpath needs (a number, or per lane).
        cut = truncate and not self.every
        self.light_max = s if cut else maxdepth + 1
        self.camera_max = t if cut else maxdepth + 2

    def wants(self, s, t):
        """Mask of the lanes that evaluate strategy (s, t)."""
        return True if self.every else (self.s == s) & (self.t == t)

    def weight(self, s, t, w):
        """The factor a contribution of strategy (s, t) with MIS weight ``w`` gets."""
        w = w if self.weighted else mi.Float(1.0)
        return w if self.every else dr.select(self.wants(s, t), w, 0.0)

    def connections(self, k, s_max):
        """(first, last) s >= 2 whose strategy joins camera vertex z_k (t = k + 1) to a stored
        light vertex, given the last one the light subpath allows (``s_max``)."""
        if self.every:
            return mi.UInt32(2), s_max
        last = dr.select(self.t == k + 1, dr.minimum(self.s, s_max), 0)
        return dr.maximum(self.s, 2), last


# ------------------------------------------------------------------------ helpers

def to_area(pdf, p_from, p_to, n_to, direction_only=None):
    """pbrt-v4's ``ConvertDensity``: a solid-angle density at ``p_from`` as an area density
    at ``p_to`` (normal ``n_to``; 0 for a point, which takes no cosine). Where
    ``direction_only`` (an infinite light's vertex) the density stays per solid angle."""
    w = p_to - p_from
    d2 = dr.squared_norm(w)
    cos = dr.select(dr.squared_norm(n_to) > 0, dr.abs(dr.dot(n_to, w)) * dr.rsqrt(d2), 1.0)
    out = dr.select(d2 > 0, pdf * cos / d2, 0.0)
    return out if direction_only is None else dr.select(direction_only, pdf, out)


def reverse_pdf(bsdfs, bsdf_id, ctx, wi_local, wo_local, active):
    """Density of the BSDF at ``ctx`` sampling ``wo_local`` when the path arrives from
    ``wi_local`` (both local): the vertex's density for the opposite walking direction."""
    si = mi.SurfaceInteraction3f(ctx.si)
    si.wi = wi_local
    return bsdfs.eval_pdf(bsdf_id, ShadingContext(si, ctx.wl), wo_local, active)[1]


def delta_flag() -> mi.Bool:
    """The delta flag of a subpath's first vertex (False) as loop state: opaque, since
    Dr.Jit drops a state variable that starts and ends the body as the same literal (the
    samples' flag in a scene without delta lobes) and then traces the body again."""
    return dr.opaque(mi.Bool, False)


def light_kinds(lights) -> mi.UInt32:
    """Per light (expanded index): DELTA_POSITION / DELTA_DIRECTION / INFINITE_LIGHT bits."""
    fam = []
    for t in lights.order:
        f = lights.families[t]
        k = INFINITE_LIGHT if f.infinite else 0
        if f.delta:
            k |= DELTA_DIRECTION if isinstance(f, (DirectionalLight, DirectionalAreaLight)) else DELTA_POSITION
        fam.append(k)
    return dr.gather(mi.UInt32, mi.UInt32(fam), lights.family_of)


def infinite_density(lights, sampler, wi, active):
    """pbrt-v4's ``InfiniteLightDensity``: the density (solid angle, light pick of
    ``sample_Le`` with ``sampler`` included) of direction ``wi`` toward the infinite
    lights, summed."""
    pdf = mi.Float(0.0)
    for g in lights.infinite_ids:
        t, i = lights.entries[g]
        light = mi.UInt32(int(lights.first_light[g]))
        pdf += lights.families[t].pdf_Le_dir(mi.UInt32(i), wi, active) * lights.pmf_Le(sampler, light, active)
    return pdf


@INTEGRATORS.register("bdpt")
class BDPTIntegrator(LightTracingIntegrator):
    """``bdpt``: bidirectional path tracing with MIS over all strategies (pbrt-v4's
    ``BDPTIntegrator``); lights picked by power. No participating media, no derivatives.

    ===================  ====  =======  ========================================================
    name                 type  default  meaning
    ===================  ====  =======  ========================================================
    maxdepth             int   5        pbrt-v4's bounces (0: emitters seen directly)
    max_depth            int   -        Mitsuba's depth instead (= maxdepth + 1; finite)
    regularize           bool  false    pbrt-v4's BSDF regularisation (only false)
    visualizestrategies  bool  false    render_strategies() returns unweighted strategy images
    visualizeweights     bool  false    render_strategies() returns MIS-weighted strategy images
    ===================  ====  =======  ========================================================
    """

    name = "bdpt"
    bytes_per_lane = 576          # the light and camera subpaths (pbr.memory)
    traces_light_paths = True
    light_sampler_type = "power"

    def __init__(self, props):
        super().__init__(props)
        if props.has("maxdepth") and props.has("max_depth"):
            raise props.error("max_depth", "give either 'maxdepth' (pbrt-v4) or 'max_depth' (Mitsuba), not both")
        if props.has("max_depth"):
            md = props.int("max_depth", min=-1)
            if md < 0:
                raise props.error("max_depth", "bdpt needs a finite max_depth (its strategies are "
                                                "enumerated up to it); e.g. 6 = pbrt-v4's default maxdepth 5")
            self.max_depth = md
        else:
            self.max_depth = props.int("maxdepth", 5, min=0) + 1
        self.maxdepth = self.max_depth - 1          # pbrt-v4's: bounces
        if props.bool("regularize", False):
            raise props.error("regularize", "BSDF regularisation is not supported (only false)")
        self.visualize_strategies = props.bool("visualizestrategies", False)
        self.visualize_weights = props.bool("visualizeweights", False)
        props.finish()
        self._strategies = None    # Strategies of render_strategies (None: all, weighted)

    # -- rendering ---------------------------------------------------------------------
    def _plan(self, scene, sensor, spp):
        cam, w, h, spp, per_pass, _ = super()._plan(scene, sensor, spp)
        per_pass = min(per_pass, max(1, MAX_SAMPLES_PER_PASS // (w * h)))
        while spp % per_pass:
            per_pass -= 1
        return cam, w, h, spp, per_pass, spp // per_pass

    def render_strategies(self, scene, sensor=0, seed=0, spp=0, weighted=None):
        """pbrt-v4's ``visualizeweights`` / ``visualizestrategies``: {(s, t): image} with
        the contribution of each strategy alone, MIS-weighted (their sum is the image) or
        not (each then estimates all light of depth s + t - 2 on its own). ``weighted``
        defaults to the scene's choice (``visualizestrategies`` -> unweighted)."""
        if weighted is None:
            weighted = not self.visualize_strategies
        out = {}
        try:
            for depth in range(self.maxdepth + 1):
                for t in range(1, depth + 3):
                    s = depth + 2 - t
                    if (s, t) == (1, 1):
                        continue
                    # Opaque: one kernel serves every strategy. Full-length subpaths:
                    # every image then comes from the same paths as the BDPT image.
                    self._strategies = Strategies(self.maxdepth, dr.opaque(mi.UInt32, s),
                                                  dr.opaque(mi.UInt32, t), weighted, truncate=False)
                    out[(s, t)] = self.render(scene, sensor, seed, spp, progress=False)
        finally:
            self._strategies = None
        return out

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        if self.max_depth == 0:
            return mi.Spectrum(0.0), mi.Bool(False)
        strategies = self._strategies or Strategies(self.maxdepth)
        store, n_light = self.light_subpaths(scene, self.camera, rng, wl, strategies, self.splats.splat)
        dr.eval(self.splats.buf)
        return self.camera_subpaths(scene, self.camera, rng, ray, wl, active, store, n_light, strategies)

    def light_subpaths(self, scene, camera, rng, wl, strategies, splat):
        """Trace the light subpaths of ``dr.width(wl)`` samples (random numbers from
        ``rng.next_float32()``), evaluating the strategies t = 1 among ``strategies``:
        ``splat(pos, L, wl, active)`` receives their contributions at film positions.
        Returns the stored vertices and their count per sample, evaluated with ``rng``."""
        n = dr.width(wl.lambda_)
        store = dr.zeros(LightVertex, n * (self.maxdepth + 1))
        n_light = dr.zeros(mi.UInt32, n)
        if self.maxdepth >= 1 and len(scene.lights):
            self._light_subpaths(scene, camera, rng, wl, store, n_light, strategies, splat)
            dr.eval(store, n_light, rng)
        return store, n_light

    # -- light subpaths (and the t = 1 strategies) ------------------------------------
    @dr.syntax
    def _light_subpaths(self, scene, camera, rng, wl, store, n_light, strategies, splat):
        geo, bsdfs, lights = scene.geometry, scene.bsdfs, scene.lights
        n = dr.width(n_light)
        lane = dr.arange(mi.UInt32, n)
        les, ray, beta = start_light_path(scene, self.emission_sampler, rng, wl, mi.Bool(True))
        # s = 1 takes a fresh light sample (next-event estimation): subpaths start at s = 2.
        ok = (les.pdf_dir > 0) & (strategies.light_max >= 2)
        inf0 = les.infinite | les.delta_dir
        n0 = dr.select(inf0 | les.delta_pos, mi.Normal3f(0.0), les.n)
        fwd0 = dr.select(inf0, infinite_density(lights, self.emission_sampler, -les.d, ok), les.pmf * les.pdf_pos)
        E0 = dr.select(les.delta_pos | les.delta_dir, 0.0, 1.0)
        flags0 = dr.select(inf0, mi.UInt32(INFINITE), mi.UInt32(0))
        dr.scatter(store, LightVertex(les.o, les.d, les.o, n0, les.L, fwd0, E0, flags0), lane, ok)
        n_light[ok] = 1

        # The previous vertex y_{k-1}.
        prev_p = mi.Point3f(les.o)
        prev_n = mi.Normal3f(n0)
        prev_fwd = mi.Float(fwd0)
        prev_E = mi.Float(E0)
        prev_delta = delta_flag()
        pdf_dir = mi.Float(les.pdf_dir)       # solid-angle density of the ray leaving y_{k-1}
        pdf_pos0 = mi.Float(les.pdf_pos)
        beta = mi.Spectrum(beta)
        k = mi.UInt32(1)
        active = mi.Bool(ok)
        # The loop state holds only what a vertex changes (see path's loop): the ray's
        # time and wavelengths, the stream's constants, the wavelengths, the lane index,
        # y_0's densities and the store (scattered to) stay outside it, and the dispersion
        # flag is state only with dispersion. Python ifs are plain ifs (mode="scalar"),
        # so that the excluded variables they read stay outside.
        dispersive = bsdfs.dispersive
        term = mi.Bool(False) if dispersive else None
        ray_var, ray_fixed = ray_state(ray, extent=False)   # spawned rays: the largest extent
        rng_state = rng.loop_state()
        while dr.hint(active, label="bdpt_light", exclude=[ray, ray_fixed, rng, wl, lane, pdf_pos0, inf0, store]):
            ray = loop_ray(ray_var, ray_fixed)
            rng.set_loop_state(rng_state)
            prev_inf = inf0 & (k == 1)      # y_{k-1} is y_0 of an infinite light
            si, shape = geo.intersect(ray, active)
            hit = active & si.is_valid()
            cos_k = dr.abs(dr.dot(si.n, ray.d))
            # Forward density of y_k; after an infinite light, its disk's density (pbrt-v4).
            fwd = dr.select(prev_inf, pdf_pos0 * cos_k, to_area(pdf_dir, prev_p, si.p, si.n))
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
            ctx = ShadingContext(si, wl)
            conn = hit & bsdfs.smooth(bsdf_id, hit) & strategies.wants(k + 1, 1)

            # t = 1: connect y_k to the camera (strategy s = k + 1, depth k): the pinhole, or
            # a point of the lens (its 2D sample drawn here: LENS_DIMS).
            cs = camera.sample_Wi(si.p, lens_sample(camera, rng))
            Lc, pos, vis = connect_to_camera(scene, camera, si, bsdf_id, wl, beta, conn, cs)
            wi_cam = si.to_local(cs.wi)
            pdf_cam = camera.pdf_We(mi.Ray3f(cs.p, -cs.wi))[1]
            rev_k = to_area(pdf_cam, cs.p, si.p, si.n)
            rev_km1 = to_area(reverse_pdf(bsdfs, bsdf_id, ctx, wi_cam, si.wi, vis), si.p, prev_p, prev_n, prev_inf)
            w = mis_weight(0.0, side_sum(rev_k, fwd, rev_km1, prev_fwd, prev_delta, prev_E))
            Lc = Lc * strategies.weight(k + 1, 1, w)
            if dr.hint(dispersive, mode="scalar"):
                Lc[term] = first_only(Lc)
            splat(pos, Lc, wl, vis)

            # Continue: sample the adjoint BSDF, then y_{k-1}'s reverse density is known.
            u1 = rng.next_float32()
            u2 = rng.next_2d()
            go = hit & (k + 1 < strategies.light_max)
            bs = sample_importance(bsdfs, bsdf_id, ctx, u1, u2, go)
            wo = si.to_world(bs.wo)
            corr, side_ok = shading_correction(si, -ray.d, wo)
            rev_km1 = to_area(reverse_pdf(bsdfs, bsdf_id, ctx, bs.wo, si.wi, go & ~bs.delta),
                              si.p, prev_p, prev_n, prev_inf)
            rev_km1 = dr.select(bs.delta, 0.0, rev_km1)
            E = advance_sum(prev_E, rev_km1, prev_fwd, bs.delta, prev_delta)
            flags = dr.select(bs.delta & go, mi.UInt32(DELTA), 0)
            if dr.hint(dispersive, mode="scalar"):
                flags |= dr.select(term, mi.UInt32(TERMINATED), 0)
            dr.scatter(store, LightVertex(ray.o, ray.d, si.p, si.n, beta, fwd, E, flags), k * n + lane, hit)
            n_light[hit] = k + 1

            beta *= bs.weight * corr
            if dr.hint(dispersive, mode="scalar"):
                term |= go & bs.terminate
            prev_p = mi.Point3f(si.p)
            prev_n = mi.Normal3f(si.n)
            prev_fwd = mi.Float(fwd)
            prev_E = mi.Float(E)
            prev_delta = mi.Bool(bs.delta)
            pdf_dir = dr.select(bs.delta, 0.0, bs.pdf)
            ray_var = ray_state(si.spawn_ray(wo), extent=False)[0]
            k += 1
            active = go & (bs.pdf > 0) & side_ok & nonzero(beta)
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)

    # -- camera subpaths (s = 0, s = 1 and s, t >= 2) ------------------------------------
    @dr.syntax
    def camera_subpaths(self, scene, cam, rng, ray, wl, active, store, n_light, strategies):
        """Trace the camera subpaths from ``ray`` (random numbers from ``rng``) and evaluate
        the strategies t >= 2 among ``strategies``, joining them to the stored light
        vertices (:meth:`light_subpaths`): (radiance, valid mask)."""
        geo, bsdfs, lights = scene.geometry, scene.bsdfs, scene.lights
        kinds = light_kinds(lights) if len(lights) else None
        n = dr.width(n_light)
        lane = dr.arange(mi.UInt32, n)
        md = self.maxdepth
        has_lights = len(lights) > 0
        area_lights = "area" in lights.families

        prev_p = cam.lens_point(ray)      # z_0: the pinhole or the ray's point on the lens
        prev_n = mi.Normal3f(0.0)
        prev_fwd = mi.Float(1.0)
        prev_E = mi.Float(0.0)
        prev_delta = delta_flag()
        pdf_dir = mi.Float(cam.pdf_We(ray)[1])
        L = mi.Spectrum(0.0)
        beta = mi.Spectrum(1.0)
        valid = mi.Bool(False)
        k = mi.UInt32(1)                  # z_k is found now; its strategies have t = k + 1
        active = mi.Bool(active) & (pdf_dir > 0) & (strategies.camera_max >= 2)
        # Loop state: only what a vertex changes (as in the light subpaths' loop); the
        # light kinds, lane index and light subpath lengths are read from outside.
        dispersive = bsdfs.dispersive
        term = mi.Bool(False) if dispersive else None
        ray_var, ray_fixed = ray_state(ray)
        rng_state = rng.loop_state()
        while dr.hint(active, label="bdpt_camera", exclude=[ray, ray_fixed, rng, wl, kinds, lane, n_light]):
            ray = loop_ray(ray_var, ray_fixed)
            rng.set_loop_state(rng_state)
            si, shape = geo.intersect(ray, active)
            hit = active & si.is_valid()
            valid |= hit
            fwd = to_area(pdf_dir, prev_p, si.p, si.n)
            Lk = mi.Spectrum(0.0)

            # s = 0: the camera subpath found an emitter.
            if dr.hint(has_lights, mode="scalar"):
                light = lights.light_of_hit(scene, shape, si, hit)
                on_light = hit & (light > 0) & strategies.wants(0, k + 1)
                Le = lights.L(light - 1, si, wl, on_light)
                pdf_pos, pdf_e = lights.pdf_Le(light - 1, si.p, si.sh_frame.n, -ray.d, on_light)
                rev_k = lights.pmf_Le(self.emission_sampler, light - 1, on_light) * pdf_pos
                rev_km1 = to_area(pdf_e, si.p, prev_p, prev_n)
                w = dr.select(k == 1, 1.0, mis_weight(side_sum(rev_k, fwd, rev_km1, prev_fwd, prev_delta, prev_E), 0.0))
                Lk += dr.select(on_light, beta * Le * strategies.weight(0, k + 1, w), 0.0)
                if dr.hint(lights.has_infinite, mode="scalar"):
                    escaped = active & ~si.is_valid() & strategies.wants(0, k + 1)
                    Le_inf = mi.Spectrum(0.0)
                    for Le_i, _ in lights.Le_escaped(ray.d, wl, prev_p, prev_n, escaped):
                        Le_inf += Le_i
                    rev_k = infinite_density(lights, self.emission_sampler, ray.d, escaped)
                    # The escaped vertex's forward density stays per solid angle (pbrt-v4).
                    rev_km1 = self._planar_density(lights, escaped) * dr.select(
                        dr.squared_norm(prev_n) > 0, dr.abs(dr.dot(prev_n, ray.d)), 1.0)
                    w = dr.select(k == 1, 1.0,
                                  mis_weight(side_sum(rev_k, pdf_dir, rev_km1, prev_fwd, prev_delta, prev_E), 0.0))
                    Lk += dr.select(escaped, beta * Le_inf * strategies.weight(0, k + 1, w), 0.0)

            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
            ctx = ShadingContext(si, wl)
            conn = hit & bsdfs.smooth(bsdf_id, hit)

            # s = 1: next-event estimation (depth k).
            u_light = rng.next_float32()
            u_pos = rng.next_2d()
            u1 = rng.next_float32()
            u2 = rng.next_2d()
            go = hit & (k + 1 < strategies.camera_max)
            nee = conn & (k <= md) & strategies.wants(1, k + 1)
            wo_l = mi.Vector3f(0, 0, 1)
            if dr.hint(has_lights, mode="scalar"):   # a Python branch: both share variables
                lt, pmf = self.light_sampler.sample(u_light, si.p, si.n, nee)
                lt = mi.UInt32(lt)
                ls = lights.sample_Li_light(lt, si, u_pos, wl, nee)
                em = nee & (ls.pdf > 0) & (pmf > 0)
                kind = dr.gather(mi.UInt32, kinds, lt, em)
                inf_l = (kind & (INFINITE_LIGHT | DELTA_DIRECTION)) != 0
                delta_l = (kind & (DELTA_POSITION | DELTA_DIRECTION)) != 0
                dist = dr.norm(ls.p - si.p)
                wo_l = si.to_local(ls.wi)
            # One BSDF call gives the value toward the light and the continuation.
            f_l, pdf_l, bs = bsdfs.eval_pdf_sample(bsdf_id, ctx, wo_l, u1, u2, go | nee)
            bs = dr.detach(bs)
            if dr.hint(has_lights, mode="scalar"):
                # A ray to the light only where the estimate is not zero (light_reaches).
                em = nonzero_estimate(f_l * ls.L, em)
                if dr.hint(area_lights, mode="scalar"):
                    # Trace to the light point: the hit gives the light's normals there.
                    sray = si.spawn_ray_to(ls.p)
                    sray.maxt = dist * 1.001
                    si_l, _ = geo.intersect(sray, em)
                    em &= ~si_l.is_valid() | (si_l.t >= dist * 0.999)
                    ng_l = dr.select(si_l.is_valid(), si_l.n, 0.0)
                    ns_l = dr.select(si_l.is_valid(), si_l.sh_frame.n, 0.0)
                else:
                    em &= geo.unoccluded(si, ls.p, em)
                    ng_l = mi.Normal3f(0.0)
                    ns_l = mi.Normal3f(0.0)
                ng_l = dr.select(inf_l | ((kind & DELTA_POSITION) != 0), 0.0, ng_l)
                pdf_pos, pdf_e = lights.pdf_Le(lt, ls.p, ns_l, -ls.wi, em)
                fwd_l = dr.select(inf_l, infinite_density(lights, self.emission_sampler, ls.wi, em & inf_l),
                                  lights.pmf_Le(self.emission_sampler, lt, em) * pdf_pos)
                rev_l = to_area(pdf_l, si.p, ls.p, ng_l, inf_l)
                cos_k = dr.abs(dr.dot(si.n, ls.wi))
                rev_k = dr.select(inf_l, pdf_pos * cos_k, pdf_e * cos_k / dr.square(dist))
                rev_km1 = to_area(reverse_pdf(bsdfs, bsdf_id, ctx, wo_l, si.wi, em), si.p, prev_p, prev_n)
                sum_l = side_sum(rev_l, fwd_l, 0.0, 1.0, delta_l, 0.0)   # y_0 alone: s = 1
                w = mis_weight(side_sum(rev_k, fwd, rev_km1, prev_fwd, prev_delta, prev_E), sum_l)
                Lk += dr.select(em, beta * f_l * ls.L * (strategies.weight(1, k + 1, w) / (ls.pdf * pmf)), 0.0)

            if dr.hint(dispersive, mode="scalar"):
                Lk[term] = first_only(Lk)
            L += Lk

            # s >= 2, t = k + 1: connect z_k to the stored light vertices y_{s-1}.
            s, s_max = strategies.connections(k, dr.minimum(n_light, md + 1 - dr.minimum(k, md + 1)))
            inner = conn & (s <= s_max)
            # Its state: the strategy, the mask and the radiance; the camera vertex and
            # everything else it reads stay outside.
            while dr.hint(inner, label="bdpt_connect",
                          exclude=[store, lane, si, ctx, bsdf_id, fwd, beta, term, k, s_max, prev_p, prev_n,
                                   prev_fwd, prev_delta, prev_E, wl]):
                q = dr.gather(LightVertex, store, (s - 1) * n + lane, inner)
                qm = dr.gather(LightVertex, store, (s - 2) * n + lane, inner)
                si_q, shape_q = geo.intersect(mi.Ray3f(q.o, q.d), inner)
                bsdf_q = dr.gather(mi.UInt32, scene.shape_bsdf, shape_q, inner)
                ok = inner & si_q.is_valid() & bsdfs.smooth(bsdf_q, inner)
                dv = q.p - si.p
                d2 = dr.squared_norm(dv)
                dn = dv * dr.rsqrt(d2)
                ok &= d2 > 0
                ctx_q = ShadingContext(si_q, wl)
                wo_t = si.to_local(dn)
                wo_q = si_q.to_local(-dn)
                f_t, pdf_t = bsdfs.eval_pdf(bsdf_id, ctx, wo_t, ok)
                f_q, pdf_q = eval_importance(bsdfs, bsdf_q, ctx_q, wo_q, ok)
                corr, side_ok = shading_correction(si_q, -q.d, -dn)
                ok &= side_ok
                # The shadow ray only where both ends scatter along it (light_reaches).
                ok = nonzero_estimate(f_t * f_q, ok)
                ok &= geo.unoccluded(si, q.p, ok)
                pdf_t_rev = reverse_pdf(bsdfs, bsdf_id, ctx, wo_t, si.wi, ok)
                pdf_q_rev = reverse_pdf(bsdfs, bsdf_q, ctx_q, wo_q, si_q.wi, ok)
                q_inf = (q.flags & INFINITE) != 0
                qm_inf = (qm.flags & INFINITE) != 0
                sum_c = side_sum(to_area(pdf_q, q.p, si.p, si.n), fwd,
                                 to_area(pdf_t_rev, si.p, prev_p, prev_n), prev_fwd, prev_delta, prev_E)
                sum_q = side_sum(to_area(pdf_t, si.p, q.p, q.n, q_inf), q.fwd,
                                 to_area(pdf_q_rev, q.p, qm.p, qm.n, qm_inf), qm.fwd,
                                 (qm.flags & DELTA) != 0, qm.E)
                w = mis_weight(sum_c, sum_q)
                Lc = q.beta * f_q * f_t * beta * (corr * strategies.weight(s, k + 1, w) / d2)
                if dr.hint(dispersive, mode="scalar"):
                    Lc[term | ((q.flags & TERMINATED) != 0)] = first_only(Lc)
                L += dr.select(ok, Lc, 0.0)
                s += 1
                inner &= s <= s_max


            # Continue the camera subpath with the BSDF sample drawn above.
            rev_km1 = to_area(reverse_pdf(bsdfs, bsdf_id, ctx, bs.wo, si.wi, go & ~bs.delta), si.p, prev_p, prev_n)
            rev_km1 = dr.select(bs.delta, 0.0, rev_km1)
            prev_E = advance_sum(prev_E, rev_km1, prev_fwd, bs.delta, prev_delta)
            beta *= bs.weight
            if dr.hint(dispersive, mode="scalar"):
                term |= go & bs.terminate
            prev_p = mi.Point3f(si.p)
            prev_n = mi.Normal3f(si.n)
            prev_fwd = mi.Float(fwd)
            prev_delta = mi.Bool(bs.delta)
            pdf_dir = dr.select(bs.delta, 0.0, bs.pdf)
            ray_var = ray_state(si.spawn_ray(si.to_world(bs.wo)))[0]
            k += 1
            active = go & (bs.pdf > 0) & nonzero(beta)
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)

        return L, valid

    @staticmethod
    def _planar_density(lights, active):
        """pbrt-v4's density of an infinite light's ray origins: 1 / (pi r^2) over the disk
        of the scene's bounding sphere (as ``sample_Le`` samples it)."""
        g = lights.infinite_ids[0]
        first = mi.UInt32(int(lights.first_light[g]))
        return lights.pdf_Le(first, mi.Point3f(0.0), mi.Normal3f(0.0), mi.Vector3f(0, 0, 1), active)[0]
