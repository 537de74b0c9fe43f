"""Adaptive sampling vs uniform spp: time to reach a per-pixel relative error.

For each scene (``caustic``: ``pbr.scenes.glass_caustic`` with a 20 cm light, uneven
noise: the caustic and the sphere are far noisier than the floor; ``cornell``: the
Cornell box, whose dark corners and shadows need more samples than the lit walls):

1. an adaptive render, ``target_relative_error=e`` (``--target``), at most ``--cap`` spp:
   its time, mean spp (pilot included) and the 95th percentile ``p95`` of its pixels'
   estimated relative standard errors;
2. uniform renders at doubling spp (from 16) until 95% of their pixels reach that same
   ``p95`` (their own estimates, ``return_info``): the time and spp at which they do
   (log-log interpolation, ``pbr.convergence.time_to_reach``).

The ratio of times (uniform / adaptive) at equal 95th-percentile error is the speed-up.
Each render is done once untimed first (kernel compilation), then timed (median of
``--reps``).

    python benchmarks/bench_adaptive.py [--res 48] [--reps 3] [--scenes caustic,cornell]
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

import pbr
from pbr.convergence import time_to_reach

SCENES = ("caustic", "cornell")
TARGETS = {"caustic": 0.05, "cornell": 0.1}


def scene(name, res):
    if name == "caustic":
        d = pbr.scenes.glass_caustic(res, light_size=0.2, radiance=120.0)
        d["integrator"] = {"type": "path", "max_depth": 6}
    else:
        d = pbr.cornell_box(res)
    return pbr.load_dict(d)


def timed(fn, reps):
    fn()                                     # compile
    out, ts = None, []
    for _ in range(reps):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return out, float(np.median(ts))


def run(name, res, target, cap, reps, max_spp=1 << 15):
    s = scene(name, res)
    (_, ia), ta = timed(lambda: pbr.render(s, spp=cap, target_relative_error=target, return_info=True,
                                           progress=False, seed=1), reps)
    p95 = float(np.percentile(ia.relative_error, 95))
    # Uniform renders at doubling spp until their p95 is at most the adaptive one's.
    spps, times, errs = [], [], []
    n = 16
    while n <= max_spp:
        (_, iu), tu = timed(lambda: pbr.render(s, spp=n, return_info=True, progress=False, seed=3 + n), 1)
        spps.append(n)
        times.append(tu)
        errs.append(float(np.percentile(iu.relative_error, 95)))
        if errs[-1] <= p95:
            break
        n *= 2
    t_u, n_u = time_to_reach(times, errs, p95), time_to_reach(spps, errs, p95)
    return {"scene": name, "target": target, "adaptive_s": ta, "adaptive_mean_spp": ia.mean_spp,
            "adaptive_p95": p95, "above_target": ia.above_target, "uniform_spp": n_u, "uniform_s": t_u,
            "uniform_curve": list(zip(spps, times, errs)),
            "speedup": t_u / ta if t_u else float("nan"), "spp_ratio": n_u / ia.mean_spp if n_u else float("nan")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--cap", type=int, default=8192, help="most samples per pixel of the adaptive render")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--backend", default="llvm")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    print(f"bench_adaptive: {a.res}x{a.res}, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    rows = []
    for name in a.scenes.split(","):
        r = run(name, a.res, TARGETS[name], a.cap, a.reps)
        rows.append(r)
        print(f"{name}: target {r['target']:g}: adaptive {r['adaptive_s']:.2f} s, mean {r['adaptive_mean_spp']:.0f} "
              f"spp, p95 {r['adaptive_p95']:.4f}, {100 * r['above_target']:.1f}% above target | uniform at "
              f"equal p95: {r['uniform_spp'] or 0:.0f} spp, {r['uniform_s'] or 0:.2f} s | "
              f"speed-up {r['speedup']:.2f}x time, {r['spp_ratio']:.2f}x samples", flush=True)
        print("  uniform (spp, s, p95): " + ", ".join(f"({n}, {t:.2f}, {e:.4f})" for n, t, e in r["uniform_curve"]))
    return rows


if __name__ == "__main__":
    main()
