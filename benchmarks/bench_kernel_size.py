"""What a scene's kernel costs when it models only what the scene requires, and what
each optional feature costs (issue 20, item 5).

pbr traces its megakernel over the BSDF, texture and light families a scene contains
(``BSDFSet`` dispatches over the scene's families, texture lookups trace only the kinds
a parameter can reach), so a scene without a family pays nothing for it. To measure
that, each scene is rendered as it is (``scene``) and with tiny objects far below it
(radius 1e-3 at y = -1000: no ray from the scene reaches them in practice), one per
BSDF family of the materials gallery and one per procedural texture kind (``+bsdfs``),
and then also with one emitter of every other kind at zero power (``+lights``; the
``power`` light sampler never picks them). The image is the same (the image-mean ratio
is printed as a check); only the kernel grows.

Then the optional features, each present vs absent on one scene:
``aov`` (the ``aov`` integrator with depth, shading normal and albedo channels around
``path``) vs ``path``; dispersion (a glass sphere with ``int_ior`` ``glass-BK7`` vs its
constant 1.5168); a homogeneous medium in a ball vs the same null ball without one
(``volpath``); and ``volpath`` vs ``path`` on the Cornell box (no media).

Per variant: the LLVM IR size (characters, summed over the render's JIT kernels) and
operation count, the first render's IR generation + LLVM compilation time (Dr.Jit's
in-memory kernel cache flushed first; a kernel found in Dr.Jit's on-disk cache
``~/.drjit`` is loaded, not compiled: ``cached`` says so, run with ``HOME=$(mktemp -d)``
for cold compiles), then the warm render time (tracing + kernel; wall and process CPU
time, medians of interleaved pairs with the baseline) and the ratio to the baseline.

    python benchmarks/bench_kernel_size.py [--res 64] [--spp 16] [--reps 5]
    python benchmarks/bench_kernel_size.py --quick      # 16 x 16, 1 spp, 1 rep, 3 families
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

import pbr  # first: it chooses libLLVM before Dr.Jit loads
import drjit as dr
import mitsuba as mi

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_scenes import scene_dicts, interleaved_cpu, _checker_stage, _sphere  # noqa: E402

FAR = -1000.0      # y of the unreachable objects
TEXTURES = [{"type": "checkerboard", "color0": 0.3, "color1": 0.6},
            {"type": "fbm"}, {"type": "wrinkled"}, {"type": "marble"}, {"type": "dots"}]


def _T():
    return mi.ScalarTransform4f


def _tiny(k: int, bsdf: dict) -> dict:
    return {"type": "sphere", "center": [0.01 * k, FAR, 0.0], "radius": 1e-3, "bsdf": bsdf}


def all_materials() -> list[dict]:
    """Every gallery material (hair excepted: it needs curves) and a diffuse one per
    procedural texture kind."""
    from pbr.scenes import GALLERY_MATERIALS
    mats = [m for _, m in GALLERY_MATERIALS if m["type"] != "hair"]
    return mats + [{"type": "diffuse", "reflectance": t} for t in TEXTURES]


# ``--quick``: a few families, so that the kernels compile in seconds
QUICK_MATERIALS = [{"type": "conductor", "material": "Au"},
                   {"type": "roughplastic", "alpha": 0.2},
                   {"type": "diffuse", "reflectance": TEXTURES[0]}]


def with_all_bsdfs(d: dict, materials: list | None = None) -> dict:
    """``d`` plus one unreachable tiny sphere per material of ``materials`` (default
    :func:`all_materials`)."""
    d = dict(d)
    for k, m in enumerate(all_materials() if materials is None else materials):
        d[f"zz-family-{k}"] = _tiny(k, m)
    return d


def with_all_lights(d: dict, materials: list | None = None) -> dict:
    """``with_all_bsdfs(d)`` plus a zero-power emitter of every other kind; the integrator
    samples lights by power so that they are never chosen."""
    d = with_all_bsdfs(d, materials)
    zero = {"type": "rgb", "value": [0.0, 0.0, 0.0]}
    T = _T()
    frame = T().look_at(origin=[0, FAR, 0], target=[0, FAR - 1, 0], up=[0, 0, 1])
    d["zz-point"] = {"type": "point", "position": [0.0, FAR, 0.0], "intensity": zero}
    d["zz-spot"] = {"type": "spot", "to_world": frame, "intensity": zero}
    d["zz-projector"] = {"type": "projector", "to_world": frame, "irradiance": zero}
    d["zz-directional"] = {"type": "directional", "direction": [0, -1, 0], "irradiance": zero}
    d["zz-constant"] = {"type": "constant", "radiance": zero}
    d["integrator"] = dict(d["integrator"], light_sampler="power")
    return d


def family_scenes(res: int, spp: int, names=("cornell", "cornell-glossy", "bsdf-textured"),
                  materials: list | None = None) -> dict:
    """scene name -> [(variant, dict)], the first variant the baseline."""
    base = scene_dicts(res, spp)
    out = {}
    for n in names:
        d = base[n]
        lit = dict(d, integrator=dict(d["integrator"], light_sampler="power"))
        out[n] = [("scene", d), ("+bsdfs", with_all_bsdfs(d, materials)),
                  ("scene (power)", lit), ("+bsdfs+lights", with_all_lights(d, materials))]
    return out


def feature_scenes(res: int, spp: int) -> dict:
    """feature name -> [(absent, dict), (present, dict)]."""
    out = {}
    d = pbr.cornell_box(res, spp)
    d["integrator"] = {"type": "path", "max_depth": 8}
    a = dict(d, integrator={"type": "aov", "aovs": "dd:depth,nn:sh_normal,alb:albedo",
                            "path": {"type": "path", "max_depth": 8}})
    out["aov (cornell)"] = [("path", d), ("aov+path", a)]
    glass = lambda ior: _checker_stage(res, spp, {"type": "path", "max_depth": 8})  # noqa: E731
    g0, g1 = glass(0), glass(0)
    g0["sphere"] = _sphere({"type": "dielectric", "int_ior": 1.5168})
    g1["sphere"] = _sphere({"type": "dielectric", "int_ior": "glass-BK7"})
    out["dispersion (glass sphere)"] = [("ior 1.5168", g0), ("glass-BK7", g1)]
    m0 = _checker_stage(res, spp, {"type": "volpath", "max_depth": 8})
    m1 = _checker_stage(res, spp, {"type": "volpath", "max_depth": 8})
    m0["sphere"] = _sphere({"type": "null"})
    m1["sphere"] = dict(_sphere({"type": "null"}), interior={"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.8,
                                                             "phase": {"type": "hg", "g": 0.6}})
    out["medium (volpath)"] = [("no medium", m0), ("homogeneous", m1)]
    v = dict(d, integrator={"type": "volpath", "max_depth": 8})
    out["volpath, no media (cornell)"] = [("path", d), ("volpath", v)]
    return out


def first_render(scene, spp: int) -> dict:
    """Kernel figures of a scene's first render (in-memory kernel cache flushed)."""
    dr.flush_kernel_cache()
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    t = time.perf_counter()
    img = np.asarray(pbr.render(scene, spp=spp, seed=0, progress=False))
    t = time.perf_counter() - t
    h = dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    jit = [k for k in h if k["type"] == dr.KernelType.JIT]
    return {"ir": sum(len(k["ir"].getvalue()) for k in jit if "ir" in k),
            "ops": sum(k.get("operation_count", 0) for k in jit),
            "compile_ms": sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in jit),
            "cached": sum(bool(k.get("cache_hit")) for k in jit), "kernels": len(jit),
            "first_s": t, "mean": float(np.mean(img[..., :3]))}


def compare(variants, spp: int, reps: int) -> list[dict]:
    """Figures of every variant; warm times interleaved with the first (the baseline)."""
    scenes = [(v, pbr.load_dict(d)) for v, d in variants]
    rows = []
    seed = [100]

    def runner(sc):
        def run():
            seed[0] += 1
            np.asarray(pbr.render(sc, spp=spp, seed=seed[0], progress=False))
        return run

    base = runner(scenes[0][1])
    for v, sc in scenes:
        r = dict(first_render(sc, spp), variant=v)
        wa, wb, rw, ca, cb, rc = interleaved_cpu(runner(sc), base, reps)
        r.update(wall_ms=wa * 1e3, cpu_ms=ca * 1e3, wall_ratio=rw, cpu_ratio=rc)
        rows.append(r)
    b = rows[0]
    for r in rows:
        r["ir_ratio"] = r["ir"] / b["ir"]
        r["mean_ratio"] = r["mean"] / b["mean"] if b["mean"] else float("nan")
    return rows


HEADER = (f"| {'scene / feature':30s} | {'variant':16s} | {'IR chars':>9s} | {'IR x':>5s} | {'ops':>6s} | "
          f"{'compile ms':>10s} | {'cached':>6s} | {'warm wall ms':>12s} | {'warm cpu ms':>11s} | "
          f"{'cpu x':>5s} | {'wall x':>6s} | {'mean x':>6s} |")


def line(name: str, r: dict) -> str:
    return (f"| {name:30s} | {r['variant']:16s} | {r['ir']:9d} | {r['ir_ratio']:5.2f} | {r['ops']:6d} | "
            f"{r['compile_ms']:10.1f} | {r['cached']:>2d}/{r['kernels']:<3d} | {r['wall_ms']:12.1f} | "
            f"{r['cpu_ms']:11.1f} | {r['cpu_ratio']:5.2f} | {r['wall_ratio']:6.2f} | {r['mean_ratio']:6.3f} |")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--quick", action="store_true", help="16 x 16, 1 spp, 1 rep, the Cornell box with 3 added families and the AOVs only")
    ap.add_argument("--no-features", action="store_true", help="only the family comparison")
    a = ap.parse_args(argv)
    if a.quick:
        a.res, a.spp, a.reps = 16, 1, 1
    pbr.set_backend(a.backend)
    print(f"backend {pbr.get_backend()}, {a.res} wide, {a.spp} spp, medians of {a.reps} interleaved pairs; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs", flush=True)
    print(HEADER)
    print("|" + "|".join("-" * (len(c)) for c in HEADER.split("|")[1:-1]) + "|", flush=True)
    results = {}
    if a.quick:
        fams = family_scenes(a.res, a.spp, ("cornell",), QUICK_MATERIALS)
    else:
        fams = family_scenes(a.res, a.spp)
    for name, variants in fams.items():
        # the zero-power-lights variant is compared with the scene under the same light sampler
        rows = compare(variants[:2], a.spp, a.reps) + compare(variants[2:], a.spp, a.reps)
        results[name] = rows
        for r in rows:
            print(line(name, r), flush=True)
    if not a.no_features:
        feats = feature_scenes(a.res, a.spp)
        for name, variants in feats.items():
            if a.quick and not name.startswith("aov"):
                continue
            rows = compare(variants, a.spp, a.reps)
            results[name] = rows
            for r in rows:
                print(line(name, r), flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    return results


if __name__ == "__main__":
    main()
