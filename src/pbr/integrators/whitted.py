"""``whitted``: recursive ray tracing after Whitted (pbrt-v3's ``WhittedIntegrator``),
vectorised as a wavefront over depth levels (the rays of specular branches are
compacted into the next level). Lobes, branching and depth: docs/integrators.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from ..samplers import IndependentSampler
from ..samplers.independent import IndependentStream
from ..spectrum import N_WAVELENGTHS, SampledWavelengths, first_only
from .base import INTEGRATORS, SamplingIntegrator, light_reaches
from .direct import add_unweighted_emission, intersect_camera_ray


@INTEGRATORS.register("whitted")
class WhittedIntegrator(SamplingIntegrator):
    """``whitted``: recursive ray tracing (pbrt-v3's ``WhittedIntegrator``): emission,
    direct light from every light, and both branches of every specular surface. Surfaces
    only.

    =============  ====  =======  ==============================================================
    name           type  default  meaning
    =============  ====  =======  ==============================================================
    max_depth      int   5        path segments counting the camera ray; finite (each dielectric
                                  hit doubles the rays)
    hide_emitters  bool  false    camera rays pass through emitting surfaces and do not see
                                  the environment
    =============  ====  =======  ==============================================================
    """

    name = "whitted"
    surfaces_only = True
    light_sampler_type = "uniform"   # unused: every light is sampled
    # Lobe-selection numbers of the branches: the first lobe and the last one.
    branch_u = (0.0, 1.0 - 2.0 ** -24)

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", 5)
        if self.max_depth < 0:
            raise props.error("max_depth", f"must be >= 0 (whitted branches at every specular hit, so the "
                                           f"depth must be finite), got {self.max_depth}")
        self.hide_emitters = props.bool("hide_emitters", False)
        props.finish()

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        n = dr.width(active)
        if self.max_depth == 0:
            return mi.Spectrum(0.0), dr.zeros(mi.Bool, n)
        acc = dr.zeros(mi.Float, N_WAVELENGTHS * n)
        key = rng.next_uint32()
        dr.eval(key, wl)
        slot = dr.arange(mi.UInt32, n)
        code = dr.zeros(mi.UInt32, n)
        beta = dr.full(mi.Spectrum, 1.0, n)
        single = dr.zeros(mi.Bool, n)   # only the first wavelength goes on (dispersion)
        ray = mi.Ray3f(ray)
        valid = None
        for depth in range(self.max_depth):
            if depth > 0:
                rng = IndependentStream(rng=IndependentSampler.make_rng(code, dr.gather(mi.UInt32, key, slot)))
                wl_k = SampledWavelengths(dr.gather(mi.Spectrum, wl.lambda_, slot),
                                          dr.gather(mi.Spectrum, wl.pdf, slot))
            else:
                wl_k = wl
            L, hit, branches = self._shade(scene, rng, ray, wl_k, beta, single, depth, active)
            for c in range(N_WAVELENGTHS):
                dr.scatter_reduce(dr.ReduceOp.Add, acc, L[c], slot * N_WAVELENGTHS + c, active)
            if depth == 0:
                valid = hit
            if branches is None:
                break
            dr.eval(acc, valid, branches)
            ray, beta, single, slot, code, active = self._compact(branches, slot, code)
            if active is None:
                break
        idx = dr.arange(mi.UInt32, n) * N_WAVELENGTHS
        L = mi.Spectrum(*[dr.gather(mi.Float, acc, idx + c) for c in range(N_WAVELENGTHS)])
        return L, valid

    @staticmethod
    def _compact(branches, slot, code):
        """The next level's rays: the followed branches of this level's rays, packed.
        Returns (ray, beta, single, slot, code, active), active = None when no ray is left."""
        nb, m = len(branches), dr.width(branches[0][2])

        def pick(tp, i, which, parent):
            v = dr.gather(tp, branches[0][i], parent)
            for b in range(1, nb):
                v = dr.select(which == b, dr.gather(tp, branches[b][i], parent), v)
            return v
        j = dr.arange(mi.UInt32, nb * m)
        idx = dr.compress(pick(mi.Bool, 2, j // m, j % m))
        k = dr.width(idx)
        if k == 0:
            return (None,) * 6
        which, parent = idx // m, idx % m
        ray = mi.Ray3f(pick(mi.Point3f, 0, which, parent), pick(mi.Vector3f, 1, which, parent))
        # Ray-tree codes: the children of node c are nb c + 1 + b (0: the camera ray).
        child_code = dr.gather(mi.UInt32, code, parent) * nb + 1 + which
        return (ray, pick(mi.Spectrum, 3, which, parent), pick(mi.Bool, 4, which, parent),
                dr.gather(mi.UInt32, slot, parent), child_code, dr.full(mi.Bool, True, k))

    @dr.syntax
    def _shade(self, scene, rng, ray, wl, beta, single, depth: int, active):
        """One level: (radiance toward the rays times their throughput, hit mask, the two
        specular branches as (origin, direction, followed, throughput, single-wavelength
        flag), or None at the last level)."""
        geo, lights, bsdfs = scene.geometry, scene.lights, scene.bsdfs
        hidden = self.hide_emitters and depth == 0
        si, shape = intersect_camera_ray(scene, ray, active, hidden)
        hit = active & si.is_valid()
        L = mi.Spectrum(0.0)
        if not hidden:
            L, _ = add_unweighted_emission(L, scene, si, shape, ray, wl, active, hit, 0, 1.0, False)
        branches = None
        if depth + 2 <= self.max_depth:
            ctx = ShadingContext(si, wl)
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)

            # Direct light: one sample of every light.
            smooth = hit & bsdfs.smooth(bsdf_id, hit)
            k = dr.zeros(mi.UInt32, dr.width(smooth))
            # Only what an iteration changes is loop state (see path's loop).
            rng_state = rng.loop_state()
            while dr.hint(smooth & (k < lights.n_lights), label="whitted_lights",
                          exclude=[rng, wl, si, ctx, bsdf_id, smooth]):
                rng.set_loop_state(rng_state)
                u = mi.Point2f(rng.next_float32(), rng.next_float32())
                ls = lights.sample_Li_light(k, si, u, wl, smooth)
                em = smooth & (ls.pdf > 0)
                f = bsdfs.eval_pdf(bsdf_id, ctx, si.to_local(ls.wi), em)[0]
                Ld = f * ls.L / ls.pdf
                L += dr.select(light_reaches(geo, si, ls.p, Ld, em), Ld, 0.0)
                k += 1
                rng_state = rng.loop_state()
            rng.set_loop_state(rng_state)

            # The specular branches, each weighted by its lobe's Fresnel factor.
            u2 = mi.Point2f(rng.next_float32(), rng.next_float32())
            branches = []
            for u1 in self.branch_u:
                bs = bsdfs.sample(bsdf_id, ctx, mi.Float(u1), u2, hit)
                follow = hit & bs.delta & (bs.pdf > 0) & dr.any(bs.weight != 0)
                if len(branches) > 0:
                    follow &= ~(branches[0][2] & dr.all(bs.wo == branches[0][5]))
                w = beta * bs.weight * bs.pdf
                single_b = mi.Bool(single)
                if bsdfs.dispersive:
                    term = bs.terminate & ~single
                    w = dr.select(term, first_only(w), w)
                    single_b |= term
                r = si.spawn_ray(si.to_world(bs.wo))
                branches.append((r.o, r.d, follow, w, single_b, bs.wo))
            branches = [b[:5] for b in branches]
        return beta * L, hit, branches
