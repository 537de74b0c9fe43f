"""Sampling integrators: camera samples -> radiance -> developed image.

One render *pass* is one megakernel over ``width * height * spp_pass`` camera samples laid
out pixel-major, so a pixel's samples are summed by a local scatter-add inside the kernel.
Passes bound memory; their number follows from :func:`max_samples_per_pass`. A pass's
samples depend only on the seed and their sample indices, so passes can be rendered
anywhere and merged: :class:`PassJob` (``pbr.distributed``) renders some of a render's
passes, or develops an image from passes rendered elsewhere, bit for bit as one render.

Differentiation follows Path Replay Backpropagation: ``sample`` is written once with a
``mode``; the primal pass accumulates radiance, the adjoint passes replay the same
paths (same random numbers) and propagate the adjoint radiance to scene parameters.

Samples whose value is not finite (NaN or inf) are replaced by 0, so that an image stays
finite, and counted (:class:`NonFinite`, inside the rendering kernels); ``pbr.render``
reports the count (``on_nonfinite``).
"""

from __future__ import annotations

import contextlib
import os
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import backend, dispatch, memory
from .. import spectrum as spec
from ..samplers import seed_array
from ..sampling import power_heuristic
from ..lights import LIGHT_TYPES
from ..plugins.props import SceneError
from ..plugins.registry import Registry
from ..spectrum import SampledWavelengths
from .surface import surface_channels

PRIMAL, FORWARD, BACKWARD = "primal", "forward", "backward"
NONFINITE_POLICIES = ("warn", "raise", "ignore")
# Type name -> integrator class (each integrator registers itself in its module).
INTEGRATORS = Registry("integrator")
# Camera samples per pass, by backend. Each pass is traced anew in Python (tens of ms for
# a scene with many BSDF families), which on a GPU can cost more than the kernel: on an
# H100 the materials gallery at 1024 x 768 x 64 spp took 16 passes of 2^22 and 4.8x
# Mitsuba's time. A symbolic-loop pass keeps its per-sample state in registers, so its
# memory is the film's, and the GPU takes 2^26 samples a pass.
SAMPLES_PER_PASS = {"llvm": 1 << 22, "cuda": 1 << 26}


def max_samples_per_pass() -> int:
    """Camera samples per render pass: ``PBR_MAX_SAMPLES_PER_PASS`` if set (a positive
    integer, e.g. smaller on a GPU with little memory), else the backend's default."""
    env = os.environ.get("PBR_MAX_SAMPLES_PER_PASS")
    if env is None:
        return SAMPLES_PER_PASS[backend.get_backend()]
    try:
        n = int(env)
    except ValueError:
        n = 0
    if n <= 0:
        raise ValueError(f"PBR_MAX_SAMPLES_PER_PASS={env!r}: expected a positive integer (samples per pass)")
    return n


class PassJob:
    """Part of a render, for ``pbr.distributed`` (set with ``SamplingIntegrator.pass_job``).

    ``spp_per_pass``: samples per pixel in each pass (a divisor of the render's spp;
    None: the integrator's own plan). ``run``: the passes (indices) to render; their
    per-pixel film sums (numpy float32, see ``_pixel_sums``) are stored in ``sums`` by
    pass index. ``given``: per-pass sums rendered elsewhere, used instead of rendering
    those passes. The film adds the passes it renders or is given in pass order (float32,
    as a whole render does), so developing the sums of every pass gives the image of one
    render bit for bit; the image of a job that lacks passes is not a render's."""

    def __init__(self, spp_per_pass: int | None = None, run=(), given=None):
        self.spp_per_pass = spp_per_pass
        self.run = set(run)
        self.given = {} if given is None else given     # a mapping (it may fetch on demand)
        self.sums = {}

    def wants(self, p: int) -> bool:
        return p in self.run or p in self.given


class NonFinite:
    """The number of sample values that were not finite (NaN or inf) and were replaced
    by 0: a one-entry counter that :meth:`replace` increments inside the kernel that
    makes the values (one local reduction and one atomic add per SIMD packet or GPU warp,
    no kernel of its own); :meth:`report` reads it after the render."""

    def __init__(self, policy: str = "warn"):
        if policy not in NONFINITE_POLICIES:
            raise ValueError(f"on_nonfinite must be one of {', '.join(map(repr, NONFINITE_POLICIES))}, "
                             f"got {policy!r}")
        self.policy = policy
        self.count = dr.zeros(mi.UInt32, 1)

    def replace(self, values, active=True):
        """``values`` (Dr.Jit arrays of one sample each per lane) with every value of a
        lane set to 0 where any of them is not finite; such lanes are counted."""
        ok = mi.Bool(True)
        for v in values:
            ok &= dr.all(dr.isfinite(v)) if dr.depth_v(v) > 1 else dr.isfinite(v)
        dr.scatter_reduce(dr.ReduceOp.Add, self.count, mi.UInt32(1), mi.UInt32(0), active & ~ok,
                          mode=dr.ReduceMode.Local)
        return [dr.select(ok, v, 0.0) for v in values]

    def report(self, what: str = "pbr.render") -> int:
        """Read the count (not inside ``dr.freeze``, which cannot read values; nor with
        the policy 'ignore') and warn ('warn') or raise ``FloatingPointError`` ('raise')
        if it is not 0. Returns the count (0 when not read)."""
        policy = self.policy
        if policy == "ignore" or dr.flag(dr.JitFlag.FreezingScope):
            return 0
        n = int(self.count[0])
        if n:
            msg = (f"{what}: {n} sample{'s were' if n > 1 else ' was'} NaN or infinite and counted as 0 "
                   f"(the image is too dark where they fell): a scene value that overflows, or a numerical "
                   f"failure; on_nonfinite='raise' stops here, 'ignore' silences this")
            if policy == "raise":
                raise FloatingPointError(msg)
            warnings.warn(msg, RuntimeWarning, stacklevel=3)
        return n


class SamplingIntegrator:
    """Base of every integrator: camera samples in passes, the film, and the adjoint
    passes of differentiable integrators (``differentiable = True``)."""

    name = ""
    path = "scene.integrator"     # the integrator's key path (for error messages)
    light_sampler_type = "power"  # the 'light_sampler' parameter: the light sampler of NEE
    light_sampler = None          # that sampler over the scene being rendered (see prepare)
    emission_sampler = None       # light paths' light sampler (traces_light_paths; see prepare)
    differentiable = False        # whether render_forward/render_backward are implemented
    surfaces_only = False         # whether participating media are an error
    traces_light_paths = False    # whether every emitter must emit rays (sample_Le), without media
    needs_camera_importance = False  # whether paths connect to the camera (sample_Wi: static perspective/thinlens)
    bytes_per_lane = 0            # per-path state kept in memory between kernels (pbr.memory)
    supports_films = True         # whether non-RGB films (sensor matrix, extra channels) develop right
    supports_sensor_films = False  # without supports_films: whether a camera sensor (RGB only) is fine
    supports_moving_shapes = True  # whether shapes may move (motion blur; light paths never do)
    moving_shapes = False         # whether the scene being rendered has moving shapes (see prepare)
    # Records a function's kernels once and replays them (dr.freeze for pbr scenes): set
    # by pbr.freeze, a layer above the integrators; None where pbr.freeze is not loaded.
    recorder = None
    _ray_weight = None            # the last camera samples' ray weights (None: 1)
    # The count of non-finite samples of the current render (pbr.render sets a fresh one).
    nonfinite = None
    # Whether render() is the film of independent camera-sample passes (_film), so that
    # a PassJob can split it; light tracers, sppm and mlt render otherwise.
    pass_separable = True
    # The PassJob of the current render (pass_job), None for a whole render.
    job = None
    # The adaptive plan of the current render (pbr.adaptive), None for uniform spp.
    adaptive = None
    # The current pass's camera rays attached to the camera pose (None: not differentiated).
    primary_ray_ad = None

    def __init__(self, props):
        self.path = props.path

    def prepare(self, scene, sensor: int = 0) -> None:
        """Per-render set-up, run by ``render``, ``render_forward`` and ``render_backward``
        (and by ``Scene.build`` for the scene's own integrator, so that a render inside
        ``dr.freeze`` builds nothing): check the scene (it may be rendered with an
        integrator other than its own) and take this integrator's light samplers for the
        scene's current lights (cached per scene build by ``LightSet.sampler``)."""
        self.check(scene)
        cam = scene.sensors[sensor] if 0 <= sensor < len(scene.sensors) else None
        if self.needs_camera_importance and cam is not None and not getattr(cam, "connectable", False):
            name = type(cam).name
            what = repr(name) if name not in ("perspective", "thinlens") else f"a moving {name!r} camera"
            raise SceneError(f"{self.path}: the {self.name!r} integrator connects paths to the camera, which needs "
                             f"a static 'perspective' or 'thinlens' camera (sensor {sensor} is {what})")
        film = getattr(cam, "film", None)
        if film is not None and not self.supports_films and not (
                film.splattable if self.supports_sensor_films else film.plain):
            what = "RGB images" if self.supports_sensor_films else "plain RGB images"
            has = "extra channels" if self.supports_sensor_films else "a sensor response or extra channels"
            rgb = "an" if self.supports_sensor_films else "a default"
            raise SceneError(f"{self.path}: the {self.name!r} integrator develops {what} only; sensor "
                             f"{sensor}'s film ({film.name!r}) has {has} (use 'hdrfilm' or {rgb} 'rgb' film)")
        if getattr(cam, "weights_rays", False) and not self.supports_films:
            raise SceneError(f"{self.path}: the {self.name!r} integrator does not support the "
                             f"{type(cam).name!r} camera (its rays carry lens weights)")
        # Moving shapes: every camera ray gets a time in the shutter, as for a moving camera.
        self.moving_shapes = scene.geometry.moving
        self.light_sampler = scene.lights.sampler(self.light_sampler_type)
        if self.traces_light_paths:
            self.emission_sampler = scene.lights.sampler("power")

    def check(self, scene) -> None:
        """Raise a SceneError naming this integrator's key path where ``scene`` holds
        something it cannot render (called when a scene is loaded with it)."""
        if scene.geometry.moving and (self.traces_light_paths or self.needs_camera_importance
                                      or not self.supports_moving_shapes):
            raise SceneError(f"{self.path}: the {self.name!r} integrator does not support moving shapes or "
                             f"instances ('to_world_end': motion blur); use 'path' or 'volpath'")
        if self.surfaces_only and len(scene.media):
            raise SceneError(f"{self.path}: the {self.name!r} integrator does not support participating media "
                             f"(use 'volpath')")
        if self.traces_light_paths:
            lights = scene.lights
            for path, (t, _) in zip(lights.paths, lights.entries):
                if not lights.families[t].emits_rays:
                    emitting = sorted(n for n, f in LIGHT_TYPES.items() if f.emits_rays)
                    raise SceneError(f"{path}: the {self.name} integrator ({self.path}) cannot trace light paths "
                                     f"from a {t!r} emitter (supported: {', '.join(emitting)})")
            if len(scene.media):
                raise SceneError(f"{self.path}: the {self.name} integrator does not support participating media")

    def pass_job(self, job: PassJob):
        """Within the block, ``render`` does ``job`` (a part of the render; see PassJob)."""
        return self.passes_planned_by("job", job, "its passes cannot be rendered apart")

    @contextlib.contextmanager
    def passes_planned_by(self, attr: str, plan, refusal: str):
        """Within the block, attribute ``attr`` holds ``plan`` (a PassJob or an adaptive
        plan), which decides ``render``'s passes; integrators whose passes are not
        independent camera samples refuse, saying ``refusal``."""
        if not self.pass_separable:
            raise NotImplementedError(f"{self.path}: the {self.name!r} integrator does not render independent "
                                      f"camera-sample passes, so {refusal}")
        setattr(self, attr, plan)
        try:
            yield plan
        finally:
            setattr(self, attr, None)

    def counter(self) -> NonFinite:
        """The non-finite sample counter of the current render (made on first use)."""
        if not isinstance(self.nonfinite, NonFinite):
            self.nonfinite = NonFinite()
        return self.nonfinite

    # -- subclasses -----------------------------------------------------------------
    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        """(radiance L (primal) / its derivative (forward), valid mask)."""
        raise NotImplementedError

    # -- camera samples ---------------------------------------------------------------
    def _plan(self, scene, sensor, spp):
        cam = scene.sensors[sensor]
        w, h = cam.film.size
        spp = cam.sampler.round_spp(int(spp), warn=True) if spp else cam.sampler.sample_count
        if self.job is not None and self.job.spp_per_pass:
            per_pass = self.job.spp_per_pass
            if spp % per_pass:
                raise ValueError(f"{self.path}: {per_pass} samples per pass do not divide the {spp} samples per pixel")
        else:
            per_pass = max(1, min(spp, max_samples_per_pass() // (w * h)))
            while spp % per_pass:
                per_pass -= 1
        memory.check_render(w, h, per_pass, 4, f"sensor {sensor}", self.bytes_per_lane)
        textures = getattr(scene, "textures", None)
        if textures is not None and textures.needs_footprint and hasattr(cam, "approximate_dp_dxy"):
            # Procedural and MIP-mapped textures filter over this camera's pixel footprint
            # (its minimum ray differentials are found here, outside the render kernels).
            cam.min_differentials()
            textures.footprint = (cam, spp)
        return cam, w, h, spp, per_pass, spp // per_pass

    def _camera_samples(self, cam, w, h, spp, per_pass, pass_index, seed, pixels=None, sampler=None,
                        pixel=None, index=None):
        """Rays, wavelengths, filter weights and sample streams of one pass: the camera's
        sampler (or ``sampler``) starts a stream per (pixel, sample index), which gives the
        wavelength (1D), the filter's position in the pixel (2D) and the lens (2D), in
        pbrt-v4's order; the integrator draws the rest from it. A pass is every pixel's
        samples ``pass_index * per_pass`` onward, pixel-major (``pixels``: only these
        pixels, ``per_pass`` samples each: an adaptive render's pass, see pbr.adaptive),
        unless ``pixel`` and ``index`` (per-lane ``mi.UInt32``, index < spp) name the samples."""
        if pixel is None:
            n = (w * h if pixels is None else dr.width(pixels)) * per_pass
            idx = dr.arange(mi.UInt32, n)
            slot = idx // per_pass
            pixel = slot if pixels is None else dr.gather(mi.UInt32, pixels, slot)
            index = dr.opaque(mi.UInt32, pass_index) * per_pass + (idx - slot * per_pass)
        sampler = sampler or cam.sampler
        rng = sampler.start(pixel, index, spp, (w, h), seed_array(seed))
        wl = SampledWavelengths.sample_visible(rng.next_1d())
        off, weight = cam.film.rfilter.sample(rng.pixel_2d())
        px = mi.Float(pixel % w) + 0.5 + off.x
        py = mi.Float(pixel // w) + 0.5 + off.y
        inside = (px >= 0) & (px < w) & (py >= 0) & (py < h)
        weight = dr.select(inside, weight, 0.0)
        aperture = rng.next_2d() if cam.needs_aperture_sample else None
        moves = getattr(cam, "motion", None) is not None or self.moving_shapes
        time = cam.sample_time(rng.next_1d()) if moves else None
        if getattr(cam, "weights_rays", False):
            # A camera whose rays carry a weight (the realistic camera's lens throughput):
            # it scales the sample's radiance, not the filter weight the film divides by.
            ray, self._ray_weight = cam.sample_ray_weighted(mi.Point2f(px / w, py / h), aperture, time)
        else:
            ray, self._ray_weight = cam.sample_ray(mi.Point2f(px / w, py / h), aperture, time), None
        # A camera pose with gradients: the same rays, attached, for the adjoint passes
        # of integrators that differentiate it (camera_gradients).
        self.primary_ray_ad = None
        if getattr(self, "camera_gradients", False) and getattr(cam, "to_world_ad", None) is not None:
            with dr.resume_grad():
                self.primary_ray_ad = cam.sample_ray_attached(mi.Point2f(px / w, py / h))
        return rng, wl, ray, weight, inside

    def _pass_sums(self, scene, cam, w, h, spp, per_pass, p, seed, radiance, pixels=None, moments=False):
        """Per-pixel film sums of pass ``p`` (see _film; ``pixels``: of those pixels only,
        in their order). ``moments`` appends w^2 Y^2, w^2 Y and w^2 (Y: the sample's
        luminance), the sums a pixel's variance is estimated from (pbr.adaptive)."""
        rng, wl, ray, weight, inside = self._camera_samples(cam, w, h, spp, per_pass, p, seed, pixels=pixels)
        ray_weight = self._ray_weight
        scene.textures.fix_per_sample(wl.lambda_, scene.lights.spectrum_slots)
        try:
            out = radiance(rng, ray, wl, inside)
        finally:
            scene.textures.release_per_sample()
        L, extra = out if isinstance(out, tuple) else (out, ())
        if ray_weight is not None:
            L = L * ray_weight
        extra = [*film_channels(scene, cam, rng, ray, wl, L, inside), *extra]
        xyz = clamp_sample(cam.film, cam.film.to_xyz(L, wl))
        xyz, *extra = self.counter().replace([xyz * weight, *extra], inside)
        extra = [c * weight for c in extra]
        stats = [xyz.y * xyz.y, xyz.y * weight, weight * weight] if moments else []
        n = w * h if pixels is None else dr.width(pixels)
        return _pixel_sums([*xyz, weight, *extra, *stats], n, per_pass)

    # -- rendering ------------------------------------------------------------------------
    def _film(self, scene, sensor, seed, spp, radiance, progress=None):
        """Develop an image from per-sample spectra ``radiance(rng, ray, wl, inside)``
        (radiance for the primal image, its derivative for forward mode): pass by pass,
        accumulate w * XYZ and w per pixel, then convert to linear sRGB.

        ``radiance`` may also return ``(spectrum, channels)``, ``channels`` a list of
        per-sample ``mi.Float`` (AOVs): they are developed with the same filter weights
        and appended after R, G, B, giving an (H, W, 3 + len(channels)) tensor."""
        if self.adaptive is not None:       # per-pixel sample counts (pbr.adaptive)
            return self.adaptive.film(self, scene, sensor, seed, spp, radiance, progress)
        cam, w, h, spp, per_pass, n_pass = self._plan(scene, sensor, spp)
        sums, job = None, self.job
        bar = _progress(n_pass, progress)
        for p in range(n_pass):
            if job is not None and not job.wants(p):
                continue
            with dr.suspend_grad():
                if job is not None and p in job.given:
                    s = mi.Float(job.given[p])
                else:
                    s = self._pass_sums(scene, cam, w, h, spp, per_pass, p, seed, radiance)
                    if job is not None:
                        job.sums[p] = np.array(s, dtype=np.float32)
                sums = s if sums is None else sums + s
                if n_pass > 1:
                    dr.eval(sums)               # one kernel per pass
            if bar:
                bar.update(1)
        if bar:
            bar.close()
        return _develop(sums, w, h, cam.film)

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        """Primal image: ``mi.TensorXf`` (H, W, 3), linear sRGB."""
        self.prepare(scene, sensor)
        def radiance(rng, ray, wl, inside):
            return self.sample(scene, rng, ray, wl, PRIMAL, None, None, inside)[0]
        return self._film(scene, sensor, seed, spp, radiance, progress)

    def _develop_adjoint(self, wl, weight, pixel_w, grad_img_flat, pixel, active):
        """Per-sample adjoint radiance dLoss/dL for a film adjoint ``grad_img`` (the film
        is linear in L: pixel = M_xyz2srgb * sum(w XYZ(L)) / sum(w))."""
        norm = weight * dr.rcp(dr.gather(mi.Float, pixel_w, pixel, active))
        g = mi.Array3f([dr.gather(mi.Float, grad_img_flat, pixel * 3 + k, active) for k in range(3)])
        return spec.to_xyz_adjoint(spec.srgb_to_xyz_adjoint(g) * norm, wl)

    def render_backward(self, scene, grad_img, sensor=0, seed=0, spp=0, sample=None):
        """Propagate the image adjoint ``grad_img`` (H, W, 3) to the scene parameters.
        ``sample``: the estimator replayed per camera sample (default ``self.sample``;
        the projective integrators add their boundary terms through it)."""
        with dispatch.whole_packets():
            self._render_backward(scene, grad_img, sensor, seed, spp, sample)

    def _render_backward(self, scene, grad_img, sensor, seed, spp, sample):
        self._require_differentiable()
        sample = sample or self.sample
        self.prepare(scene, sensor)
        cam, w, h, spp, per_pass, n_pass = self._plan(scene, sensor, spp)
        if not cam.film.plain:
            raise NotImplementedError(f"{self.name}: reverse-mode derivatives need a plain RGB film ('hdrfilm' or a "
                                      f"default 'rgb'), not {cam.film.name!r}")
        if getattr(cam, "weights_rays", False):
            raise NotImplementedError(f"{self.name}: reverse-mode derivatives with a {type(cam).name!r} camera "
                                      f"(weighted camera rays) are not supported")
        pixel_w = self._pixel_weights(scene, sensor, seed, spp)
        g = grad_img.array if isinstance(grad_img, mi.TensorXf) else mi.Float(np.asarray(grad_img, np.float32).ravel())
        for p in range(n_pass):
            with dr.suspend_grad():
                rng, wl, ray, weight, inside = self._camera_samples(cam, w, h, spp, per_pass, p, seed)
                pixel = dr.arange(mi.UInt32, w * h * per_pass) // per_pass
                state = rng.copy()
                L, _ = sample(scene, rng, mi.Ray3f(ray), wl, PRIMAL, None, None, inside)
                dL = self._develop_adjoint(wl, weight, pixel_w, g, pixel, inside)
                dL, = self.counter().replace([dL], inside)
                # L and dL stay lazy: the primal and adjoint loops fuse into one kernel
                rng.assign(state)
                sample(scene, rng, ray, wl, BACKWARD, dL, L, inside)
            dr.eval()

    def render_forward(self, scene, sensor=0, seed=0, spp=0, sample=None):
        """Forward-mode derivative of the image w.r.t. the gradients set on parameters
        (``sample``: as in :meth:`render_backward`)."""
        self._require_differentiable()
        sample = sample or self.sample
        self.prepare(scene, sensor)
        def radiance_derivative(rng, ray, wl, inside):
            state = rng.copy()
            L, _ = sample(scene, rng, mi.Ray3f(ray), wl, PRIMAL, None, None, inside)
            dr.eval(L)
            rng.assign(state)
            return sample(scene, rng, ray, wl, FORWARD, None, L, inside)[0]
        return self._film(scene, sensor, seed, spp, radiance_derivative, progress=False)

    def _require_differentiable(self) -> None:
        if not self.differentiable:
            names = sorted(n for n, c in INTEGRATORS.items() if c.differentiable)
            raise NotImplementedError(f"{self.name}: derivatives are not supported (primal renders only); "
                                      f"differentiable integrators: {', '.join(names)}")

    def _pixel_weights(self, scene, sensor, seed, spp):
        """Sum of filter weights per pixel (depends only on the random numbers)."""
        cam, w, h, spp, per_pass, n_pass = self._plan(scene, sensor, spp)
        sum_w = None
        with dr.suspend_grad():
            for p in range(n_pass):
                _, _, _, weight, _ = self._camera_samples(cam, w, h, spp, per_pass, p, seed)
                s = _pixel_sums([weight], w * h, per_pass)
                sum_w = s if sum_w is None else sum_w + s
        return dr.maximum(sum_w, 1e-30)


def path_state(ray, active, L=None):
    """The loop state every path tracer starts from: copies of the camera ray and the
    active mask (symbolic loops update their state in place), the radiance ``L`` (0, or
    the primal radiance a PRB replay starts from), throughput ``beta`` = 1, ``depth`` = 0
    and ``valid`` (whether the path hit anything) = False."""
    L = mi.Spectrum(0.0) if L is None else mi.Spectrum(L)
    return mi.Ray3f(ray), mi.Bool(active), L, mi.Spectrum(1.0), mi.UInt32(0), mi.Bool(False)


def ray_state(ray, extent: bool = True):
    """A path's ray as symbolic-loop state: ((origin, direction, extent), (time,
    wavelengths)). A bounce changes the first part; the second stays, and is read from
    outside the loop (``dr.hint(exclude=...)``): a state variable the body leaves
    unchanged makes Dr.Jit trace the loop body twice. :func:`loop_ray` joins them.
    ``extent=False``: the extent stays too (rays of the largest extent throughout, as
    light paths have: ((origin, direction), (extent, time, wavelengths)))."""
    if extent:
        return (ray.o, ray.d, ray.maxt), (ray.time, ray.wavelengths)
    return (ray.o, ray.d), (ray.maxt, ray.time, ray.wavelengths)


def loop_ray(varying, fixed) -> mi.Ray3f:
    """The ray of :func:`ray_state`'s two parts."""
    return mi.Ray3f(*varying, *fixed)


class ConditionalState:
    """Loop variables that change only in some configurations (a medium index without
    media, a forward derivative outside forward mode): :attr:`state` holds those that
    change and is the loop's state; the others are constants read from outside the loop
    (``dr.hint(exclude=[...])``, see :func:`ray_state`). ``values(state)`` gives every
    variable in order at the start of an iteration, ``update(**v)`` the new state at its end."""

    def __init__(self, **entries):
        """``name=(initial value, changes)`` for each variable, in the order
        :meth:`values` returns them."""
        self.names = tuple(entries)
        self.state = {k: v for k, (v, changes) in entries.items() if changes}
        self.fixed = {k: v for k, (v, changes) in entries.items() if not changes}

    def values(self, state: dict) -> tuple:
        # Constants are handed out as new references, so that a masked assignment in the
        # body (x[mask] = ...) cannot change them for the next iteration.
        return tuple(state[k] if k in state else type(self.fixed[k])(self.fixed[k]) for k in self.names)

    def update(self, **values) -> dict:
        return {k: values[k] for k in self.names if k in self.state}


def mis_state(ray):
    """The previous vertex that MIS weights of emitter hits refer to, at the start of a
    path: (``prev_p`` the camera ray's origin, ``prev_n`` 0, ``prev_pdf`` 1, ``prev_delta``
    True: emitters seen directly are weighted 1)."""
    return mi.Point3f(ray.o), mi.Normal3f(0.0), mi.Float(1.0), mi.Bool(True)


def emitted_mis(scene, sampler, light, si, d, wl, on_light, escaped, prev_p, prev_n, prev_pdf, prev_delta):
    """Radiance a path finds by BSDF (or phase) sampling: the area light ``light - 1``
    at ``si`` on ``on_light`` lanes, the infinite lights along ``d`` on ``escaped`` lanes,
    each weighted by the power heuristic against light sampling (with light sampler
    ``sampler``) from the previous vertex (weight 1 after a delta vertex). Throughput not
    included."""
    lights = scene.lights

    def hit():
        Le = lights.L(light - 1, si, wl, on_light)
        pdf_light = lights.pdf_Li(sampler, light - 1, prev_p, prev_n, si, on_light & ~prev_delta)
        w_hit = dr.select(prev_delta, 1.0, power_heuristic(prev_pdf, pdf_light))
        return mi.Spectrum(dr.select(on_light, Le * w_hit, 0.0))

    # In a conditional, as Mitsuba's emitter calls: packets with no lane on a light skip it.
    Le = dispatch.when_any(on_light, hit, label="emission")
    if lights.has_infinite:
        for Le_inf, pdf_inf in lights.Le_escaped(d, wl, prev_p, prev_n, escaped, sampler):
            w_inf = dr.select(prev_delta, 1.0, power_heuristic(prev_pdf, pdf_inf))
            Le += dr.select(escaped, Le_inf * w_inf, 0.0)
    return Le


def light_reaches(geo, si, p, contribution, em, skip_zero: bool = True):
    """Lanes of ``em`` where the light sample at ``p`` reaches ``si``: its unoccluded
    ``contribution`` (the estimate before the shadow ray) is nonzero and the segment to
    ``p`` is free. As in pbrt-v4's ``SampleLd``, the BSDF is evaluated first and a shadow
    ray is traced only where it can change the estimate (not toward a light behind the
    surface, or on the side a one-sided BSDF does not scatter to; Mitsuba traces every
    sampled lane). Measured (64x64, 16 spp, max_depth 3, LLVM): shadow rays on ``door``
    121,928 -> 76,853, on the Cornell box 87,101 -> 73,863, the images unchanged.
    ``skip_zero=False`` (derivative passes) traces every lane of ``em``: a contribution
    of zero may have a nonzero derivative (a reflectance of 0 being optimised)."""
    if skip_zero:
        em = nonzero_estimate(contribution, em)
    return em & geo.unoccluded(si, p, em)


def nonzero_estimate(contribution, em):
    """Lanes of ``em`` whose light-sample ``contribution`` (a spectrum) is not zero: the
    ones worth a shadow ray (:func:`light_reaches`)."""
    return em & nonzero(contribution)


def nonzero(s):
    """Lanes where some wavelength of the spectrum ``s`` is not zero (pbrt-v4's ``if
    (!beta)``): whether a path's throughput still carries anything. A NaN counts as not
    zero, so that a path whose throughput went NaN goes on to the film's count of
    non-finite samples (:class:`NonFinite`) instead of ending unseen, as it did with
    ``max(beta) > 0`` (a conductor of eta = k = 0 rendered black without a warning).
    Written ``~(s == 0)``: Dr.Jit's ``!=`` on floats is an ordered comparison, false
    for NaN (``s != 0`` would end those paths too)."""
    m = ~(dr.detach(s) == 0)
    return m if dr.depth_v(m) == 1 else dr.any(m)      # (dr.any of a Bool would reduce over lanes)


def forward_derivative(Lo) -> mi.Spectrum:
    """Forward-mode derivative of ``Lo`` w.r.t. the parameters' tangents. Only interior
    gradients are cleared: the edges from the parameters to the scene tables must
    survive, because one replay propagates several times."""
    return mi.Spectrum(dr.forward_to(Lo, flags=dr.ADFlag.ClearInterior | dr.ADFlag.AllowNoGrad))


def _pixel_sums(channels, n_pixels, per_pass):
    """Per-pixel sums of per-sample ``channels`` over a pass's pixel-major samples,
    reduced inside the rendering kernel (a local scatter-add), so per-sample values are
    never stored. Returns a flat ``mi.Float``, pixel-major, ``len(channels)`` per pixel."""
    n_ch = len(channels)
    pixel = dr.arange(mi.UInt32, dr.width(channels[-1])) // per_pass
    acc = dr.zeros(mi.Float, n_pixels * n_ch)
    for k, v in enumerate(channels):
        dr.scatter_reduce(dr.ReduceOp.Add, acc, v, pixel * n_ch + k, mode=dr.ReduceMode.Local)
    return acc


def film_channels(scene, cam, rng, ray, wl, L, active) -> list:
    """The film's own per-sample channels: spectral ones (``spectral``, ``specfilm``) and
    the surface channels of a ``gbuffer`` (camera space unless it asks for world space)."""
    film = cam.film
    out = film.sample_channels(L, wl)
    if film.surface_channels:
        frame = None
        if not getattr(film, "world_space", False):
            inv = np.linalg.inv(np.asarray(cam.to_world, np.float64))
            m = inv.tolist()
            nm = np.asarray(cam.to_world, np.float64)[:3, :3].T.tolist()   # normals: inverse transpose

            def frame(v, point):
                a = m if point else nm
                r = [a[k][0] * v[0] + a[k][1] * v[1] + a[k][2] * v[2] + (m[k][3] if point else 0.0)
                     for k in range(3)]
                return mi.Point3f(*r) if point else dr.normalize(mi.Vector3f(*r))
        out += surface_channels(scene, rng, ray, wl, film.surface_channels, active, frame)
    return out


def clamp_sample(film, xyz):
    """A sample's sensor values (XYZ, or a camera sensor's RGB) times the imaging ratio,
    scaled down so that their largest component is at most the film's ``max_component``
    (pbrt-v4's maxcomponentvalue clamps the sensor RGB, before the output transform)."""
    if not np.isfinite(film.max_component):
        return xyz
    v = xyz * float(getattr(film, "imaging_ratio", 1.0))
    top = dr.maximum(dr.maximum(v[0], v[1]), v[2])
    return xyz * dr.select(top > film.max_component, film.max_component / dr.maximum(top, 1e-30), 1.0)


def _develop(sums, w, h, film=None):
    """The film's image from per-pixel sums (w X, w Y, w Z, w, then weighted extra
    channels): XYZ / w through the film's sensor matrix, converted to linear sRGB (left
    out by films without RGB), extra channels / w appended. Stays on the device (no host
    round trip), so a whole render can be recorded by ``dr.freeze``. One lane per output
    value picks its channel: one small kernel, without scatters (scatters into one image
    made a kernel each)."""
    n_ch = dr.width(sums) // (w * h)
    keeps_rgb = getattr(film, "keeps_rgb", True)
    n_out = (3 if keeps_rgb else 0) + n_ch - 4
    if n_out <= 0:
        return mi.TensorXf(dr.zeros(mi.Float, 0), (h, w, 0))
    lane = dr.arange(mi.UInt32, w * h * n_out)
    pixel = lane // n_out
    channel = lane - pixel * n_out
    ch = [dr.gather(mi.Float, sums, pixel * n_ch + k) for k in range(n_ch)]
    inv_w = dr.rcp(dr.maximum(ch[3], 1e-30))
    xyz = mi.Array3f(ch[0], ch[1], ch[2]) * inv_w
    m = getattr(film, "xyz_matrix", None)
    if m is not None:
        m = np.asarray(m, np.float64).tolist()
        xyz = mi.Array3f(*[m[r][0] * xyz[0] + m[r][1] * xyz[1] + m[r][2] * xyz[2] for r in range(3)])
    rgb = [*spec.xyz_to_srgb(xyz)] if keeps_rgb else []
    out = rgb + [c * inv_w for c in ch[4:]]
    img = out[-1]
    for k in range(n_out - 2, -1, -1):
        img = dr.select(channel == k, out[k], img)
    return mi.TensorXf(img, (h, w, n_out))


def _progress(n_pass, progress, desc="pbr render", unit="pass"):
    """A tqdm bar over ``n_pass`` steps (None for one step, or ``progress=False``)."""
    if n_pass <= 1 or progress is False:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=n_pass, desc=desc, unit=unit, leave=False)


def depth_limit(max_depth: int) -> int:
    """Mitsuba's ``max_depth`` as a bound on a path's vertex count in a kernel: -1
    (unlimited) becomes 2^32 - 1; otherwise paths have at most max_depth - 1 bounces
    after the camera ray (max_depth = 1 shows only directly visible emitters)."""
    return max_depth if max_depth >= 0 else 0xFFFFFFFF


class NestingIntegrator(SamplingIntegrator):
    """Base of the integrators that render nested ones alongside (Mitsuba's ``aov`` and
    ``moment``): ``self.nested``, (key, integrator) pairs (:func:`nested_integrators`),
    prepared with this one."""

    nested = ()

    def prepare(self, scene, sensor: int = 0) -> None:
        super().prepare(scene, sensor)
        for _, integrator in self.nested:
            integrator.prepare(scene, sensor)


def nested_integrators(props, refuse=None) -> list:
    """(key, integrator) of the integrators nested in ``props`` (Mitsuba's ``aov`` and
    ``moment`` take any number, each under its own key), in order. ``refuse(type,
    integrator)`` may return why one cannot be nested (an error naming its key)."""
    out = []
    for key, child in props.children():
        t = child["type"]
        if t not in INTEGRATORS:
            raise props.error(key, f"expected a nested integrator, got {t!r}")
        integrator = INTEGRATORS[t](props.child(key))
        why = refuse(t, integrator) if refuse else None
        if why:
            raise props.error(key, why)
        out.append((key, integrator))
    return out


def pbrt_max_depth(props, default: int = 5) -> int:
    """Path-length limit of the pbrt-v4 integrators in Mitsuba's terms: pbrt-v4's
    ``maxdepth`` counts scattering events (0: emitters seen directly), Mitsuba's
    ``max_depth`` path segments, so ``max_depth = maxdepth + 1``. Either name is accepted
    (not both); the limit must be finite (these integrators have no Russian roulette)."""
    if props.has("maxdepth") and props.has("max_depth"):
        raise props.error("max_depth", "give either 'maxdepth' (pbrt-v4) or 'max_depth' (Mitsuba), not both")
    if props.has("max_depth"):
        return props.int("max_depth", min=0)
    return props.int("maxdepth", default, min=0) + 1
