"""Convergence of pbr's samplers (issue 20, item 2): relMSE vs spp from 1 to 4096 for
every sampler on five scenes of different difficulty, the fitted convergence slope, and
relMSE at equal time; a table, a CSV and a log-log plot.

Scenes (``--res`` pixels square; box filter, so that a pixel's integrand is its own):

- ``direct``: a diffuse floor lit by a small (10 cm) square area light, direct light only
  (``path``, max_depth 2): a low-dimensional, smooth integrand (pixel 2D, wavelength 1D,
  light position 2D; the MIS'd BSDF sample finds the light's edge);
- ``textured``: a checkerboard plane seen at a grazing angle under a constant sky, direct
  light only: the pixel integral of a discontinuous texture (anti-aliasing);
- ``cornell``: the Cornell box, ``path`` max_depth 8 (high-dimensional: many bounces);
- ``envglossy``: a rough gold sphere on a diffuse floor under an environment map with a
  bright sun, ``path`` max_depth 4;
- ``medium``: the Cornell box with a scattering fog cube (``volpath``, max_depth 8).

Error: ``relMSE = mean of (x - r)^2 / (r^2 + 0.01)`` (``pbr.validate.relative_mse``) against
a reference ``r`` rendered with ``--ref-sampler`` (``sobol``, the fastest to converge) at
``--ref-spp`` in 16 batches (other seeds); the reference's own noise (``floor``, from
its batches) is subtracted. Each point is the mean over ``--reps`` images (other seeds)
up to 64 spp, one image above; ``spp`` is what the sampler rendered (ldsampler and
multijitter round some counts up).

Slope: least-squares slope of log relMSE vs log spp over spp >= 16, leaving out points
whose raw error is under 4x the reference's floor (not measurable against it).
Independent sampling gives -1; randomised low-discrepancy points reach -1.5 on
discontinuous and -2 or below on smooth low-dimensional integrands. Equal time: each sampler's warm render time per spp
(median of repeats at 256 spp, compile time excluded: ``bench_integrators.timed_render``)
gives the spp it affords in the time ``independent`` takes for 256 spp, and its relMSE
there (log-log interpolation on its curve). Times are process CPU time (all threads):
under other jobs' load it repeats far better than wall-clock time; ``--retime CSV``
measures them again for the rows of an earlier run.

    python benchmarks/bench_samplers.py [--res 32] [--max-spp 4096] [--ref-spp 65536] [--ref-sampler sobol]
        [--scenes direct,textured,cornell,envglossy,medium] [--samplers independent,zsobol]
        [--reps 4] [--out out/bench_samplers] [--from-csv out/bench_samplers.csv]
        [--retime out/bench_samplers.csv]

Writes ``<out>.csv``, ``<out>.json`` and ``<out>.md`` (slopes, equal-time relMSE) and, with matplotlib
(``pip install -e '.[bench]'``), ``<out>.png``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import pbr
from pbr import validate
from pbr.plotting import pyplot

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_integrators import floor_of, timed_render  # noqa: E402

SCENES = ("direct", "textured", "cornell", "envglossy", "medium")
SAMPLERS = ("independent", "stratified", "multijitter", "ldsampler", "sobol", "paddedsobol", "zsobol", "halton",
            "pmj02bn")
RELMSE_EPS = 1e-2
REF_BATCHES = 16
CACHE_VERSION = 1


def _T():
    import mitsuba as mi
    pbr.backend.ensure_any()
    return mi.ScalarTransform4f


def _sensor(res, origin, target, fov=40.0):
    T = _T()
    return {"type": "perspective", "fov": fov, "to_world": T().look_at(origin=origin, target=target, up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}


def _envmap(path: Path):
    """A lat-long sky: a blue-white gradient and a small bright sun (written once)."""
    if not path.exists():
        h, w = 64, 128
        v = (np.arange(h) + 0.5) / h
        u = (np.arange(w) + 0.5) / w
        sky = np.empty((h, w, 3), np.float32)
        sky[:] = (0.4 + 0.6 * (1 - v))[:, None, None] * np.array([0.5, 0.7, 1.0], np.float32)
        theta, phi = np.meshgrid(v * np.pi, u * 2 * np.pi, indexing="ij")
        d = np.stack([np.sin(theta) * np.cos(phi), np.cos(theta), np.sin(theta) * np.sin(phi)], -1)
        sun = np.array([0.5, 0.75, 0.43])
        sun /= np.linalg.norm(sun)
        sky[(d @ sun) > 0.995] = [400.0, 380.0, 300.0]
        path.parent.mkdir(parents=True, exist_ok=True)
        pbr.write_image(str(path), sky)
    return str(path)


def scene_dict(name: str, res: int, cache: Path) -> dict:
    T = _T()
    if name in ("cornell", "medium"):
        d = pbr.cornell_box(res, 16)
        d["sensor"]["film"]["rfilter"] = {"type": "box"}
        d["integrator"] = {"type": "path", "max_depth": 8}
        if name == "medium":
            d["integrator"] = {"type": "volpath", "max_depth": 8}
            d["fog"] = {"type": "cube", "to_world": T().translate([0.0, -0.3, 0.0]).scale([0.7, 0.5, 0.7]),
                        "bsdf": {"type": "null"},
                        "interior": {"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.8}}
        return d
    floor = {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(4.0),
             "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.7]}}}
    if name == "direct":
        return {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                "sensor": _sensor(res, [0, 1.5, 2.5], [0, 0, 0]),
                "floor": floor,
                "light": {"type": "rectangle", "to_world": T().translate([0.2, 0.6, 0.0]).rotate([1, 0, 0], 90)
                          .scale(0.05), "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                                                  "value": [400.0, 300.0, 200.0]}}}}
    if name == "textured":
        floor["bsdf"] = {"type": "diffuse", "reflectance": {"type": "checkerboard", "to_uv": T().scale(24.0),
                                                            "color0": {"type": "rgb", "value": [0.05, 0.05, 0.05]},
                                                            "color1": {"type": "rgb", "value": [0.9, 0.8, 0.6]}}}
        return {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                "sensor": _sensor(res, [0, 0.6, 3.0], [0, 0, -1.0], fov=50.0), "floor": floor,
                "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}
    if name == "envglossy":
        return {"type": "scene", "integrator": {"type": "path", "max_depth": 4},
                "sensor": _sensor(res, [0, 1.0, 3.0], [0, 0.5, 0], fov=35.0), "floor": floor,
                "ball": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
                         "bsdf": {"type": "roughconductor", "material": "Au", "alpha": 0.15}},
                "sky": {"type": "envmap", "filename": _envmap(cache / "bench_samplers_sky.exr")}}
    raise ValueError(f"unknown scene {name!r} (known: {', '.join(SCENES)})")


def with_sampler(d: dict, sampler: str) -> dict:
    d = dict(d)
    d["sensor"] = dict(d["sensor"])
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": 16}
    return d


def reference(name, d, res, spp, sampler, cache: Path):
    """(mean, variance of the mean) of ``sampler`` at ``spp`` in 16 batches, cached."""
    key = hashlib.sha1(repr((CACHE_VERSION, name, res, spp, sampler, sorted((k, repr(v)) for k, v in d.items())))
                       .encode()).hexdigest()[:12]
    f = cache / f"samplers_ref_{name}_{res}_{spp}_{key}.npz"
    if f.exists():
        z = np.load(f)
        return z["mean"], z["var"]
    scene = pbr.load_dict(with_sampler(d, sampler))
    t = time.perf_counter()
    est = validate.estimate(lambda seed, spp: pbr.render(scene, spp=spp, seed=seed, progress=False),
                            spp, batches=REF_BATCHES, seed=9)
    print(f"  reference {name}: {sampler} {spp} spp in {time.perf_counter() - t:.1f} s", flush=True)
    f.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(f, mean=est[0], var=est[1])
    return est[0], est[1]


def fit_slope(spps, errors, min_spp=16, usable=None):
    usable = usable or [True] * len(spps)
    pts = [(math.log(s), math.log(e)) for s, e, u in zip(spps, errors, usable) if s >= min_spp and e > 0 and u]
    if len(pts) < 2:
        return float("nan")
    x, y = np.array(pts).T
    return float(np.polyfit(x, y, 1)[0])


def curve_slope(c):
    return fit_slope([r["spp"] for r in c], [r["relmse"] for r in c],
                     usable=[r["relmse_raw"] > 4 * r["floor"] for r in c])


def interp_loglog(spps, errors, s):
    """relMSE at ``s`` spp, log-log interpolated (extrapolated along the end segments)."""
    x, y = np.log(np.asarray(spps, float)), np.log(np.maximum(np.asarray(errors, float), 1e-300))
    ls = math.log(s)
    i = int(np.clip(np.searchsorted(x, ls) - 1, 0, len(x) - 2))
    w = (ls - x[i]) / (x[i + 1] - x[i])
    return float(math.exp(y[i] + w * (y[i + 1] - y[i])))


def run(a):
    cache = Path(a.cache)
    rows = []
    for name in a.scenes:
        d = scene_dict(name, a.res, cache)
        ref, var = reference(name, d, a.res, a.ref_spp, a.ref_sampler, cache)
        floor = floor_of(ref, var)
        print(f"{name}: reference floor {floor:.3g}", flush=True)
        for sampler in a.samplers:
            scene = pbr.load_dict(with_sampler(d, sampler))
            _, t_eq, cpu_eq, _ = timed_render(scene, a.time_spp, seed=1, repeat_below=1e9, repeats=3)
            spp = 1
            while spp <= a.max_spp:
                reps = a.reps if spp <= 64 else 1
                raws = []
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)   # rounded sample counts
                    for r in range(reps):
                        img = np.asarray(pbr.render(scene, spp=spp, seed=100 + r, progress=False), np.float64)
                        raws.append(validate.relative_mse(img, ref, RELMSE_EPS))
                raw = float(np.mean(raws))
                rows.append({"scene": name, "sampler": sampler, "spp": scene.sensors[0].sampler.round_spp(spp),
                             "relmse": max(raw - floor, 1e-12), "relmse_raw": raw, "floor": floor,
                             "s_per_spp": t_eq / a.time_spp, "cpu_s_per_spp": cpu_eq / a.time_spp})
                spp *= 4
            last = [r for r in rows if r["scene"] == name and r["sampler"] == sampler]
            print(f"  {sampler:12s} " + " ".join(f"{r['relmse']:.2e}" for r in last)
                  + f"  slope {curve_slope(last):+.2f}  {1e3 * t_eq / a.time_spp:.2f} ms/spp", flush=True)
    return rows


def analyse(rows, time_spp=256):
    """Per scene and sampler: slope, relMSE at 256 spp and its ratio to independent's,
    relMSE at equal time (the time independent takes for ``time_spp`` spp)."""
    out = {}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    for name in scenes:
        curves = {}
        for r in rows:
            if r["scene"] == name:
                curves.setdefault(r["sampler"], []).append(r)
        base = curves.get("independent")
        key = "cpu_s_per_spp" if base and "cpu_s_per_spp" in base[0] else "s_per_spp"
        t_budget = base[0][key] * time_spp if base else None
        out[name] = {}
        for sampler, c in curves.items():
            spps, errs = [r["spp"] for r in c], [r["relmse"] for r in c]
            e256 = interp_loglog(spps, errs, time_spp)
            res = {"slope": curve_slope(c), f"relmse_{time_spp}spp": e256,
                   "ms_per_spp": 1e3 * c[0][key]}
            if base:
                b256 = interp_loglog([r["spp"] for r in base], [r["relmse"] for r in base], time_spp)
                res[f"gain_{time_spp}spp"] = b256 / e256
                spp_eq = t_budget / c[0][key]
                res["spp_at_equal_time"] = spp_eq
                res["relmse_equal_time"] = interp_loglog(spps, errs, spp_eq)
                res["gain_equal_time"] = b256 / res["relmse_equal_time"]
            out[name][sampler] = res
    return out


def print_table(summary, time_spp=256):
    for name, per in summary.items():
        print(f"\n{name}: slope, relMSE at {time_spp} spp (x lower than independent), "
              f"relMSE at equal time (x lower), ms per spp")
        for sampler, r in sorted(per.items(), key=lambda kv: kv[1][f"relmse_{time_spp}spp"]):
            print(f"  {sampler:12s} {r['slope']:+.2f}  {r[f'relmse_{time_spp}spp']:.2e} "
                  f"({r.get(f'gain_{time_spp}spp', float('nan')):5.1f}x)  {r.get('relmse_equal_time', float('nan')):.2e} "
                  f"({r.get('gain_equal_time', float('nan')):5.1f}x)  {r['ms_per_spp']:.2f}")


def markdown(summary, time_spp=256) -> str:
    """The summary as Markdown tables (one per scene), best relMSE at 256 spp first."""
    out = []
    for name, per in summary.items():
        out += [f"**{name}**", "", f"| sampler | slope | relMSE at {time_spp} spp | lower than independent | "
                "relMSE at equal time | lower than independent | ms CPU per spp |", "|---|---|---|---|---|---|---|"]
        for sampler, r in sorted(per.items(), key=lambda kv: kv[1][f"relmse_{time_spp}spp"]):
            out.append(f"| {sampler} | {r['slope']:+.2f} | {r[f'relmse_{time_spp}spp']:.2e} | "
                       f"{r.get(f'gain_{time_spp}spp', float('nan')):.1f}x | {r.get('relmse_equal_time', float('nan')):.2e} | "
                       f"{r.get('gain_equal_time', float('nan')):.1f}x | {r['ms_per_spp']:.2f} |")
        out.append("")
    return "\n".join(out)


def plot(rows, summary, path):
    plt = pyplot()
    if plt is None:
        print("matplotlib not installed: no plot (pip install -e '.[bench]')")
        return
    scenes = list(summary)
    ncols = min(3, len(scenes))
    nrows = -(-len(scenes) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 4.2 * nrows), squeeze=False)
    for ax in axes.ravel()[len(scenes):]:
        ax.axis("off")
    for ax, name in zip(axes.ravel(), scenes):
        for sampler in summary[name]:
            c = [r for r in rows if r["scene"] == name and r["sampler"] == sampler]
            ls = "--" if sampler == "independent" else "-"
            ax.loglog([r["spp"] for r in c], [r["relmse"] for r in c], ls, marker=".",
                      label=f"{sampler} ({summary[name][sampler]['slope']:+.2f})")
        base = [r for r in rows if r["scene"] == name and r["sampler"] == "independent"]
        if base:    # guides: slopes -1 and -2 through independent's 16-spp point
            x0, y0 = next(((r["spp"], r["relmse"]) for r in base if r["spp"] >= 16), (base[0]["spp"], base[0]["relmse"]))
            xs = np.array([x0, max(r["spp"] for r in base)], float)
            for k in (1, 2):
                ax.loglog(xs, y0 * (xs / x0) ** -k, ":", color="grey", lw=0.8)
                ax.annotate(f"-{k}", (xs[1], y0 * (xs[1] / x0) ** -k), fontsize=7, color="grey")
        ax.set_title(name)
        ax.set_xlabel("samples per pixel")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    for row in axes:
        row[0].set_ylabel("relMSE")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def retime(rows, a):
    """Measure each (scene, sampler)'s CPU time per spp again (``cpu_s_per_spp``)."""
    cache = Path(a.cache)
    for name in dict.fromkeys(r["scene"] for r in rows):
        d = scene_dict(name, a.res, cache)
        for sampler in dict.fromkeys(r["sampler"] for r in rows if r["scene"] == name):
            scene = pbr.load_dict(with_sampler(d, sampler))
            timed_render(scene, a.time_spp, seed=1, repeat_below=0.0, repeats=1)     # compile
            _, wall, cpu, _ = timed_render(scene, a.time_spp, seed=1, repeat_below=1e9, repeats=3)
            print(f"  {name} {sampler}: {1e3 * cpu / a.time_spp:.2f} ms CPU per spp "
                  f"({1e3 * wall / a.time_spp:.2f} ms wall)", flush=True)
            for r in rows:
                if r["scene"] == name and r["sampler"] == sampler:
                    r["cpu_s_per_spp"] = cpu / a.time_spp
    return rows


def read_csv(path):
    with open(path) as f:
        return [{k: (v if k in ("scene", "sampler") else (int(v) if k == "spp" else float(v))) for k, v in r.items()}
                for r in csv.DictReader(f)]


def write_csv(rows, path):
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--res", type=int, default=32)
    p.add_argument("--max-spp", type=int, default=4096)
    p.add_argument("--ref-spp", type=int, default=65536)
    p.add_argument("--ref-sampler", default="sobol")
    p.add_argument("--time-spp", type=int, default=256)
    p.add_argument("--reps", type=int, default=4)
    p.add_argument("--scenes", default=",".join(SCENES))
    p.add_argument("--samplers", default=",".join(SAMPLERS))
    p.add_argument("--backend", default="llvm")
    p.add_argument("--cache", default=str(HERE / ".cache"))
    p.add_argument("--out", default="out/bench_samplers")
    p.add_argument("--from-csv", default=None)
    p.add_argument("--retime", default=None, help="CSV of an earlier run: measure its CPU times again")
    a = p.parse_args(argv)
    a.scenes, a.samplers = a.scenes.split(","), a.samplers.split(",")
    if a.retime:
        pbr.set_backend(a.backend)
        rows = retime(read_csv(a.retime), a)
        write_csv(rows, a.out + ".csv")
    elif a.from_csv:
        rows = read_csv(a.from_csv)
    else:
        pbr.set_backend(a.backend)
        print(f"backend {a.backend}, load {os.getloadavg()[0]:.1f}, {a.res}x{a.res}", flush=True)
        rows = run(a)
        write_csv(rows, a.out + ".csv")
    summary = analyse(rows, a.time_spp)
    print_table(summary, a.time_spp)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    with open(a.out + ".json", "w") as f:
        json.dump(summary, f, indent=1)
    with open(a.out + ".md", "w") as f:
        f.write(markdown(summary, a.time_spp))
    plot(rows, summary, a.out + ".png")


if __name__ == "__main__":
    main()
