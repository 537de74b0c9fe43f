"""Convergence of pbr's `sppm` toward `path`: error vs iterations.

Renders one scene with `sppm` for up to ``--iters`` iterations, keeping the image after
1, 2, 4, ... iterations (one render: the checkpoints share the run), and prints per
checkpoint the photons emitted, the mean search radius (and the schedule predicted for
photons arriving at a steady density, r_k^2 = r_0^2 prod_j (j + 2/3) / (j + 1)), the
elapsed time, the relative MSE against a high-spp `path` reference and the image-mean
ratio. For comparison, the last columns give `path` at one sample per pixel per iteration
(the same number of camera samples) and its time.

Scenes: ``cornell`` (the diffuse Cornell box) and ``caustic`` (the box with a glass sphere
instead of the two blocks: a caustic on the floor). Emitters are hidden (Mitsuba's
``hide_emitters``) so that the light's own pixels do not dominate the error.

    python benchmarks/bench_sppm.py [--scene cornell] [--res 64] [--iters 256]
        [--photons -1] [--radius 0] [--max-depth 6] [--ref-spp 8192]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import pbr
from pbr import validate


def scene_dict(name, res, max_depth, photons, radius):
    d = pbr.cornell_box(res, 16)
    d["integrator"] = {"type": "sppm", "max_depth": max_depth, "hide_emitters": True,
                       "photonsperiteration": photons, "radius": radius}
    if name == "caustic":
        del d["small-box"], d["large-box"]
        d["ball"] = {"type": "sphere", "center": [0.0, -0.5, 0.1], "radius": 0.4,
                     "bsdf": {"type": "dielectric", "int_ior": 1.5}}
    return d


def as_path(d):
    d = dict(d)
    i = d["integrator"]
    d["integrator"] = {"type": "path", "max_depth": i["max_depth"], "hide_emitters": True}
    return d


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=("cornell", "caustic"), default="cornell")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--iters", type=int, default=256)
    ap.add_argument("--photons", type=int, default=-1, help="photons per iteration (-1: one per pixel)")
    ap.add_argument("--radius", type=float, default=0.0, help="initial radius (0: automatic)")
    ap.add_argument("--max-depth", type=int, default=6)
    ap.add_argument("--ref-spp", type=int, default=8192)
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)

    d = scene_dict(a.scene, a.res, a.max_depth, a.photons, a.radius)
    ref_scene = pbr.load_dict(as_path(d))
    t = time.perf_counter()
    chunks = max(1, a.ref_spp // 1024)
    ref = np.mean([np.asarray(pbr.render(ref_scene, spp=a.ref_spp // chunks, seed=1000 + i, progress=False))
                   for i in range(chunks)], axis=0)
    t_ref = time.perf_counter() - t

    scene = pbr.load_dict(d)
    integ = scene.integrator
    pbr.render(scene, spp=2, progress=False)          # compile the kernels
    marks = [k for k in (2 ** i for i in range(int(math.log2(a.iters)) + 1))]
    if marks[-1] != a.iters:
        marks.append(a.iters)
    integ.render(scene, spp=a.iters, seed=a.seed, progress=False, checkpoints=marks)

    r0 = integ.initial_radius(scene, a.res, a.res)
    print(f"sppm on '{a.scene}', {a.res}x{a.res}, max_depth {a.max_depth}, "
          f"{integ.history[0]['photons']} photons/iteration, r0 = {r0:.4f}; "
          f"reference: path {a.ref_spp} spp ({t_ref:.1f} s)")
    print(f"{'iters':>6} {'photons':>10} {'r mean':>8} {'r sched':>8} {'time s':>7} {'relMSE':>9} "
          f"{'mean':>7} | {'path relMSE':>11} {'time s':>7}")
    log_r = 0.0
    prev = 0
    for k in marks:
        for j in range(prev, k):
            log_r += 0.5 * math.log((j + 2.0 / 3.0) / (j + 1.0))
        prev = k
        img = np.asarray(integ.checkpoints[k])
        h = integ.history[k - 1]
        pbr.render(ref_scene, spp=k, seed=5, progress=False)     # compile (spp is a kernel constant)
        t = time.perf_counter()
        p_img = np.asarray(pbr.render(ref_scene, spp=k, seed=7 + k, progress=False))
        t_path = time.perf_counter() - t
        print(f"{k:6d} {h['photons']:10d} {h['radius_mean']:8.4f} {r0 * math.exp(log_r):8.4f} {h['seconds']:7.2f} "
              f"{validate.relative_mse(img, ref):9.5f} {img.mean() / ref.mean():7.4f} | "
              f"{validate.relative_mse(p_img, ref):11.5f} {t_path:7.2f}")


if __name__ == "__main__":
    main()
