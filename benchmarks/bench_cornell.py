"""pbr `path` vs Mitsuba 3 `path` on the Cornell box: equal spp and resolution, warm
kernels, same process. Prints both times, samples/s and the time ratio (pbr / Mitsuba;
the target is <= 1.0).

    python benchmarks/bench_cornell.py [--res 256] [--spp 64] [--reps 5] [--backend llvm]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import pbr
import drjit as dr
import mitsuba as mi


def _time(fn):
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def interleaved(fa, fb, reps):
    """Median times of fa and fb and the median of per-pair ratios, alternating the two
    so that machine-load drift affects both alike. One warm-up each (compilation)."""
    fa(), fb()
    ta, tb = [], []
    for _ in range(reps):
        ta.append(_time(fa))
        tb.append(_time(fb))
    ratios = np.array(ta) / np.array(tb)
    return float(np.median(ta)), float(np.median(tb)), float(np.median(ratios))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--max-depth", type=int, default=8)
    ap.add_argument("--backend", default="llvm")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    d = pbr.cornell_box(a.res, a.spp)
    d["integrator"] = {"type": "path", "max_depth": a.max_depth}
    scene = pbr.load_dict(d)
    mscene = mi.load_dict(d)
    seed = [0]

    def run_pbr():
        seed[0] += 1
        np.asarray(pbr.render(scene, spp=a.spp, seed=seed[0], progress=False))

    def run_mi():
        seed[0] += 1
        img = mi.render(mscene, spp=a.spp, seed=seed[0])
        dr.eval(img)
        np.asarray(img)

    t_pbr, t_mi, ratio = interleaved(run_pbr, run_mi, a.reps)
    n = a.res * a.res * a.spp
    print(f"Cornell box {a.res}x{a.res}, {a.spp} spp, max_depth {a.max_depth}, backend {pbr.get_backend()}")
    print(f"  pbr     : {t_pbr:.3f} s  {n / t_pbr / 1e6:.2f} Msamples/s")
    print(f"  mitsuba : {t_mi:.3f} s  {n / t_mi / 1e6:.2f} Msamples/s")
    print(f"  time ratio pbr/mitsuba = {ratio:.3f} (median of {a.reps} interleaved pairs)")


if __name__ == "__main__":
    main()
