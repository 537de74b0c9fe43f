"""Measured defaults of the integrators whose accuracy depends on a resolution parameter.

On the Cornell box (``pbr.cornell_box``, 64x64, its gaussian filter), against pbr's
``path`` with ``max_depth`` -1 at ``--ref-spp`` (16 batches; ``path`` agrees with
Mitsuba's ``path``: tests/test_mitsuba_compare.py), for each setting: the image mean
ratio, the median over 8x8-pixel blocks of the blocks' relative error (mean luminance),
relMSE (``pbr.validate.relative_mse``, the reference's noise subtracted), and the time.

- ``radiosity``: ``max_area`` 0 (the mesh as given) and ``patch_budget`` from 128 to
  2048, flat and ``smooth`` (ignoring the light's pixels: the light is rendered exactly
  either way);
- ``sppm``: ``radius`` (0: automatic) and ``photonsperiteration`` at a fixed number
  of iterations;
- ``coateddiffuse`` walls: ``maxdepth`` and ``nsamples`` (path at equal spp).

    python benchmarks/bench_defaults.py [--only radiosity,sppm,layered] [--ref-spp 4096]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import pbr
from pbr import validate

RES = 64
LUM = np.array([0.2126, 0.7152, 0.0722])


def reference(d, spp, seed=5):
    """path max_depth -1 at ``spp`` in 16 batches, cached in benchmarks/.cache (by scene and spp)."""
    import hashlib
    key = hashlib.sha1(repr((sorted((k, repr(v)) for k, v in d.items()), spp, seed)).encode()).hexdigest()[:12]
    f = os.path.join(os.path.dirname(os.path.abspath(__file__)), ".cache", f"defaults_ref_{key}.npz")
    if os.path.exists(f):
        z = np.load(f)
        return validate.Estimate(z["mean"], z["var"], float(z["imv"]), 16, spp // 16)
    est = _reference(d, spp, seed)
    os.makedirs(os.path.dirname(f), exist_ok=True)
    np.savez_compressed(f, mean=est.mean, var=est.var, imv=est.image_mean_var)
    return est


def _reference(d, spp, seed):
    s = pbr.load_dict({**d, "integrator": {"type": "path", "max_depth": -1}})
    return validate.estimate(lambda seed, spp: pbr.render(s, seed=seed, spp=spp, progress=False), spp,
                             batches=16, seed=seed)


def errors(img, ref, mask=None):
    """(mean ratio, median 8x8-block relative error, relMSE minus the reference's noise)."""
    x, r = np.asarray(img, np.float64), ref.mean
    keep = np.ones(x.shape[:2], bool) if mask is None else ~mask
    ratio = float((x[keep] @ LUM).mean() / (r[keep] @ LUM).mean())
    h, w = x.shape[:2]
    bx = (x @ LUM).reshape(h // 8, 8, w // 8, 8)
    br = (r @ LUM).reshape(h // 8, 8, w // 8, 8)
    bk = keep.reshape(h // 8, 8, w // 8, 8).all(axis=(1, 3))
    blocks = np.abs(bx.mean(axis=(1, 3)) - br.mean(axis=(1, 3))) / br.mean(axis=(1, 3))
    floor = float(np.mean(ref.var[keep] / (r[keep] ** 2 + 1e-2)))
    rel = float(np.mean((x[keep] - r[keep]) ** 2 / (r[keep] ** 2 + 1e-2))) - floor
    return ratio, float(np.median(blocks[bk])), rel


def timed(scene, spp, seed=1):
    t = time.perf_counter()
    img = np.asarray(pbr.render(scene, spp=spp, seed=seed, progress=False))
    return img, time.perf_counter() - t


def radiosity(d, ref, light):
    print("\nradiosity (gauss_seidel, 16 form-factor samples; 64 spp view; the light's pixels excluded):")
    print(f"{'setting':>18s} {'patches':>7s} {'time s':>7s} {'mean':>7s} {'block med':>9s} {'relMSE':>8s}")
    settings = [("max_area 0", {"max_area": 0.0}), ("max_area 0, smooth", {"max_area": 0.0, "smooth": True})]
    settings += [(f"patch_budget {b}", {"patch_budget": b}) for b in (128, 256, 512, 1024, 2048)]
    settings += [("budget 512, smooth", {"patch_budget": 512, "smooth": True})]
    for name, kw in settings:
        s = pbr.load_dict({**d, "integrator": {"type": "radiosity", **kw}})
        img, t = timed(s, 64)
        n = s.integrator.solution.patches.count
        m, b, rel = errors(img, ref, light)
        print(f"{name:>18s} {n:7d} {t:7.2f} {m:7.4f} {b:9.4f} {rel:8.4f}", flush=True)


def sppm(d, ref):
    print("\nsppm (max_depth -1 vs path max_depth -1; 64 iterations; radius 0: automatic, 4 R / max(W, H)):")
    print(f"{'radius':>7s} {'photons':>8s} {'time s':>7s} {'mean':>7s} {'block med':>9s} {'relMSE':>8s}")
    for radius, photons in ((0.0, -1), (0.0, 4 * RES * RES), (0.4, -1), (0.2, -1), (0.05, -1), (0.025, -1),
                            (1.0, -1)):
        s = pbr.load_dict({**d, "integrator": {"type": "sppm", "max_depth": -1, "radius": radius,
                                               "photonsperiteration": photons}})
        img, t = timed(s, 64)
        m, b, rel = errors(img, ref)
        r0 = s.integrator.initial_radius(s, RES, RES)
        print(f"{radius:7.3f} {photons:8d} {t:7.2f} {m:7.4f} {b:9.4f} {rel:8.4f}  (r_0 {r0:.3f})", flush=True)


def layered(d, ref_spp):
    print("\ncoateddiffuse walls (roughness 0.1), path max_depth -1, 64 spp; reference maxdepth 64:")
    def varnished(ns, md):
        v = dict(d)
        v["white"] = {"type": "coateddiffuse", "reflectance": {"type": "rgb", "value": [0.885809, 0.698859, 0.666422]},
                      "roughness": 0.1, "nsamples": ns, "maxdepth": md}
        return v
    ref = reference(varnished(1, 64), ref_spp)
    print(f"{'maxdepth':>8s} {'nsamples':>8s} {'time s':>7s} {'mean':>7s} {'block med':>9s} {'relMSE':>8s}")
    for md, ns in ((2, 1), (3, 1), (5, 1), (10, 1), (20, 1), (10, 2), (10, 4)):
        s = pbr.load_dict({**varnished(ns, md), "integrator": {"type": "path", "max_depth": -1}})
        timed(s, 4)
        img, t = timed(s, 64)
        m, b, rel = errors(img, ref)
        print(f"{md:8d} {ns:8d} {t:7.2f} {m:7.4f} {b:9.4f} {rel:8.4f}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="radiosity,sppm,layered")
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--backend", default="llvm")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    d = pbr.cornell_box(RES)
    print(f"bench_defaults: Cornell box {RES}x{RES}, reference path max_depth -1 at {a.ref_spp} spp; load "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    only = a.only.split(",")
    if "radiosity" in only or "sppm" in only:
        t = time.perf_counter()
        ref = reference(d, a.ref_spp)
        print(f"reference: {time.perf_counter() - t:.1f} s")
        light = (ref.mean @ LUM) > 5.0          # the light's pixels
        if "radiosity" in only:
            radiosity(d, ref, light)
        if "sppm" in only:
            sppm(d, ref)
    if "layered" in only:
        layered(d, a.ref_spp)


if __name__ == "__main__":
    main()
