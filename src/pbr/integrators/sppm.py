"""``sppm``: stochastic progressive photon mapping (pbrt-v4's ``SPPMIntegrator``): per
iteration a camera pass to visible points, a hash grid of them, a photon pass and the
progressive radius update. The steps, units and depth conventions: docs/integrators.md.
"""

from __future__ import annotations

import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import memory
from .. import spectrum as spec
from ..bsdfs import DIFFUSE, NO_BACK, ShadingContext
from ..lights.lightsamplers import LIGHT_SAMPLERS
from ..samplers import IndependentSampler
from ..sampling import power_heuristic
from ..spectrum import SampledWavelengths, first_only
from .base import INTEGRATORS, SamplingIntegrator, _progress, emitted_mis, light_reaches, mis_state, nonzero, path_state
from .lightpath import sample_importance, shading_correction, start_light_path

UNLIMITED = 0xFFFFFFF0
# The camera pass samples independently (see _visible_points).
_INDEPENDENT = IndependentSampler()


class VisiblePoints:
    """One iteration's visible points, one per pixel (structure of arrays)."""

    def __init__(self, si, p, bsdf, beta, depth, valid, terminated):
        self.si = si                    # mi.SurfaceInteraction3f at the point (wi: toward the camera)
        self.p = p                      # its position (mi.Point3f)
        self.bsdf = bsdf                # BSDF entry (mi.UInt32)
        self.beta = beta                # camera path throughput times the filter weight
        self.depth = depth              # camera vertex index v (1: seen directly)
        self.valid = valid
        self.terminated = terminated    # secondary wavelengths terminated (dispersion)


class PixelState:
    """What SPPM keeps per pixel across iterations."""

    def __init__(self, n_pixels: int, radius: float):
        self.Ld = dr.zeros(mi.Array3f, n_pixels)     # sum_k w_k Ld_k (XYZ)
        self.w = dr.zeros(mi.Float, n_pixels)        # sum_k w_k
        self.tau = dr.zeros(mi.Array3f, n_pixels)    # photon flux (XYZ), rescaled with r^2
        self.N = dr.zeros(mi.Float, n_pixels)        # accumulated photon count
        self.r = dr.full(mi.Float, radius, n_pixels)
        # Opaque from the start: the first iteration then uses the same kernels as the rest.
        dr.make_opaque(self.Ld, self.w, self.tau, self.N, self.r)


class HashGrid:
    """Visible points by cell: the entries of bucket ``b`` are ``start[b] .. start[b] +
    count[b]``; each holds a visible point and its cell's full 32-bit hash (to skip
    other cells of the same bucket, so a point is never counted twice)."""

    def __init__(self, inv_cell, start, count, entry_vp, entry_hash, mask):
        self.inv_cell, self.start, self.count = inv_cell, start, count
        self.entry_vp, self.entry_hash, self.mask = entry_vp, entry_hash, mask


def cell_hash(c: mi.Vector3i) -> mi.UInt32:
    """32-bit hash of an integer cell (Teschner et al.'s primes, then murmur3's finaliser)."""
    h = (mi.UInt32(c.x) * 73856093) ^ (mi.UInt32(c.y) * 19349663) ^ (mi.UInt32(c.z) * 83492791)
    h ^= h >> 16
    h *= 0x85EBCA6B
    h ^= h >> 13
    h *= 0xC2B2AE35
    h ^= h >> 16
    return h


def mix32(a: int, b: int) -> int:
    """A 32-bit hash of two integers (splitmix64's finaliser): per-iteration seeds."""
    z = (a * 0x9E3779B97F4A7C15 + b * 0xBF58476D1CE4E5B9 + 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return (z ^ (z >> 31)) & 0xFFFFFFFF


def radical_inverse_2(i: int) -> float:
    """Van der Corput sequence in base 2."""
    return int(f"{i:032b}"[::-1], 2) / 2.0 ** 32


@INTEGRATORS.register("sppm")
class SPPMIntegrator(SamplingIntegrator):
    """``sppm``: stochastic progressive photon mapping (pbrt-v4's ``SPPMIntegrator``). One
    iteration per camera sample; lights of photons picked by power. No participating media.

    ===================  ======  =======  =========================================================
    name                 type    default  meaning
    ===================  ======  =======  =========================================================
    max_depth            int     6        Mitsuba's depth (-1 unlimited; 2 direct light only)
    maxdepth             int     5        pbrt-v4's bounces instead (= max_depth - 1)
    iterations           int     0        iterations (0: the sensor's sample_count)
    photonsperiteration  int     -1       photons per iteration (-1: one per pixel)
    radius               float   0        initial search radius (0: two scene diameters over the
                                          larger image side)
    seed                 int     0        added to the render seed
    hide_emitters        bool    false    camera rays pass through emitting surfaces and do not see
                                          the environment
    light_sampler        string  bvh      light choice of next-event estimation: 'uniform', 'power'
                                          or 'bvh' (pbrt-v4's light BVH)
    ===================  ======  =======  =========================================================
    """

    pass_separable = False    # pixel statistics carry over between iterations

    name = "sppm"
    bytes_per_lane = 416          # visible points and pixel statistics, photons (pbr.memory)
    supports_films = False        # develops its own channels (RGB films only)
    traces_light_paths = True
    GAMMA = 2.0 / 3.0      # fraction of new photons kept per iteration (Hachisuka & Jensen)

    def __init__(self, props):
        super().__init__(props)
        if props.has("max_depth") and props.has("maxdepth"):
            raise props.error("maxdepth", "give either 'maxdepth' (pbrt-v4) or 'max_depth' (Mitsuba), not both")
        if props.has("maxdepth"):
            self.max_depth = props.int("maxdepth", 5, min=0) + 1    # pbrt-v4 bounces -> Mitsuba
        else:
            self.max_depth = props.int("max_depth", 6, min=-1)      # Mitsuba's meaning
        self.iterations = props.int("iterations", 0, min=0)     # 0: the sensor's sample_count
        self.photons = props.int("photonsperiteration", -1, min=-1)
        if self.photons == 0:
            raise props.error("photonsperiteration", "must be -1 (one per pixel) or positive")
        self.radius = props.float("radius", 0.0, min=0.0)     # 0: automatic (see initial_radius)
        self.seed = props.int("seed", 0)
        self.hide_emitters = props.bool("hide_emitters", False)
        self.light_sampler_type = props.string("light_sampler", "bvh", choices=LIGHT_SAMPLERS)
        props.finish()
        self.history: list[dict] = []
        self.checkpoints: dict[int, mi.TensorXf] = {}

    # -- parameters ---------------------------------------------------------------------
    @property
    def max_bounces(self) -> int:
        """pbrt-v4's ``maxdepth``: bounces a path may have (UNLIMITED for -1)."""
        return UNLIMITED if self.max_depth < 0 else max(self.max_depth - 1, 0)

    def initial_radius(self, scene, w: int, h: int) -> float:
        """The ``radius`` parameter, or (0) two scene diameters over the image size: about
        the scene-space width of a few pixels, so that a visible point collects a similar
        number of photons per iteration (photons per iteration = pixels) at any resolution."""
        if self.radius > 0:
            return self.radius
        return 2.0 * (2.0 * scene.lights.scene_radius) / max(w, h)

    # -- rendering ------------------------------------------------------------------------
    def render(self, scene, sensor=0, seed=0, spp=0, progress=None, checkpoints=()):
        """Image after ``spp`` iterations (0: the ``iterations`` parameter, else the
        sensor's sample count). Images after the iteration counts in ``checkpoints`` are
        kept in :attr:`checkpoints`; :attr:`history` lists per iteration the photons
        emitted so far, the radius statistics, the mean photon count N and the time
        elapsed."""
        self.prepare(scene, sensor)
        cam = scene.sensors[sensor]
        w, h = cam.film.size
        n_pix = w * h
        iters = int(spp) if spp else (self.iterations or cam.sampler.sample_count)
        n_photons = n_pix if self.photons < 0 else self.photons
        memory.check_render(w, h, 1, 4, f"sensor {sensor}", self.bytes_per_lane, max(n_pix, n_photons))
        seed = (int(seed) + 0x9E3779B9 * self.seed) & 0xFFFFFFFF
        r0 = self.initial_radius(scene, w, h)
        state = PixelState(n_pix, r0)
        self.history, self.checkpoints = [], {}
        self._tables(scene)
        keep = {int(k) for k in checkpoints}
        bar = _progress(iters, progress)
        if bar:
            bar.set_description("pbr sppm")
            bar.unit = "iter"
        img = None
        t0 = time.perf_counter()
        for it in range(iters):
            wl = self._wavelengths(it, seed)
            vp, Ld, wgt = self._visible_points(scene, cam, w, h, it, seed, wl)
            state.Ld += Ld
            state.w += wgt
            phi, m = self._photon_flux(scene, vp, state, wl, it, n_photons, seed, n_pix)
            self._update(state, vp, phi, m, wl)
            dr.eval(state.Ld, state.w, state.tau, state.N, state.r)
            r = np.array(state.r)
            self.history.append({"iteration": it + 1, "photons": (it + 1) * n_photons,
                                 "radius_mean": float(r.mean()), "radius_min": float(r.min()),
                                 "radius_max": float(r.max()), "N_mean": float(np.mean(state.N)),
                                 "seconds": time.perf_counter() - t0})
            if it + 1 in keep or it + 1 == iters:
                img = self._develop(state, n_photons, w, h)
                if it + 1 in keep:
                    self.checkpoints[it + 1] = img
            if bar:
                bar.update(1)
        if bar:
            bar.close()
        if img is None:
            img = mi.TensorXf(np.zeros((h, w, 3), np.float32))
        return img

    def sample(self, *a, **k):
        raise NotImplementedError("sppm renders by iterations (render()), not by camera samples")

    def density(self, tau, n_photons: int, r):
        """Radiance from accumulated flux: ``tau / (Np pi r^2)`` (per iteration; the film
        divides by the summed filter weights)."""
        return tau * dr.rcp(n_photons * dr.pi * r * r)

    def _develop(self, state, n_photons, w, h):
        xyz = state.Ld + self.density(state.tau, n_photons, state.r)
        xyz = np.stack([np.array(xyz[c], dtype=np.float64) for c in range(3)], axis=1)
        ws = np.maximum(np.array(state.w, dtype=np.float64), 1e-30)
        rgb = spec.xyz_to_srgb(xyz / ws[:, None])
        return mi.TensorXf(rgb.astype(np.float32).reshape(h, w, 3))

    def _wavelengths(self, it: int, seed: int) -> SampledWavelengths:
        """The iteration's wavelengths, shared by every pixel and photon: a radical-inverse
        sequence rotated by the seed (an opaque kernel input: no recompilation)."""
        u = (radical_inverse_2(it) + ((seed * 2654435761) & 0xFFFFFFFF) / 2.0 ** 32) % 1.0
        return SampledWavelengths.sample_visible(dr.opaque(mi.Float, u))

    def _tables(self, scene):
        """Which BSDF entries may hold a visible point: those with a diffuse lobe (a
        blend's from either component), without an opacity mask."""
        bsdfs = scene.bsdfs
        d = [bool(fl & DIFFUSE) and e[3] == NO_BACK for fl, e in zip(bsdfs.entry_flags(), bsdfs.entries)]
        self._all_diffuse = all(d)
        self._diffuse_of = mi.Bool(d)

    def _has_diffuse(self, bsdfs, bsdf_id, si, active):
        if self._all_diffuse:
            return mi.Bool(active)
        d = dr.gather(mi.Bool, self._diffuse_of, bsdf_id, active)
        if bsdfs.twosided:
            back = dr.gather(mi.UInt32, bsdfs.back_of, bsdf_id, active)
            flip = active & (back != NO_BACK) & (si.wi.z < 0)
            d = dr.select(flip, dr.gather(mi.Bool, self._diffuse_of, back, flip), d)
        return active & d

    # -- 1. camera pass -------------------------------------------------------------------
    def _visible_points(self, scene, cam, w, h, it, seed, wl):
        """(visible points, per-pixel w Ld (XYZ), filter weights w) of iteration ``it``
        (one camera sample per pixel; the iteration only changes the opaque seed, so one
        kernel serves every iteration count)."""
        # One independent sample per pixel and iteration (whatever the camera's sampler: the
        # iterations' points must not repeat, and a 1-sample pattern stratifies nothing).
        rng, _, ray, weight, inside = self._camera_samples(cam, w, h, 1, 1, 0, mix32(seed, it), sampler=_INDEPENDENT)
        L, vp_ray, beta, depth, found, term = self._camera_path(scene, rng, ray, wl, inside)
        si, shape = scene.geometry.intersect(vp_ray, found)
        found &= si.is_valid()
        bsdf = dr.gather(mi.UInt32, scene.shape_bsdf, shape, found)
        Ld, = self.counter().replace([spec.to_xyz(L, wl) * weight], inside)
        vp = VisiblePoints(si, mi.Point3f(si.p), bsdf, dr.select(found, beta * weight, 0.0), depth, found, term)
        dr.eval(vp.si, vp.p, vp.bsdf, vp.beta, vp.depth, vp.valid, vp.terminated, Ld, weight)
        return vp, Ld, weight

    @dr.syntax
    def _camera_path(self, scene, rng, ray, wl, active):
        """Follow a camera path to its visible point. Returns (emitted + direct radiance,
        the ray that reaches the visible point, the throughput there, its vertex index v,
        found mask, wavelength-termination mask)."""
        geo, lights, bsdfs = scene.geometry, scene.lights, scene.bsdfs
        bounces = self.max_bounces
        ray, active, L, beta, depth, valid = path_state(ray, active)
        prev_p, prev_n, prev_pdf, prev_delta = mis_state(ray)
        active &= self.max_depth != 0
        eta_scale = mi.Float(1.0)
        found = mi.Bool(False)
        vp_o = mi.Point3f(0.0)
        vp_d = mi.Vector3f(0.0, 0.0, 1.0)
        vp_t = mi.Float(0.0)
        vp_beta = mi.Spectrum(0.0)
        vp_depth = mi.UInt32(0)
        vp_term = mi.Bool(False)
        terminated = mi.Bool(False)
        dispersive = bsdfs.dispersive

        while dr.hint(active, label="sppm_camera"):
            si, shape = geo.intersect(ray, active)
            hit = active & si.is_valid()

            # Emission reached by BSDF sampling or seen directly, MIS-weighted (as in path).
            light = lights.light_of_hit(scene, shape, si, hit)
            on_light = hit & (light > 0)
            skip = on_light & (depth == 0) if self.hide_emitters else mi.Bool(False)
            on_light &= ~skip
            escaped = active & ~si.is_valid()
            if self.hide_emitters:
                escaped &= depth > 0
            Le = beta * emitted_mis(scene, self.light_sampler, light, si, ray.d, wl, on_light, escaped,
                                    prev_p, prev_n, prev_pdf, prev_delta)

            # Vertex v = depth + 1: direct light needs v <= bounces; after the visible
            # point only the emission found by its BSDF sample is still added.
            active_next = hit & ~skip & ~found & (depth + 1 <= bounces)
            ctx = ShadingContext(si, wl)
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, active_next)

            u_light = rng.next_float32()
            u_pos = mi.Point2f(rng.next_float32(), rng.next_float32())
            smooth = active_next & bsdfs.smooth(bsdf_id, active_next)
            ls = lights.sample_Li(self.light_sampler, si, u_light, u_pos, wl, smooth)
            em = smooth & (ls.pdf > 0)
            wo_em = si.to_local(ls.wi)
            u1 = rng.next_float32()
            u2 = mi.Point2f(rng.next_float32(), rng.next_float32())
            f_em, pdf_em, bs = bsdfs.eval_pdf_sample(bsdf_id, ctx, wo_em, u1, u2, active_next)
            w_em = dr.select(ls.delta, 1.0, power_heuristic(ls.pdf, pdf_em))
            Ld = beta * f_em * ls.L * (w_em / ls.pdf)
            Ld = dr.select(light_reaches(geo, si, ls.p, Ld, em), Ld, 0.0)
            L = L + Le + Ld

            # The visible point: the first vertex with a diffuse lobe.
            here = self._has_diffuse(bsdfs, bsdf_id, si, active_next)
            vp_o[here] = ray.o
            vp_d[here] = ray.d
            vp_t[here] = ray.maxt
            vp_beta[here] = beta
            vp_depth[here] = depth + 1
            vp_term[here] = terminated
            found |= here

            cont = active_next & (bs.pdf > 0)
            if dispersive:
                term = hit & bs.terminate & ~terminated
                L[term] = first_only(L)
                beta[term] = first_only(beta)
                terminated |= term
            beta[~skip] = beta * bs.weight
            eta_scale[cont & ~skip] = eta_scale * dr.square(bs.eta)
            prev_p = mi.Point3f(si.p)
            prev_n = mi.Normal3f(si.n)
            prev_pdf = mi.Float(bs.pdf)
            prev_delta = skip | bs.delta
            ray = dr.select(skip, si.spawn_ray(ray.d), si.spawn_ray(si.to_world(bs.wo)))
            depth[hit & ~skip] = depth + 1

            # pbrt-v4's camera-path roulette: on throughput (times eta^2) below 1.
            rr_beta = dr.max(beta) * eta_scale
            q = dr.maximum(0.05, 1.0 - rr_beta)
            rr = (rr_beta < 1.0) & ~skip
            survive = rng.next_float32() >= q
            beta[rr] = beta * dr.rcp(1.0 - q)
            active = skip | (cont & (~rr | survive) & nonzero(beta))

        vp_ray = mi.Ray3f(vp_o, vp_d, vp_t, 0.0, mi.Spectrum(0.0))
        return L, vp_ray, vp_beta, vp_depth, found, vp_term

    # -- 2. hash grid -------------------------------------------------------------------------
    def _build_grid(self, vp, r, n_pix) -> HashGrid:
        """Counting sort of (visible point, overlapped cell) pairs into a hash table."""
        size = 1 << max(4, int(math.ceil(math.log2(2 * n_pix))))
        r_max = dr.max(dr.select(vp.valid, r, 0.0))
        inv_cell = dr.rcp(dr.maximum(2.0 * r_max, 1e-30))
        dr.eval(inv_cell)
        lane = dr.arange(mi.UInt32, 8 * n_pix)
        v = lane >> 3
        corner = lane & 7
        ok = dr.gather(mi.Bool, vp.valid, v)
        p = dr.gather(mi.Point3f, vp.p, v, ok)
        rv = dr.gather(mi.Float, r, v, ok)
        lo = mi.Vector3i(dr.floor((p - rv) * inv_cell))
        hi = mi.Vector3i(dr.floor((p + rv) * inv_cell))
        c = lo + mi.Vector3i(mi.Int32(corner & 1), mi.Int32((corner >> 1) & 1), mi.Int32(corner >> 2))
        ok &= (c.x <= hi.x) & (c.y <= hi.y) & (c.z <= hi.z)
        hsh = cell_hash(c)
        key = hsh & (size - 1)
        count = dr.zeros(mi.UInt32, size)
        slot = dr.scatter_inc(count, key, ok)
        dr.eval(slot, count)
        start = dr.prefix_sum(count)
        pos = dr.gather(mi.UInt32, start, key, ok) + slot
        entry_vp = dr.zeros(mi.UInt32, 8 * n_pix)
        entry_hash = dr.zeros(mi.UInt32, 8 * n_pix)
        dr.scatter(entry_vp, v, pos, ok)
        dr.scatter(entry_hash, hsh, pos, ok)
        dr.eval(start, entry_vp, entry_hash)
        return HashGrid(inv_cell, start, count, entry_vp, entry_hash, size - 1)

    # -- 3. photon pass ------------------------------------------------------------------------
    def _photon_flux(self, scene, vp, state, wl, it, n_photons, seed, n_pix):
        """(per-pixel spectral flux sum_photons beta f, photon count M) of one iteration."""
        phi = dr.zeros(mi.Float64, 4 * n_pix)     # float64: run-to-run equal sums (see SplatFilm)
        m = dr.zeros(mi.Float, n_pix)
        if not scene.lights.entries or self.max_bounces < 2:
            return phi, m
        grid = self._build_grid(vp, state.r, n_pix)
        r2 = dr.square(state.r)
        dr.eval(r2)
        idx = dr.arange(mi.UInt32, n_photons) + dr.opaque(mi.UInt32, (it * n_photons) & 0xFFFFFFFF)
        rng = IndependentSampler.make_rng(idx, dr.opaque(mi.UInt32, (seed * 0x2C1B3C6D + 0x297A2D39) & 0xFFFFFFFF))
        self._trace_photons(scene, grid, vp, r2, phi, m, rng, wl)
        dr.eval(phi, m)
        return phi, m

    @dr.syntax
    def _trace_photons(self, scene, grid, vp, r2, phi, m, rng, wl):
        """Trace one photon per lane; deposits are scatter-added into ``phi`` and ``m``."""
        geo, bsdfs = scene.geometry, scene.bsdfs
        bounces = self.max_bounces
        les, ray, beta = start_light_path(scene, self.emission_sampler, rng, wl, mi.Bool(True))
        depth = mi.UInt32(0)               # photon hit index k (0: first hit, direct light)
        terminated = mi.Bool(False)
        dispersive = bsdfs.dispersive
        active = (les.pdf_dir > 0) & nonzero(beta)

        while dr.hint(active, label="sppm_photon"):
            si, shape = geo.intersect(ray, active)
            hit = active & si.is_valid()
            self._deposit(grid, vp, r2, phi, m, bsdfs, si.p, -ray.d, beta, depth, wl, terminated,
                          hit & (depth > 0))

            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
            ctx = ShadingContext(si, wl)
            u1 = rng.next_float32()
            u2 = mi.Point2f(rng.next_float32(), rng.next_float32())
            bs = sample_importance(bsdfs, bsdf_id, ctx, u1, u2, hit)
            wo = si.to_world(bs.wo)
            corr, side_ok = shading_correction(si, -ray.d, wo)
            b_new = beta * bs.weight * corr
            if dispersive:
                term = hit & bs.terminate & ~terminated
                b_new[term] = first_only(b_new)
                terminated |= term
            # pbrt-v4's photon roulette: survive with the throughput ratio (capped at 1).
            q = dr.maximum(0.0, 1.0 - dr.max(b_new) * dr.rcp(dr.max(beta)))
            survive = rng.next_float32() >= q
            beta = b_new * dr.rcp(1.0 - q)
            ray = si.spawn_ray(wo)
            depth += 1
            # Deposits at hit k need v + k <= bounces with v >= 1.
            active = hit & side_ok & (bs.pdf > 0) & survive & (depth + 1 <= bounces) & nonzero(beta)

    @dr.syntax
    def _deposit(self, grid, vp, r2, phi, m, bsdfs, p, wi, beta, k, wl, terminated, active):
        """Add a photon at ``p`` (arriving from world direction ``wi``, throughput ``beta``,
        hit index ``k``) to the visible points of its cell within their radius."""
        cell = mi.Vector3i(dr.floor(p * grid.inv_cell))
        hsh = cell_hash(cell)
        key = hsh & grid.mask
        i = dr.gather(mi.UInt32, grid.start, key, active)
        end = i + dr.gather(mi.UInt32, grid.count, key, active)
        i = dr.select(active, i, 0)
        end = dr.select(active, end, 0)
        dispersive = bsdfs.dispersive
        while dr.hint(i < end, label="sppm_lookup"):
            on = i < end
            same = on & (dr.gather(mi.UInt32, grid.entry_hash, i, on) == hsh)
            v = dr.gather(mi.UInt32, grid.entry_vp, i, same)
            d2 = dr.squared_norm(dr.gather(mi.Point3f, vp.p, v, same) - p)
            near = same & (d2 <= dr.gather(mi.Float, r2, v, same))
            near &= self._within_depth(dr.gather(mi.UInt32, vp.depth, v, near), k)
            si = dr.gather(mi.SurfaceInteraction3f, vp.si, v, near)
            bsdf_id = dr.gather(mi.UInt32, vp.bsdf, v, near)
            wo = si.to_local(wi)
            f_cos, _ = bsdfs.eval_pdf(bsdf_id, ShadingContext(si, wl), wo, near)
            cos = dr.abs(wo.z)
            f = dr.select(cos > 0, f_cos * dr.rcp(cos), 0.0)
            flux = beta * f
            if dispersive:
                # Both sides keep only the first wavelength: its factor N counts once.
                both = near & terminated & dr.gather(mi.Bool, vp.terminated, v, near)
                flux[both] = flux * (1.0 / spec.N_WAVELENGTHS)
            for c in range(4):
                dr.scatter_reduce(dr.ReduceOp.Add, phi, mi.Float64(flux[c]), v * 4 + c, near)
            dr.scatter_reduce(dr.ReduceOp.Add, m, 1.0, v, near)
            i += 1

    def _within_depth(self, v, k):
        """A photon's k-th hit at a visible point of camera vertex v completes a path of
        v + k bounces: it counts up to ``max_bounces`` (as ``path`` with the same depth)."""
        return v + k <= self.max_bounces

    # -- 4. progressive update -----------------------------------------------------------------
    def _update(self, state, vp, phi, m, wl):
        """Hachisuka & Jensen's update with gamma = ``GAMMA``: keep a fraction gamma of the
        new photons, shrink the radius to hold the density, rescale the flux."""
        flux = mi.Spectrum(*[mi.Float(dr.gather(mi.Float64, phi, dr.arange(mi.UInt32, dr.width(m)) * 4 + c))
                             for c in range(4)])
        has = m > 0
        xyz, = self.counter().replace([spec.to_xyz(vp.beta * flux, wl)], has)
        n_new = state.N + self.GAMMA * m
        r_new = state.r * dr.sqrt(n_new * dr.rcp(state.N + m))
        state.tau = dr.select(has, (state.tau + xyz) * dr.square(r_new * dr.rcp(state.r)), state.tau)
        state.N = dr.select(has, n_new, state.N)
        state.r = dr.select(has, r_new, state.r)
