"""Shared parts of the inverse-rendering examples: command line, multi-view sensors,
reference images, the Adam loop with clamping, error measures and the loss plot.

Every example follows Mitsuba's tutorial recipe, with ``pbr`` in place of ``mitsuba``:

1. build a scene dict with the true parameters and render reference images;
2. overwrite the parameters to optimise with an initial guess (``pbr.traverse`` keys);
3. per iteration: render every view with ``params`` (so the image is differentiable),
   take an image loss, ``dr.backward``, one ``dr.opt.Adam`` step, clamp the values into
   their valid range, and write them back with ``params.update(opt)``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

import pbr  # first: pbr chooses the libLLVM that Dr.Jit loads
from pbr.plotting import pyplot
import drjit as dr
import mitsuba as mi

OUT_DIR = "out"


@dataclass
class Result:
    """What an example's ``main`` returns."""
    error: float                 # final parameter error (the example states its measure)
    losses: list                 # image loss per iteration (sum over views)
    initial_error: float
    errors: list = field(default_factory=list)   # parameter error per iteration
    values: dict = field(default_factory=dict)   # final parameter values (NumPy)
    seconds: float = 0.0                         # wall time of the loop
    scene: object = field(default=None, repr=False)   # the scene, holding the final values
    refs: list = field(default_factory=list, repr=False)  # the reference images


def cli(main, doc: str):
    """``python examples/<name>.py [--small]``: run ``main`` and exit."""
    ap = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    ap.add_argument("--small", action="store_true", help="the tiny configuration the tests run")
    ap.add_argument("--backend", default="llvm", help="llvm, cuda or auto")
    a = ap.parse_args()
    pbr.set_backend(a.backend)
    main(small=a.small)
    sys.exit(0)


def transform() -> "mi.ScalarTransform4f":
    """An identity ``mi.ScalarTransform4f`` (selects pbr's Mitsuba variant first)."""
    pbr.backend.ensure()
    return mi.ScalarTransform4f()


def look_at_sensor(origin, target=(0, 0, 0), up=(0, 1, 0), fov=40.0, res=32, spp=16) -> dict:
    """A perspective sensor dict (box filter: one pixel's samples stay in that pixel)."""
    w, h = (res, res) if np.isscalar(res) else res
    return {"type": "perspective", "fov": float(fov), "fov_axis": "x",
            "to_world": transform().look_at(origin=list(map(float, origin)), target=list(map(float, target)),
                                            up=list(map(float, up))),
            "sampler": {"type": "independent", "sample_count": int(spp)},
            "film": {"type": "hdrfilm", "width": int(w), "height": int(h), "rfilter": {"type": "box"}}}


def orbit_sensors(n: int, radius: float, height: float = 0.0, target=(0, 0, 0), phase: float = 0.0,
                  **kw) -> dict:
    """``n`` sensors evenly spaced on a horizontal circle around ``target`` (starting at
    angle ``phase``), all looking at it: ``{"sensor_0": ..., "sensor_1": ...}``
    (insertion order = sensor index)."""
    out = {}
    for i in range(n):
        a = phase + 2 * np.pi * i / n
        o = (target[0] + radius * np.sin(a), target[1] + height, target[2] + radius * np.cos(a))
        out[f"sensor_{i}"] = look_at_sensor(o, target, **kw)
    return out


def render_references(scene, spp: int, seed: int = 1 << 20) -> list:
    """One converged (high spp) image per sensor, rendered with the true parameters."""
    refs = []
    for s in range(len(scene.sensors)):
        img = pbr.render(scene, sensor=s, spp=spp, seed=seed + s)
        dr.eval(img)
        refs.append(img)
    return refs


def mse(img, ref):
    """The image loss: mean squared difference over pixels and channels."""
    return dr.mean(dr.square(img - ref), axis=None)


def views_backward(scene, params, refs: list, spp: int, seed: int, loss=mse) -> float:
    """Render every view (sensor s with seed ``seed + s``), back-propagate each view's
    loss against ``refs[s]`` (the gradients add up) and return the summed loss."""
    total = 0.0
    for s, ref in enumerate(refs):
        img = pbr.render(scene, params, sensor=s, spp=spp, seed=seed + s)
        li = loss(img, ref)
        dr.backward(li)
        total += float(li.array[0])
    return total


def optimize(scene, init: dict, refs: list, *, n_iter: int, lr, spp: int, bounds: dict,
             error=None, loss=mse, lr_final: float = 1.0, grad_scale: float = 1.0, seed: int = 0,
             log: bool = True, name: str = "") -> Result:
    """Adam on the parameters ``init`` ({traverse key: initial value}) against ``refs``
    (one image per sensor). Each iteration renders every view at ``spp`` with its own
    seed, back-propagates each view's loss (the gradients add up), steps and clamps each
    key into ``bounds[key] = (lo, hi)``. ``lr`` is a float or {key: float}; it decays
    geometrically to ``lr_final`` times its value at the last iteration (Monte Carlo
    gradients keep Adam's steps at about ``lr`` in size, so a fixed rate ends in a random
    walk of that size around the solution).
    ``error(params) -> float`` measures the parameter error (logged per iteration).
    ``grad_scale = -1`` ascends instead of descends: the tests' broken optimiser."""
    params = pbr.traverse(scene)
    lrs = lr if isinstance(lr, dict) else {k: lr for k in init}
    opt = dr.opt.Adam(lr=max(lrs.values()))
    for k, v in init.items():
        params[k] = v
        opt[k] = params[k]
    params.update(opt)
    e0 = float(error(params)) if error else float("nan")
    losses, errors = [], []
    n_views = len(refs)
    t0 = time.perf_counter()
    for it in range(n_iter):
        decay = lr_final ** (it / max(n_iter - 1, 1))
        opt.set_learning_rate({k: lrs[k] * decay for k in init})
        total = views_backward(scene, params, refs, spp, seed + it * n_views, loss)
        opt.step(grad_scale=grad_scale if grad_scale != 1.0 else None)
        for k in init:
            lo, hi = bounds[k]
            opt[k] = dr.clip(opt[k], lo, hi)
        params.update(opt)
        losses.append(total)
        errors.append(float(error(params)) if error else float("nan"))
        if log:
            print(f"{name} iter {it:3d}  loss {total:.6g}  error {errors[-1]:.5f}", flush=True)
    seconds = time.perf_counter() - t0
    values = {k: np.array(params[k]) for k in init}
    return Result(errors[-1] if errors else e0, losses, e0, errors, values, seconds, scene, refs)


def rmse(a, b, weights=None) -> float:
    """Root-mean-square difference of two arrays (optionally weighted per element of
    ``weights``, broadcast against them)."""
    d2 = np.square(np.asarray(a, np.float64) - np.asarray(b, np.float64))
    if weights is None:
        return float(np.sqrt(d2.mean()))
    w = np.broadcast_to(np.asarray(weights, np.float64), d2.shape)
    return float(np.sqrt((w * d2).sum() / w.sum()))


def side_by_side(result: Result, sensor: int = 0, spp: int = 64):
    """Reference | current image of one view, as one (H, 2W, 3) tensor (displayed inline
    in Jupyter once pbr is imported)."""
    img = pbr.render(result.scene, sensor=sensor, spp=spp, seed=7)
    return mi.TensorXf(np.concatenate([np.asarray(result.refs[sensor]), np.asarray(img)], axis=1))


def plot_losses(result: Result, name: str, out_dir: str = OUT_DIR):
    """Loss (and parameter error) per iteration into ``out/<name>_loss.png``; skipped
    without matplotlib. Returns the path or None."""
    plt = pyplot()
    if plt is None:
        print("(matplotlib is not installed: no loss plot)")
        return None
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    ax[0].semilogy(result.losses)
    ax[0].set(title="image loss", xlabel="iteration")
    ax[1].semilogy(result.errors)
    ax[1].set(title="parameter error", xlabel="iteration")
    fig.suptitle(name)
    fig.tight_layout()
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, f"{name}_loss.png")
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def summary(name: str, result: Result, what: str) -> None:
    print(f"{name}: loss {result.losses[0]:.4g} -> {result.losses[-1]:.4g} "
          f"(x{result.losses[0] / max(result.losses[-1], 1e-30):.1f}); {what} "
          f"{result.initial_error:.4f} -> {result.error:.4f}; {result.seconds:.1f} s "
          f"({result.seconds / max(len(result.losses), 1):.2f} s/iteration)")
    p = plot_losses(result, name)
    if p:
        print(f"loss curve: {p}")
