"""``pbr.render``: the image of a scene, differentiable with respect to its parameters.

Same signature as ``mitsuba.render``. Without gradients it runs the integrator's primal
passes. When any scene parameter has gradients enabled, the image is produced by a
``dr.CustomOp`` whose backward (forward) derivative runs the integrator's PRB adjoint
passes with seed ``seed_grad`` and ``spp_grad`` samples, decorrelated from the primal.
Samples that are not finite are counted and reported (``on_nonfinite``).
"""

from __future__ import annotations

import drjit as dr

from . import backend, dispatch
from .integrators.base import NonFinite
from .samplers import seed_array
from .scene.params import tables_as_leaves, traverse


class _RenderOp(dr.CustomOp):
    def eval(self, scene, params, sensor, integrator, seed, spp, on_nonfinite):
        self.scene, self.sensor, self.integrator = scene, sensor, integrator
        self.seed, self.spp, self.on_nonfinite = seed, spp, on_nonfinite
        # The primal pass's count is read after a derivative pass, not here: reading it
        # would wait for the image while Python could trace the adjoint pass.
        self.primal = integrator.nonfinite
        with dr.suspend_grad():
            return integrator.render(scene, sensor=sensor, seed=seed[0], spp=spp[0])

    def forward(self):
        # The rendering loop's forward derivative starts from the tables' tangents, and
        # crosses family dispatch as per-lane selects (see pbr.dispatch).
        counter = self.integrator.nonfinite = NonFinite(self.on_nonfinite)
        with tables_as_leaves(self.scene, self.grad_in("params")), dispatch.by_lane():
            img = self.integrator.render_forward(self.scene, sensor=self.sensor, seed=self.seed[1],
                                                 spp=self.spp[1])
        self.set_grad_out(img)
        self._report(counter, "pbr.render (forward derivative)")

    def backward(self):
        counter = self.integrator.nonfinite = NonFinite(self.on_nonfinite)
        self.integrator.render_backward(self.scene, self.grad_out(), sensor=self.sensor,
                                        seed=self.seed[1], spp=self.spp[1])
        self._report(counter, "pbr.render (adjoint pass)")

    def _report(self, counter, what):
        if self.primal is not None:
            primal, self.primal = self.primal, None
            primal.report()
        counter.report(what)

    def name(self):
        return "pbr.render"


def render(scene, params=None, sensor=0, integrator=None, seed=0, seed_grad=0, spp=0, spp_grad=0,
           progress=None, on_nonfinite="warn"):
    """Render ``scene`` from sensor ``sensor``; returns ``mi.TensorXf`` (H, W, 3), linear
    sRGB (``np.asarray`` gives float32). ``spp=0`` uses the scene's sampler count. Seeds
    are Python ints or width-1 ``mi.UInt32`` (pass the latter, e.g. ``dr.opaque(mi.UInt32,
    i)``, to a function under ``dr.freeze``: an int is baked into its recording).
    Samples that are NaN or infinite count as 0 in the image; ``on_nonfinite`` says what
    to do about them after the render: 'warn' (a ``RuntimeWarning`` with their number),
    'raise' (``FloatingPointError``) or 'ignore' (not checked inside ``dr.freeze``). With
    gradients enabled the count is read after the derivative pass (``dr.backward``,
    ``dr.forward``), so that the render does not wait for its image."""
    backend.ensure()
    integrator = integrator or scene.integrator
    counter = integrator.nonfinite = NonFinite(on_nonfinite)
    if not isinstance(sensor, int) or not 0 <= sensor < len(scene.sensors):
        raise ValueError(f"render: sensor index {sensor!r} out of range (scene has {len(scene.sensors)})")
    if spp < 0 or spp_grad < 0:
        raise ValueError("render: spp must be >= 0")
    if not scene.requires_grad():
        img = integrator.render(scene, sensor=sensor, seed=seed, spp=spp, progress=progress)
        counter.report()
        return img
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
    p = params if params is not None else traverse(scene)
    values = {k: v for k, v in p.items() if dr.grad_enabled(v)}
    return dr.custom(_RenderOp, scene, values, sensor, integrator, (seed, seed_grad), (spp, spp_grad), on_nonfinite)
