"""Many-light benchmark: light samplers ``uniform``, ``power`` and ``bvh`` at equal spp and
at equal time, against a converged reference.

The scene: a 40 x 40 floor with a few blocks, ``--lights`` small emissive rectangles
(0.1-0.4 wide, 0.5-6 above the floor, 85% facing down, radiance log-normal with
sigma 1.6: powers over ~4 orders of magnitude) and an emissive icosphere of
20 * 4^subdiv triangles, written to a temporary .obj (one light per triangle: at the
defaults the samplers choose among 1000 + 20480 lights). Path tracing, ``--max-depth``
4. Camera rays pass through emitters (``hide_emitters``) unless ``--show-emitters``:
the spectral noise of directly seen emitters is the same for every sampler and would
otherwise dominate the error.

Reference: the ``bvh`` sampler at ``--ref-spp`` (8192) with an independent seed. Its
own noise adds about MSE(bvh) * spp / ref_spp to every MSE (1/32 of the bvh figure at
the defaults); it is not subtracted.

Per sampler: render time (warm kernels, median of ``--reps`` renders, interleaved
between samplers), MSE vs the reference at ``--spp`` (mean over ``--seeds`` renders),
efficiency (MSE x time relative to bvh), and the MSE at equal time: the spp that fits
the time bvh takes at ``--spp`` (scaled by the measured time ratio and rounded to a
multiple of 16, then timed again).

Each render call also pays a fixed ~0.5-0.9 s (tracing the kernel: Mitsuba's surface
interaction traces every one of the ~1000 shapes); the default spp keeps rendering the
larger part of the time.

    python benchmarks/bench_many_lights.py [--res 128] [--spp 256] [--ref-spp 8192]
        [--lights 1000] [--subdiv 5] [--max-depth 4] [--seeds 3] [--reps 3]
        [--show-emitters] [--backend llvm]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

import pbr
import mitsuba as mi
from pbr import validate


def scene_dict(obj_path: str, res: int, n_lights: int, sampler: str, max_depth: int, seed: int = 0,
               hide_emitters: bool = True) -> dict:
    rng = np.random.default_rng(seed)
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": max_depth, "light_sampler": sampler,
                        "hide_emitters": hide_emitters},
         "sensor": {"type": "perspective", "fov": 55.0,
                    "to_world": T().look_at(origin=[0, 14, 22], target=[0, 0, 0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": 16}},
         "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(20),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.6]}}},
         "ico": {"type": "obj", "filename": obj_path, "face_normals": True,
                 "to_world": T().translate([4.0, 2.0, -3.0]).scale(1.8),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.2, 0.2]}},
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [0.8, 0.9, 1.2]}}}}
    for i, (x, z, s) in enumerate([(-6, -4, 1.5), (-2, 5, 1.0), (7, 6, 1.2), (-9, 8, 0.8), (2, -8, 1.3)]):
        d[f"block{i}"] = {"type": "cube", "to_world": T().translate([x, s, z]).scale(s),
                          "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                                      "value": list(map(float, rng.uniform(0.2, 0.8, 3)))}}}
    for i in range(n_lights):
        pos = [rng.uniform(-18, 18), rng.uniform(0.5, 6.0), rng.uniform(-18, 18)]
        down = rng.random() < 0.85
        tgt = [pos[0] + rng.normal(0, 2), pos[1] - 3.0 if down else pos[1] + 3.0, pos[2] + rng.normal(0, 2)]
        L = float(rng.lognormal(2.0, 1.6))
        col = list(map(float, rng.uniform(0.3, 1.0, 3) * L))
        up = [0, 0, 1] if abs(tgt[0] - pos[0]) + abs(tgt[2] - pos[2]) < 1e-3 else [0, 1, 0]
        d[f"l{i:05d}"] = {"type": "rectangle",
                          "to_world": T().look_at(origin=pos, target=tgt, up=up).scale(float(rng.uniform(0.05, 0.2))),
                          "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}},
                          "emitter": {"type": "area", "radiance": {"type": "rgb", "value": col}}}
    return d


def render(scene, spp, seed):
    return np.asarray(pbr.render(scene, spp=spp, seed=seed, progress=False), dtype=np.float64)


def interleaved_times(jobs, reps):
    """Median wall time of each ``(scene, spp)`` job, alternating the jobs rep by rep so
    that load drift on the machine affects all alike (kernels compiled beforehand)."""
    for sc, spp in jobs.values():
        render(sc, spp, 1)
    ts = {k: [] for k in jobs}
    for r in range(reps):
        for k, (sc, spp) in jobs.items():
            t = time.perf_counter()
            render(sc, spp, 1000 + r)
            ts[k].append(time.perf_counter() - t)
    return {k: float(np.median(v)) for k, v in ts.items()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--ref-spp", type=int, default=8192)
    ap.add_argument("--lights", type=int, default=1000)
    ap.add_argument("--subdiv", type=int, default=5)
    ap.add_argument("--max-depth", type=int, default=4)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--show-emitters", action="store_true",
                    help="camera rays see the emitters (their own spectral noise is the same for all samplers)")
    ap.add_argument("--save", default=None, help="write the reference and renders (.exr) to this folder")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    import trimesh

    tmp = tempfile.mkdtemp(prefix="pbr_many_lights_")
    obj = os.path.join(tmp, "ico.obj")
    trimesh.creation.icosphere(subdivisions=a.subdiv, radius=1.0).export(obj)

    scenes, load_t = {}, {}
    for kind in ("uniform", "power", "bvh"):
        t = time.perf_counter()
        scenes[kind] = pbr.load_dict(scene_dict(obj, a.res, a.lights, kind, a.max_depth,
                                                 hide_emitters=not a.show_emitters))
        load_t[kind] = time.perf_counter() - t
    n_lights = len(scenes["bvh"].lights.local_of)
    bvh = scenes["bvh"].integrator.light_sampler.bvh
    print(f"scene: {a.lights} rectangles + icosphere of {20 * 4 ** a.subdiv} triangles = {n_lights} lights; "
          f"{a.res}x{a.res}, max_depth {a.max_depth}, hide_emitters {not a.show_emitters}; "
          f"BVH: {bvh.n_nodes} nodes, depth {bvh.max_depth}")
    from pbr.lights.bvh import BVHLightSampler
    t = time.perf_counter()
    BVHLightSampler(scenes["bvh"].integrator.light_sampler.table)
    t_build = time.perf_counter() - t
    print("scene load time (s): " + ", ".join(f"{k} {v:.2f}" for k, v in load_t.items())
          + f" (the first includes one-time warm-up); light BVH build {t_build:.2f} s")

    t = time.perf_counter()
    ref = render(scenes["bvh"], a.ref_spp, seed=987654)
    t_ref = time.perf_counter() - t
    print(f"reference: bvh at {a.ref_spp} spp in {t_ref:.1f} s; mean {ref.mean():.4f}")

    results = {}
    times = interleaved_times({k: (sc, a.spp) for k, sc in scenes.items()}, a.reps)
    for kind, sc in scenes.items():
        imgs = [render(sc, a.spp, 10 + s) for s in range(a.seeds)]
        mse = float(np.mean([validate.mse(im, ref) for im in imgs]))
        results[kind] = {"time": times[kind], "mse": mse, "mean": float(np.mean([im.mean() for im in imgs]))}
        if a.save:
            os.makedirs(a.save, exist_ok=True)
            pbr.write_image(os.path.join(a.save, f"{kind}_{a.spp}spp.exr"), imgs[0].astype(np.float32))
    if a.save:
        pbr.write_image(os.path.join(a.save, "reference.exr"), ref.astype(np.float32))

    # Equal time: each sampler gets the time bvh needs at --spp (spp scaled by the
    # measured time ratio, then timed again).
    tb = results["bvh"]["time"]
    eq = {}
    for kind, r in results.items():
        # (a multiple of 16, so that the render splits into as few passes as at --spp)
        r["spp_eq"] = a.spp if kind == "bvh" else max(16, 16 * int(round(a.spp * tb / r["time"] / 16)))
        eq[kind] = (scenes[kind], r["spp_eq"])
    times = interleaved_times(eq, a.reps)
    for kind, r in results.items():
        r["time_eq"] = times[kind]
        r["mse_eq"] = r["mse"] if kind == "bvh" else float(np.mean(
            [validate.mse(render(scenes[kind], r["spp_eq"], 20 + s), ref) for s in range(a.seeds)]))

    rb = results["bvh"]
    print(f"\nequal spp ({a.spp} spp), MSE vs reference (mean of {a.seeds} renders):")
    print(f"{'sampler':8s} {'time (s)':>9s} {'MSE':>11s} {'MSE/bvh':>8s} {'MSE x time / bvh':>17s} {'image mean':>11s}")
    for kind, r in results.items():
        print(f"{kind:8s} {r['time']:9.3f} {r['mse']:11.4e} {r['mse'] / rb['mse']:8.2f} "
              f"{r['mse'] * r['time'] / (rb['mse'] * rb['time']):17.2f} {r['mean']:11.4f}")
    print(f"\nequal time (bvh's {tb:.3f} s at {a.spp} spp):")
    print(f"{'sampler':8s} {'spp':>5s} {'time (s)':>9s} {'MSE':>11s} {'MSE/bvh':>8s}")
    for kind, r in results.items():
        print(f"{kind:8s} {r['spp_eq']:5d} {r['time_eq']:9.3f} {r['mse_eq']:11.4e} "
              f"{r['mse_eq'] / rb['mse_eq']:8.2f}")
    return results


if __name__ == "__main__":
    main()
