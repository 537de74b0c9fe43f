"""Recover the density grid of a heterogeneous medium from images taken around it,
rendered with ``prbvolpath`` (path replay backpropagation through media).

A cube with a ``null`` boundary holds a ``heterogeneous`` medium whose ``sigma_t`` is a
``gridvolume`` (n^3 voxels, trilinear, times ``scale``), lit by a sun (``directional``)
and a bright uniform sky; the views circle it slightly from above (six views; three in
the small configuration). The smoke is dark (albedo 0.2), so the images are mostly the
sky seen through it, a tomography problem. With a bright albedo and a dim sky (mostly
in-scattered sunlight) the per-voxel gradients were still right (they agree with finite
differences) but the optimisation wandered off: the voxel error rose while the loss
fell. The parameter is ``smoke.sigma_t.data`` (the unscaled density, clamped to
[0, 1.5]), starting from a uniform fog. Error: RMSE over all voxels of the unscaled
density (true values 0..1).

    python examples/optimize_volume.py [--small]
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402  (imports pbr first)

import pbr  # noqa: E402
import mitsuba as mi  # noqa: E402

KEY = "smoke.sigma_t.data"
SCALE = 6.0                      # sigma_t = SCALE * density, per unit length (the cube is 2 wide)
FULL = dict(n=12, res=40, views=6, spp=16, ref_spp=1024, n_iter=80, lr=0.04, lr_final=0.1)
SMALL = dict(n=6, res=24, views=3, spp=16, ref_spp=256, n_iter=16, lr=0.05, lr_final=0.3)


def true_density(n: int) -> np.ndarray:
    """A broad dense blob and a smaller, lighter one (n, n, n, 1), indexed [z, y, x]."""
    z, y, x = (np.mgrid[0:n, 0:n, 0:n] + 0.5) / n
    a = np.exp(-((x - 0.4) ** 2 + (y - 0.45) ** 2 + (z - 0.45) ** 2) / 0.08)
    b = 0.6 * np.exp(-((x - 0.75) ** 2 + (y - 0.7) ** 2 + (z - 0.7) ** 2) / 0.03)
    return np.clip(a + b, 0.0, 1.0).astype(np.float32)[..., None]


def scene_dict(n: int, res: int, views: int, spp: int, sky: float = 1.0, albedo: float = 0.2) -> dict:
    d = {"type": "scene", "integrator": {"type": "prbvolpath", "max_depth": 8}}
    d.update(C.orbit_sensors(views, radius=4.2, height=1.2, phase=0.2, fov=40.0, res=res, spp=spp))
    d["smoke"] = {"type": "heterogeneous", "albedo": albedo, "scale": SCALE,
                  "sigma_t": {"type": "gridvolume", "data": mi.TensorXf(true_density(n)),
                              "to_world": C.transform().translate([-1.0, -1.0, -1.0]).scale(2.0)}}
    d["cube"] = {"type": "cube", "bsdf": {"type": "null"}, "interior": {"type": "ref", "id": "smoke"}}
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [sky, sky, sky]}}
    d["sun"] = {"type": "directional", "direction": [-1.0, -1.0, -0.5],
                "irradiance": {"type": "rgb", "value": [3.0, 3.0, 3.0]}}
    return d


def main(small: bool = False, grad_scale: float = 1.0, log: bool = True, **overrides) -> C.Result:
    cfg = dict(SMALL if small else FULL, **overrides)
    n = cfg["n"]
    scene = pbr.load_dict(scene_dict(n, cfg["res"], cfg["views"], cfg["spp"],
                                     **{k: cfg[k] for k in ("sky", "albedo") if k in cfg}))
    refs = C.render_references(scene, cfg["ref_spp"])
    truth = true_density(n)

    def error(params):
        return C.rmse(params[KEY], truth)

    init = mi.TensorXf(np.full((n, n, n, 1), 0.1, np.float32))
    res = C.optimize(scene, {KEY: init}, refs, n_iter=cfg["n_iter"], lr=cfg["lr"], lr_final=cfg["lr_final"],
                     spp=cfg["spp"], bounds={KEY: (0.0, 1.5)}, error=error, grad_scale=grad_scale, log=log,
                     name="volume")
    if log:
        C.summary("optimize_volume", res, "density RMSE")
    return res


if __name__ == "__main__":
    C.cli(main, __doc__)
