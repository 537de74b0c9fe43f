"""pbr `volpath` vs Mitsuba 3 `volpath` on media scenes: time and error at equal spp,
same process, warm kernels; and the effect of pbr's majorant grid on a sparse cloud.

Scenes (the Cornell box, ceiling light, with a medium in the middle):

- ``cloud``: a sparse heterogeneous density grid (a blob, 85% of the grid empty) in a
  cube with a null boundary;
- ``chromatic``: a homogeneous ball whose sigma_t varies 20x across the spectrum.

Errors are MSE against a reference rendered by both renderers at ``--ref-spp`` (their
average). Prints per-scene time ratio (pbr / Mitsuba, target <= 1) and MSE ratio (target
< 1 on the chromatic scene, where pbr's spectral MIS avoids hero-wavelength fireflies),
then time and MSE of the cloud with the 16^3 majorant grid vs one global majorant.

    python benchmarks/bench_volpath.py [--res 64] [--spp 64] [--ref-spp 4096] [--reps 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import pbr
import drjit as dr
import mitsuba as mi


def cloud_grid(n=32):
    z, y, x = np.mgrid[0:n, 0:n, 0:n] / (n - 1.0)
    g = np.exp(-((x - 0.35) ** 2 + (y - 0.4) ** 2 + (z - 0.6) ** 2) / 0.01) * 40.0
    g[g < 0.5] = 0.0
    return g.astype(np.float32)


def scenes(res, spp, vol_path):
    T = mi.ScalarTransform4f
    out = {}
    for name in ("cloud", "chromatic"):
        d = pbr.cornell_box(res, spp)
        d["integrator"] = {"type": "volpath", "max_depth": 8}
        d["sensor"]["film"]["rfilter"] = {"type": "box"}
        if name == "cloud":
            c, h = np.array([0.1, 0.55, 0.1]), 0.3
            d["cloud"] = {"type": "cube", "to_world": T().translate(c.tolist()).scale(h), "bsdf": {"type": "null"},
                          "interior": {"type": "heterogeneous", "albedo": 0.9,
                                       "sigma_t": {"type": "gridvolume", "filename": vol_path,
                                                   "to_world": T().translate((c - h).tolist()).scale(2 * h)}}}
        else:
            d["ball"] = {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.35, "bsdf": {"type": "null"},
                         "interior": {"type": "homogeneous", "scale": 12.0, "albedo": 0.95,
                                      "sigma_t": {"type": "rgb", "value": [0.05, 0.3, 1.0]}}}
        out[name] = d
    return out


def timed(fn):
    t = time.perf_counter()
    img = fn()
    return time.perf_counter() - t, img


def mse(a, b):
    return float(np.mean((a - b) ** 2))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--vol", default="/tmp/pbr_bench_cloud.vol")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    from pbr.media.grid import write_vol
    write_vol(a.vol, cloud_grid())
    print(f"{a.res}x{a.res}, {a.spp} spp, reference {a.ref_spp} spp, median of {a.reps}")
    for name, d in scenes(a.res, a.spp, a.vol).items():
        scene, mscene = pbr.load_dict(d), mi.load_dict(d)
        rp = lambda spp, seed: np.asarray(pbr.render(scene, spp=spp, seed=seed, progress=False))  # noqa: E731

        def rm(spp, seed):
            img = mi.render(mscene, spp=spp, seed=seed)
            dr.eval(img)
            return np.asarray(img)[..., :3]
        ref = 0.5 * (rp(a.ref_spp, 999) + rm(a.ref_spp, 999))
        rp(a.spp, 0), rm(a.spp, 0)   # warm-up (compilation)
        tp, tm, ep, em = [], [], [], []
        for k in range(a.reps):
            t, img = timed(lambda: rp(a.spp, k + 1))
            tp.append(t), ep.append(mse(img, ref))
            t, img = timed(lambda: rm(a.spp, k + 1))
            tm.append(t), em.append(mse(img, ref))
        tp, tm, ep, em = map(np.median, (tp, tm, ep, em))
        print(f"{name:10s} pbr {tp:6.2f} s  MSE {ep:.3e} | Mitsuba {tm:6.2f} s  MSE {em:.3e} | "
              f"time ratio {tp / tm:.3f}  MSE ratio {ep / em:.3f}")
        if name == "cloud":
            import pbr.media as media
            res_ = {}
            for r in (16, 1):
                media.MAJORANT_RES = r
                pbr.media.majorant.MAJORANT_RES = r
                s2 = pbr.load_dict(d)
                f = lambda seed: np.asarray(pbr.render(s2, spp=a.spp, seed=seed, progress=False))  # noqa: E731
                f(0)
                ts, es = zip(*[(lambda t_img: (t_img[0], mse(t_img[1], ref)))(timed(lambda: f(k + 1)))
                               for k in range(a.reps)])
                res_[r] = (float(np.median(ts)), float(np.median(es)))
            media.MAJORANT_RES = pbr.media.majorant.MAJORANT_RES = 16
            (t16, e16), (t1, e1) = res_[16], res_[1]
            print(f"{'':10s} majorant grid 16^3: {t16:.2f} s, MSE {e16:.3e}; one global majorant: {t1:.2f} s, "
                  f"MSE {e1:.3e}; time ratio {t16 / t1:.3f}")


if __name__ == "__main__":
    main()
