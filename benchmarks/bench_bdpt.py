"""pbr ``bdpt`` vs ``path``: error at equal time on scenes where bidirectional sampling
should win, against a high-spp reference.

Scenes (max_depth 6 = pbrt-v4's default maxdepth 5, box filter):

- ``indirect``: the Cornell box with its light turned to face the ceiling, 10 cm below
  it: the room is lit only by the bright ceiling patch above the light, so next-event
  estimation from the room finds nothing and path tracing must hit that patch by BSDF
  sampling; light subpaths land on it directly.
- ``covered``: the Cornell box with a glass pane (a 1.6 cm dielectric slab) under its
  light: shadow rays to the light are blocked, so path tracing sees light only when a
  BSDF-sampled ray passes the glass and hits the light; light subpaths cross the glass
  and connect from the room.
- ``caustic``: a glass sphere on a diffuse floor under a small area light (the scene of
  tests/test_bdpt.py). The caustic's focus is the light's image through the sphere,
  which camera paths hit well; BDPT gains only on the floor around it (light the
  sphere reflects), a small part of the error.
- ``cornell``: the plain Cornell box, where path tracing does well (for calibration).

Each integrator renders ``--reps`` independent images at the spp that takes ``--time``
seconds (measured with warm kernels). Errors are against a ``bdpt`` render at
``--ref-spp`` (another seed; its own error, estimated from the bdpt images, is
subtracted): MSE, which the directly visible light's spectral noise dominates (the
same for both integrators: the camera sees the emitter the same way), and relMSE
(``pbr.validate.relative_mse``, squared error over reference^2 + 0.01). Prints seconds
per image, spp, both errors and their ratios path / bdpt at equal time (error x time;
> 1: bdpt wins).

    python benchmarks/bench_bdpt.py [--res 48] [--time 4] [--ref-spp 4096] [--reps 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import pbr
import mitsuba as mi
from pbr import validate

MAX_DEPTH = 6


def scenes(res):
    T = mi.ScalarTransform4f
    out = {}
    d = pbr.cornell_box(res, 16)
    d["light"]["to_world"] = T().translate([0.0, 0.9, 0.01]).rotate([1, 0, 0], -90).scale([0.23, 0.19, 0.19])
    out["indirect"] = d
    d = pbr.cornell_box(res, 16)
    d["pane"] = {"type": "cube", "to_world": T().translate([0.0, 0.96, 0.01]).scale([0.3, 0.008, 0.26]),
                 "bsdf": {"type": "dielectric", "int_ior": 1.5}}
    out["covered"] = d
    out["caustic"] = pbr.scenes.glass_caustic(res)
    out["cornell"] = pbr.cornell_box(res, 16)
    for d in out.values():
        d["sensor"]["film"]["rfilter"] = {"type": "box"}
    return out


def load(d, integrator):
    d = dict(d)
    d["integrator"] = {"type": integrator, "max_depth": MAX_DEPTH}
    return pbr.load_dict(d)


def render(scene, spp, seed):
    t = time.perf_counter()
    img = np.asarray(pbr.render(scene, spp=spp, seed=seed, progress=False), dtype=np.float64)
    return time.perf_counter() - t, img


def spp_for(scene, budget, probe=8):
    """The spp whose render takes about ``budget`` seconds (warm kernels; two rounds,
    as a render's fixed cost makes a short probe overestimate the time per sample;
    kernels depend on the spp, so each is compiled before it is timed)."""
    spp = probe
    for _ in range(2):
        render(scene, spp, 0)               # compiles the kernels for this spp
        t, _ = render(scene, spp, 1)
        spp = max(1, int(round(spp * budget / t)))
    render(scene, spp, 0)
    return spp


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--time", type=float, default=4.0, help="seconds per image")
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--scenes", default="indirect,covered,caustic,cornell")
    ap.add_argument("--backend", default="llvm")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    print(f"{a.res}x{a.res}, max_depth {MAX_DEPTH}, {a.time:g} s per image, {a.reps} images each, "
          f"reference: bdpt at {a.ref_spp} spp")
    all_scenes = scenes(a.res)
    for name in a.scenes.split(","):
        d = all_scenes[name]
        s_b, s_p = load(d, "bdpt"), load(d, "path")
        t_ref, ref = render(s_b, a.ref_spp, 999)
        row = {}
        for label, sc in (("bdpt", s_b), ("path", s_p)):
            spp = spp_for(sc, a.time)
            runs = [render(sc, spp, 100 + i) for i in range(a.reps)]
            row[label] = (spp, np.mean([t for t, _ in runs]),
                          np.mean([np.mean((img - ref) ** 2) for _, img in runs]),
                          np.mean([validate.relative_mse(img, ref) for _, img in runs]))
        # The reference's own error: that of a bdpt image scaled by the spp ratio.
        spp_b = row["bdpt"][0]
        k_ref = spp_b / (a.ref_spp + spp_b)
        fix = {"mse": row["bdpt"][2] * k_ref, "rel": row["bdpt"][3] * k_ref}
        eq = {}
        for label, (spp, t, m, r) in row.items():
            m, r = max(m - fix["mse"], 1e-30), max(r - fix["rel"], 1e-30)
            # Error ~ 1 / time: error * time compares the two at exactly equal time.
            eq[label] = (m * t, r * t)
            print(f"  {name:9s} {label:5s} {spp:6d} spp {t:6.2f} s/image   MSE {m:.3e}   relMSE {r:.3e}")
        print(f"  {name:9s} path / bdpt at equal time:  MSE {eq['path'][0] / eq['bdpt'][0]:.2f}   "
              f"relMSE {eq['path'][1] / eq['bdpt'][1]:.2f}   (reference {t_ref:.0f} s)")

if __name__ == "__main__":
    main()
