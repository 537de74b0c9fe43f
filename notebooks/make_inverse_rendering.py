"""Write notebooks/inverse_rendering.ipynb (no Jupyter needed): the four inverse-rendering
examples of examples/ at their small size, with inline images and plots.

    python notebooks/make_inverse_rendering.py
"""

import json
import os

CELLS = [
    ("markdown", """# Inverse rendering with pbr

pbr's images are differentiable with respect to the scene parameters that
`pbr.traverse(scene)` lists (Mitsuba 3's key names). An optimisation follows Mitsuba's
recipe, with `pbr` in place of `mitsuba`:

```python
params = pbr.traverse(scene)
opt = dr.opt.Adam(lr=0.05)
opt[key] = params[key]             # the optimiser owns a differentiable copy
params.update(opt)
for it in range(n_iter):
    img = pbr.render(scene, params, spp=16, seed=it)   # seed_grad: decorrelated from seed
    loss = dr.mean(dr.square(img - ref), axis=None)
    dr.backward(loss)               # Path Replay Backpropagation
    opt.step()
    opt[key] = dr.clip(opt[key], 0.0, 1.0)   # keep the parameter valid
    params.update(opt)
```

`examples/_common.py` holds that loop (`optimize`, several views, a decaying learning
rate); each `examples/optimize_*.py` builds a scene, renders references with the true
parameters and starts from a wrong guess. Here they run at their small size
(`N_ITER` iterations each); `python examples/<name>.py` runs the full size."""),
    ("code", """import sys
import pathlib

import pbr                      # CUDA when usable, else LLVM (pbr.set_backend to choose)

ROOT = pathlib.Path(pbr.__file__).resolve().parents[2]   # the repository (editable install)
sys.path.insert(0, str(ROOT / "examples"))
import _common as C
import optimize_albedo_texture, optimize_roughness_ior, optimize_envmap, optimize_volume

N_ITER = 12
results = {}"""),
    ("markdown", """## 1. A texture: the albedo of the Cornell box's back wall

Every texel of `back.bsdf.reflectance.data` (an RGB bitmap) is a parameter. Left: the
reference; right: the wall after the optimisation."""),
    ("code", """results["albedo"] = r = optimize_albedo_texture.main(small=True, n_iter=N_ITER, log=False)
print(f"texture RMSE {r.initial_error:.3f} -> {r.error:.3f}")
C.side_by_side(r)"""),
    ("markdown", """## 2. Roughness and index of refraction of a rough glass sphere

`glass.bsdf.alpha.value` blurs what is seen through the sphere, `glass.bsdf.eta` sets
how it magnifies and flips the emitting checkerboard behind it."""),
    ("code", """results["roughness_ior"] = r = optimize_roughness_ior.main(small=True, n_iter=N_ITER, log=False)
for k, v in optimize_roughness_ior.TRUE.items():
    print(f"{k}: {optimize_roughness_ior.INIT[k]} -> {float(r.values[k].ravel()[0]):.4f} (true {v})")
C.side_by_side(r)"""),
    ("markdown", """## 3. Lighting: an environment map

`sky.data`, a latitude-longitude map, seen directly in the background and reflected by
a diffuse and a glossy sphere from two views. Error: RMSE over the upper hemisphere,
texel rows weighted by solid angle."""),
    ("code", """results["envmap"] = r = optimize_envmap.main(small=True, n_iter=N_ITER, log=False)
print(f"envmap RMSE {r.initial_error:.3f} -> {r.error:.3f}")
C.side_by_side(r)"""),
    ("markdown", """## 4. A volume: the density grid of a heterogeneous medium

`smoke.sigma_t.data` (a voxel grid) rendered with `prbvolpath`, the volumetric path
tracer with path replay backpropagation, from two views."""),
    ("code", """results["volume"] = r = optimize_volume.main(small=True, n_iter=N_ITER, log=False)
print(f"density RMSE {r.initial_error:.3f} -> {r.error:.3f}")
C.side_by_side(r)"""),
    ("markdown", """## Convergence

Image loss (a Monte Carlo estimate, so it levels off at the renders' noise) and
parameter error per iteration."""),
    ("code", """plt = C.pyplot()
if plt is not None:
    fig, ax = plt.subplots(2, len(results), figsize=(3.2 * len(results), 5))
    for j, (name, r) in enumerate(results.items()):
        ax[0, j].semilogy(r.losses)
        ax[0, j].set_title(name)
        ax[1, j].semilogy(r.errors)
    ax[0, 0].set_ylabel("image loss")
    ax[1, 0].set_ylabel("parameter error")
    plt.show()
for name, r in results.items():
    print(f"{name:15s} loss {r.losses[0]:.3g} -> {r.losses[-1]:.3g}   error {r.initial_error:.4f} -> {r.error:.4f}"
          f"   {r.seconds / len(r.losses):.2f} s/iteration")"""),
]


def main():
    cells = []
    for i, (kind, src) in enumerate(CELLS):
        cell = {"cell_type": kind, "metadata": {}, "source": src, "id": f"c{i}"}
        if kind == "code":
            cell.update(outputs=[], execution_count=None)
        cells.append(cell)
    nb = {"nbformat": 4, "nbformat_minor": 5, "cells": cells,
          "metadata": {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}}}
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "inverse_rendering.ipynb")
    with open(path, "w") as f:
        json.dump(nb, f, indent=1)
        f.write("\n")
    print(path)


if __name__ == "__main__":
    main()
