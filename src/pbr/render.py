"""``pbr.render``: the image of a scene, differentiable with respect to its parameters.

Same signature as ``mitsuba.render``: ``integrator`` may be an integrator dict or
``pbr.load_dict`` of one; ``sensor`` an index, an entry of ``scene.sensors()`` or a
sensor loaded on its own (``pbr.load_dict`` of a sensor dict). Without gradients it runs
the integrator's primal passes. When any scene parameter has gradients enabled, the image is produced by a
``dr.CustomOp`` whose backward (forward) derivative runs the integrator's PRB adjoint
passes with seed ``seed_grad`` and ``spp_grad`` samples, decorrelated from the primal.
Samples that are not finite are counted and reported (``on_nonfinite``).
"""

from __future__ import annotations

import contextlib
import numbers

import drjit as dr

from . import backend, dispatch
from .adaptive import Adaptive, adaptive_render
from .integrators.base import INTEGRATORS, NonFinite
from .samplers import seed_array
from .scene.objects import as_integrator
from .scene.params import SceneParameters, tables_as_leaves, traverse
from .scene.views import SensorView


@contextlib.contextmanager
def sensor_index(scene, sensor):
    """The index in ``scene.sensors`` of ``sensor`` (an index, a ``scene.sensors()``
    entry, or a sensor loaded on its own, which is appended for the block)."""
    if isinstance(sensor, SensorView):
        sensor = sensor.camera
    if isinstance(sensor, int) and not isinstance(sensor, bool):
        if not 0 <= sensor < len(scene.sensors):
            raise ValueError(f"render: sensor index {sensor!r} out of range (scene has {len(scene.sensors)})")
        yield sensor
        return
    if type(sensor).__module__.startswith("mitsuba"):
        raise TypeError("render: sensor is a Mitsuba object; pass pbr.load_dict(<the sensor's dict>), an entry "
                        "of scene.sensors() or an index")
    if not hasattr(sensor, "sample_ray"):
        raise TypeError(f"render: sensor: expected an index, a scene.sensors() entry or a pbr sensor, "
                        f"got {type(sensor).__name__}")
    for i, s in enumerate(scene.sensors):
        if s is sensor:
            yield i
            return
    scene.sensors.append(sensor)
    try:
        yield len(scene.sensors) - 1
    finally:
        scene.sensors.remove(sensor)


def _check_scene(scene) -> None:
    """A pbr scene (what ``pbr.load_dict``/``load_file`` return), not a scene dict or a
    Mitsuba scene."""
    if hasattr(scene, "geometry") and hasattr(scene, "integrator"):
        return
    hint = ("a scene dict: pass pbr.load_dict(d)" if isinstance(scene, dict) else
            "a Mitsuba scene: load the scene with pbr.load_file / pbr.load_dict instead"
            if type(scene).__module__.startswith("mitsuba") else type(scene).__name__)
    raise TypeError(f"render: scene: expected a pbr scene (pbr.load_dict, pbr.load_file), got {hint}")


def _count(name, v) -> int:
    """A sample count: a non-negative integer (2.5 is an error, not 2)."""
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 0:
        raise ValueError(f"render: {name} must be a non-negative integer, got {v!r}")
    return int(v)


def _seed(name, v):
    """A seed: an integer in [0, 2^32) (seeds are 32-bit: 2^32 would be seed 0), or a
    width-1 mi.UInt32 (see render)."""
    if isinstance(v, bool):
        raise ValueError(f"render: {name} must be an integer in [0, 2^32) or a mi.UInt32, got {v!r}")
    if isinstance(v, numbers.Integral):
        if not 0 <= v < 1 << 32:
            raise ValueError(f"render: {name} must be an integer in [0, 2^32) (seeds are 32-bit), got {v}")
        return int(v)
    return v


class _RenderOp(dr.CustomOp):
    def eval(self, scene, params, sensor, integrator, seed, spp, on_nonfinite):
        self.scene, self.sensor, self.integrator = scene, sensor, integrator
        self.seed, self.spp, self.on_nonfinite = seed, spp, on_nonfinite
        # The primal pass's count is read after a derivative pass, not here: reading it
        # would wait for the image while Python could trace the adjoint pass.
        self.primal = integrator.nonfinite
        with dr.suspend_grad(), sensor_index(scene, sensor) as i:
            return integrator.render(scene, sensor=i, seed=seed[0], spp=spp[0])

    def forward(self):
        # The rendering loop's forward derivative starts from the tables' tangents, and
        # crosses family dispatch as per-lane selects (see pbr.dispatch).
        counter = self.integrator.nonfinite = NonFinite(self.on_nonfinite)
        with backend.pbr_variant(), sensor_index(self.scene, self.sensor) as i, \
                tables_as_leaves(self.scene, self.grad_in("params")), dispatch.by_lane():
            img = self.integrator.render_forward(self.scene, sensor=i, seed=self.seed[1], spp=self.spp[1])
        self.set_grad_out(img)
        self._report(counter, "pbr.render (forward derivative)")

    def backward(self):
        counter = self.integrator.nonfinite = NonFinite(self.on_nonfinite)
        with backend.pbr_variant(), sensor_index(self.scene, self.sensor) as i, dispatch.whole_packets():
            self.integrator.render_backward(self.scene, self.grad_out(), sensor=i, seed=self.seed[1],
                                            spp=self.spp[1])
        self._report(counter, "pbr.render (adjoint pass)")

    def _report(self, counter, what):
        if self.primal is not None:
            primal, self.primal = self.primal, None
            primal.report()
        counter.report(what)

    def name(self):
        return "pbr.render"


@backend.uses_pbr_variant
def render(scene, params=None, sensor=0, integrator=None, seed=0, seed_grad=0, spp=0, spp_grad=0,
           progress=None, on_nonfinite="warn", target_relative_error=None, time_budget=None,
           return_info=False):
    """Render ``scene`` from sensor ``sensor``; returns ``mi.TensorXf`` (H, W, 3), linear
    sRGB (``np.asarray`` gives float32). ``spp=0`` uses the sensor's sampler count.
    ``integrator``: None (the scene's), an integrator dict, or ``pbr.load_dict`` of one.
    ``sensor``: an index, an entry of ``scene.sensors()``, or ``pbr.load_dict`` of a
    sensor dict. Seeds are Python ints or width-1 ``mi.UInt32`` (pass the latter, e.g.
    ``dr.opaque(mi.UInt32, i)``, to a function under ``dr.freeze``: an int is baked into
    its recording). Samples that are NaN or infinite count as 0 in the image;
    ``on_nonfinite`` says what to do about them after the render: 'warn' (a
    ``RuntimeWarning`` with their number), 'raise' (``FloatingPointError``) or 'ignore'
    (not checked inside ``dr.freeze``). With gradients enabled the count is read after
    the derivative pass (``dr.backward``, ``dr.forward``), so that the render does not
    wait for its image.

    Adaptive sampling (``pbr.adaptive``): with ``target_relative_error`` (e.g. 0.05) each
    pixel gets the samples a pilot estimate says it needs for that relative standard
    error, ``spp`` being the most any pixel gets; ``time_budget`` (seconds) stops the
    render when spent (alone: uniform passes until then). ``return_info=True`` returns
    ``(image, pbr.adaptive.AdaptiveInfo)``: per-pixel sample counts and estimated
    relative errors (with neither of the two, of a uniform ``spp`` render: the same
    samples as without it)."""
    _check_scene(scene)
    if params is not None and not callable(getattr(params, "items", None)):
        raise TypeError(f"render: params: expected the scene's parameters (pbr.traverse(scene)) or a dict of "
                        f"them, got {type(params).__name__} {params!r}")
    scene.geometry.check_current()    # (before any symbolic loop: its abort leaves Dr.Jit unclean)
    integrator = scene.integrator if integrator is None else as_integrator(integrator)
    spp, spp_grad = _count("spp", spp), _count("spp_grad", spp_grad)
    seed, seed_grad = _seed("seed", seed), _seed("seed_grad", seed_grad)
    counter = integrator.nonfinite = NonFinite(on_nonfinite)
    camera_grad = any(getattr(c, "to_world_ad", None) is not None and dr.grad_enabled(c.to_world_ad)
                      for c in scene.sensors)
    if camera_grad and not getattr(integrator, "camera_gradients", False):
        names = sorted(n for n, c in INTEGRATORS.items() if getattr(c, "camera_gradients", False))
        raise NotImplementedError(f"render: a sensor's to_world has gradients enabled, which the {integrator.name!r} "
                                  f"integrator does not differentiate; integrators that do: {', '.join(names)}")
    if scene.geometry_requires_grad() and not getattr(integrator, "geometry_gradients", False):
        names = sorted(n for n, c in INTEGRATORS.items() if getattr(c, "geometry_gradients", False))
        raise NotImplementedError(f"render: a shape's geometry has gradients enabled, which the {integrator.name!r} "
                                  f"integrator does not differentiate; integrators that do: {', '.join(names)}")
    if target_relative_error is not None or time_budget is not None or return_info:
        return _render_adaptive(scene, sensor, integrator, seed, spp, progress, counter, target_relative_error,
                                time_budget, return_info)
    if not scene.requires_grad():
        with sensor_index(scene, sensor) as i:
            img = integrator.render(scene, sensor=i, seed=seed, spp=spp, progress=progress)
        counter.report()
        return img
    p = params if params is not None else traverse(scene)
    if dr.flag(dr.JitFlag.FreezingScope):
        (p if isinstance(p, SceneParameters) else traverse(scene)).attach_in_recording()
    values = (p.differentiable_values() if isinstance(p, SceneParameters)
              else {k: v for k, v in p.items() if dr.grad_enabled(v)})
    if scene.bsdfs.dispersive:
        raise NotImplementedError("render: gradients of scenes with dispersive dielectrics (a "
                                  "wavelength-dependent IOR) are not supported yet")
    if isinstance(seed_grad, int) and seed_grad == 0:
        if isinstance(seed, int):
            seed_grad = seed + 0x9E3779B9 if seed else 0x51ED270B
        else:   # a mi.UInt32 (e.g. inside dr.freeze): the same rule, per lane
            seed = seed_array(seed)
            seed_grad = dr.select(seed == 0, 0x51ED270B, seed + 0x9E3779B9)
    spp_grad = spp_grad or spp
    return dr.custom(_RenderOp, scene, values, sensor, integrator, (seed, seed_grad), (spp, spp_grad),
                     on_nonfinite)


def _render_adaptive(scene, sensor, integrator, seed, spp, progress, counter, target, budget, return_info):
    """pbr.render with per-pixel sample counts (pbr.adaptive); primal images only."""
    if scene.requires_grad():
        raise NotImplementedError("render: adaptive sampling (target_relative_error, time_budget, return_info) "
                                  "renders primal images only: disable the parameters' gradients")
    plan = Adaptive(target, budget)
    with sensor_index(scene, sensor) as i, adaptive_render(integrator, plan):
        img = integrator.render(scene, sensor=i, seed=seed, spp=spp, progress=progress)
    counter.report()
    return (img, plan.info) if return_info else img
