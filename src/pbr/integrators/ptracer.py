"""``ptracer`` (Mitsuba's particle tracer; pbrt-v4's ``lightpath``): light tracing, every
surface vertex of a light path connected to the camera (a pinhole or a thin lens) and splatted
(:class:`pbr.integrators.lightpath.SplatFilm`). Conventions: docs/integrators.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..bsdfs.base import ShadingContext
from ..samplers import IndependentSampler, IndependentStream, seed_array
from ..spectrum import SampledWavelengths, first_only
from ..plugins.props import SceneError
from .base import INTEGRATORS, SamplingIntegrator, _progress, loop_ray, nonzero, ray_state
from .lightpath import (SplatFilm, connect_to_camera, lens_sample, sample_importance, shading_correction,
                        start_light_path)


@INTEGRATORS.register("ptracer", "lightpath")
class ParticleTracerIntegrator(SamplingIntegrator):
    """``ptracer`` / ``lightpath`` (Mitsuba's particle tracer, pbrt-v4's light path
    integrator): ``W H spp`` light paths, every surface vertex connected to the camera
    and splatted on the film. No participating media.

    ================  ====  =======  ===============================================================
    name              type  default  meaning
    ================  ====  =======  ===============================================================
    max_depth         int   -1       Mitsuba's meaning (a light path of k segments before its camera
                                     connection counts k + 1; -1 unlimited)
    rr_depth          int   5        depth from which Russian roulette may end a path
    hide_emitters     bool  false    emitters seen directly are left out (they still block light)
    samples_per_pass  int   -1       camera samples per pixel and pass (-1: automatic); divides spp
    ================  ====  =======  ===============================================================
    """

    pass_separable = False    # the splat film (float64 sums) spans passes

    needs_camera_importance = True  # connects paths to the camera (sample_Wi / its own camera rays)
    name = "ptracer"
    supports_films = False        # splats RGB (RGB films only)
    supports_sensor_films = True  # with a camera sensor (pbrt-v4's rgb film: iso, maxcomponentvalue)
    bytes_per_lane = 48           # the light path and its camera connection (pbr.memory)
    traces_light_paths = True

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.int("max_depth", -1, min=-1)
        self.rr_depth = props.int("rr_depth", 5, min=0)
        self.hide_emitters = props.bool("hide_emitters", False)
        self.samples_per_pass = props.int("samples_per_pass", -1, min=-1)
        if self.samples_per_pass == 0:
            raise props.error("samples_per_pass", "must be positive (or -1: automatic)")
        props.finish()

    def _plan(self, scene, sensor, spp):
        cam, w, h, spp, per_pass, n_pass = super()._plan(scene, sensor, spp)
        if self.samples_per_pass > 0:
            if spp % self.samples_per_pass:
                raise SceneError(f"ptracer: sample_count ({spp}) must be a multiple of samples_per_pass "
                                 f"({self.samples_per_pass})")
            per_pass = min(spp, self.samples_per_pass)
            n_pass = spp // per_pass
        return cam, w, h, spp, per_pass, n_pass

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        """``W H spp`` samples, pass by pass; each splats the emitter its camera ray sees
        and the camera connections of one light path. Image: the splats over ``spp``."""
        self.prepare(scene, sensor)
        cam, w, h, spp, per_pass, n_pass = self._plan(scene, sensor, spp)
        self.camera, self.splats = cam, SplatFilm(cam, self.counter())
        bar = _progress(n_pass, progress)
        try:
            for p in range(n_pass):
                with dr.suspend_grad():
                    self._pass(scene, cam, w, h, spp, per_pass, p, seed)
                    dr.eval(self.splats.buf)
                if bar:
                    bar.update(1)
            img = self.splats.develop(1.0 / spp)
        finally:
            if bar:
                bar.close()
            self.splats = None
        return mi.TensorXf(img.astype(np.float32))

    def _pass(self, scene, cam, w, h, spp, per_pass, pass_index, seed):
        n = w * h * per_pass
        idx = dr.arange(mi.UInt32, n)
        pixel = idx // per_pass
        sample_index = pixel * spp + dr.opaque(mi.UInt32, pass_index) * per_pass + (idx - pixel * per_pass)
        rng = IndependentStream(rng=IndependentSampler.make_rng(sample_index, seed_array(seed)))
        wl = SampledWavelengths.sample_visible(rng.next_float32())
        active = mi.Bool(True)
        if self.max_depth == 0:
            return
        if not self.hide_emitters:
            # A uniform film position in this sample's pixel, splatted like the light paths
            # (so both estimate the same filtered image: Mitsuba's normalised splats).
            pos = mi.Point2f((mi.Float(pixel % w) + rng.next_float32()) / w,
                             (mi.Float(pixel // w) + rng.next_float32()) / h)
            L = self._visible_emitters(scene, cam.sample_ray(pos, lens_sample(cam, rng)), wl, active)
            self.splats.splat(pos, L, wl, active)
        if self.max_depth < 0 or self.max_depth > 1:
            self._trace(scene, rng, wl, active)

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        raise NotImplementedError("ptracer renders light paths (render), not camera samples")


    def _visible_emitters(self, scene, ray, wl, active):
        """Radiance of the emitter (area or infinite) the camera ray sees, if any."""
        lights = scene.lights
        si, shape = scene.geometry.intersect(ray, active)
        hit = active & si.is_valid()
        light = lights.light_of_hit(scene, shape, si, hit)
        on_light = hit & (light > 0)
        L = dr.select(on_light, lights.L(light - 1, si, wl, on_light), 0.0)
        if lights.has_infinite:
            escaped = active & ~si.is_valid()
            for Le, _ in lights.Le_escaped(ray.d, wl, ray.o, mi.Normal3f(0.0), escaped):
                L += dr.select(escaped, Le, 0.0)
        return L

    @dr.syntax
    def _trace(self, scene, rng, wl, active):
        """One light path; splats its camera connections into ``self.splats``."""
        geo, bsdfs = scene.geometry, scene.bsdfs
        camera, splats = self.camera, self.splats
        max_depth = self.max_depth if self.max_depth >= 0 else 0x7FFFFFFF
        dispersive = bsdfs.dispersive

        ls, ray, beta = start_light_path(scene, self.emission_sampler, rng, wl, active)
        depth = mi.UInt32(1)            # segments so far (Mitsuba's count)
        # Loop state: only what a bounce changes (see path): the relative IOR and the
        # dispersion flag only where they can change; the ray's time and wavelengths,
        # the stream's constants and the wavelengths outside. Ifs on Python values are
        # plain ifs, so that the excluded variables they read stay outside.
        eta = mi.Float(1.0) if bsdfs.refracts else None
        terminated = mi.Bool(False) if dispersive else None
        active = mi.Bool(active) & (ls.pdf_dir > 0) & nonzero(beta) & (depth < max_depth)
        ray_var, ray_fixed = ray_state(ray, extent=False)   # spawned rays: the largest extent
        rng_state = rng.loop_state()

        while dr.hint(active, label="ptracer", exclude=[ray, ray_fixed, rng, wl]):
            ray = loop_ray(ray_var, ray_fixed)
            rng.set_loop_state(rng_state)
            si, shape = geo.intersect(ray, active)
            active &= si.is_valid()
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, active)

            # Connect this vertex to the camera and splat.
            cs = camera.sample_Wi(si.p, lens_sample(camera, rng))
            contrib, pos, ok = connect_to_camera(scene, camera, si, bsdf_id, wl, beta, active, cs)
            splats.splat(pos, contrib, wl, ok)

            # Scatter (importance transport) to the next vertex.
            ctx = ShadingContext(si, wl)
            bs = sample_importance(bsdfs, bsdf_id, ctx, rng.next_float32(),
                                   mi.Point2f(rng.next_float32(), rng.next_float32()), active)
            wo = si.to_world(bs.wo)
            corr, side_ok = shading_correction(si, -ray.d, wo)
            beta *= bs.weight * corr
            if dr.hint(eta is not None, mode="scalar"):
                eta *= bs.eta
            if dr.hint(dispersive, mode="scalar"):
                # Wavelength-dependent refraction: the first wavelength stands for all.
                term = active & bs.terminate & ~terminated
                beta[term] = first_only(beta)
                terminated |= term
            active &= side_ok & (bs.pdf > 0) & nonzero(beta)
            depth += 1
            active &= depth < max_depth

            # Russian roulette (Mitsuba's ptracer: beyond rr_depth segments).
            q = dr.minimum(dr.max(beta) * eta * eta if eta is not None else dr.max(beta), 0.95)
            rr = depth > self.rr_depth
            survive = rng.next_float32() < q
            beta[rr] = beta * dr.rcp(q)
            active &= ~rr | survive
            ray = si.spawn_ray(wo)
            ray_var = ray_state(ray, extent=False)[0]
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)
