"""Error vs time of every pbr integrator on two scenes: relMSE against a high-spp
``path`` reference as the budget doubles, a table, a CSV and a log-log plot.

Scenes (``benchmarks/bench_bdpt.py``'s builders; box filter, emitters visible,
max_depth 6 = pbrt-v4's default maxdepth 5):

- ``cornell``: the Cornell box, where next-event estimation does well;
- ``indirect``: the Cornell box with its light turned to face the ceiling, 10 cm below
  it: the room is lit only by the bright ceiling patch above the light, which camera
  paths must find by BSDF sampling. Both are diffuse triangle meshes with one area
  light, so every integrator (``radiosity`` included) can render them.
- ``caustic``: ``pbr.scenes.glass_caustic`` with a 10 cm light (its default 40 cm one
  at the same power gives a caustic that camera paths reach easily through the
  sphere): the caustic under a glass sphere, seen directly and through the sphere
  (specular-diffuse-specular paths, which no BDPT strategy joins: only camera paths that
  hit the light through the glass find them);
- ``crack``: ``pbr.scenes.door_crack``: a room lit through a 5 cm slit from a lit
  neighbouring room.
  These two are where Metropolis light transport (``mlt``) should win and the Cornell
  box where it should lose; they run ``path``, ``bdpt`` and ``mlt`` only, against a
  ``bdpt`` reference. ``mlt``'s budget is mutations per pixel, with bootstrap samples
  (all depths) a quarter of the mutations and pbrt-v4's 1000 chains; its scene is
  loaded again at each budget and rendered once untimed (recording the kernels that
  its later renders replay: pbr.freeze), as compilation is not timed.

Budgets: ``spp`` doubles from 4 (``sppm``: iterations, one photon per pixel each); for
``radiosity`` a budget ``b`` is ``spp = b``, ``max_area = 0.48 / b`` (the patch count
grows as ``b``) and stochastic Jacobi with ``2^14 b`` rays per iteration. An integrator
stops at ``--max-spp`` or at its first render longer than ``--max-time`` once it has
run ``--min-budgets`` budgets (``path``, the yardstick, goes on until it reaches the
target relMSE). Integrators take turns at each budget, so that the load
of other jobs on the machine hits all alike; absolute times depend on that load
(``os.getloadavg()`` is printed), and renders shorter than 0.2 s are timed 5 times
(median).

With ``--reps N`` every budget renders N independent images (other seeds) and a curve
point is their mean relMSE and mean time: on ``caustic`` and ``crack`` a single image's
relMSE jumps by 10x from one budget to the next (rare bright paths), which makes
single-image curves useless there.

Timing: each integrator first renders once at the smallest budget (kernel
compilation, reported separately); the spp is a constant of the render kernels, so
each new budget compiles again: Dr.Jit's kernel history gives those compile times,
which are subtracted from the wall time of the render (``time_s`` is warm-kernel time;
radiosity's includes its solve; ``cpu_s`` is the process CPU time, the same way).

Error: ``relMSE = mean over pixels and channels of (x - r)^2 / (r^2 + 0.01)``
(``pbr.validate.relative_mse``) against the reference ``r`` = pbr's ``path`` at
``--ref-spp`` (``bdpt`` for caustic and crack; 16 batches, cached in ``benchmarks/.cache`` under a key of the scene and
settings, not of pbr's code: delete it after changing the renderer) with the same max_depth;
``radiosity`` (all bounces) against ``path`` with max_depth -1 at half the spp.
The reference's own noise adds ``floor = mean(var(r) / (r^2 + 0.01))`` (estimated from
its batches) to every error; it is subtracted (``relmse``; ``relmse_raw`` keeps the
sum). ``whitted`` and ``direct`` leave out indirect light: their curves flatten at that
bias. The unbiased integrators' curves must keep falling (slope ~ -1 in the budget);
the benchmark warns where one does not.

Ratios: for each integrator, the time to reach a fixed relMSE (``--target``, per scene)
divided by path's, (a) interpolated (log-log) on the measured curve, (b) at the budget
where the error crosses the target, on a least-squares fit ``time = a + c budget`` of
the curve (steadier under load spikes). Unbiased curves that stop short of the target
are extrapolated as 1/budget (marked ``~``). Printed for wall-clock and for CPU time:
under other jobs' load the CPU-time ratios repeat within ~5% between runs, the
wall-clock ones within ~50%. ``mlt``'s ratios are also printed relative to ``bdpt``.

Not on the curves: ``ambientocclusion``, ``aov``, ``depth`` and ``moment`` (other quantities), ``prb``
(``path``'s estimator: the benchmark checks that its image equals ``path``'s), and
the aliases ``volpathmis`` (``volpath``) and ``lightpath`` (``ptracer``).

    python benchmarks/bench_integrators.py [--res 64] [--max-time 2] [--ref-spp 16384]
        [--target cornell=0.002,indirect=0.02,caustic=0.01,crack=0.01] [--quick]
        [--scenes cornell,indirect,caustic,crack] [--reps 1]
        [--integrators path,bdpt] [--from-csv out/bench_integrators.csv]

Writes ``out/bench_integrators.csv`` and, with matplotlib (``pip install -e '.[bench]'``),
``out/bench_integrators.png``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

import pbr
import drjit as dr
from pbr import validate
from pbr.plotting import pyplot
# The error-vs-time helpers shared with pbr.convergence.
from pbr.convergence import RELMSE_EPS, reference_floor, slope, time_to_reach, timed_render  # noqa: F401
from pbr.integrators import INTEGRATORS

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_bdpt import MAX_DEPTH, scenes as bdpt_scenes  # noqa: E402

SCENES = ("cornell", "indirect", "caustic", "crack")
# The scenes where Metropolis light transport should win run only what it is compared with.
SCENE_INTEGRATORS = {"caustic": ("path", "bdpt", "mlt"), "crack": ("path", "bdpt", "mlt")}
# Their references are bdpt's (path's noise there is what the comparison is about).
REFERENCE = {"caustic": "bdpt", "crack": "bdpt"}
# Estimators whose expected image is the reference's: their error must fall as 1/time.
UNBIASED = ("path", "volpath", "simplevolpath", "prbvolpath", "ptracer", "bdpt", "randomwalk", "simplepath",
            "prb_basic", "mlt")
# Consistent (bias -> 0 with the budget) or biased w.r.t. full global illumination.
BIASED = {"sppm": "consistent: the density estimate's bias shrinks with the radius",
          "radiosity": "consistent in the patch size; all bounces (reference: max_depth -1)",
          "whitted": "biased: direct light + specular paths only",
          "direct": "biased: direct light only"}
EXCLUDED = {"ambientocclusion": "computes ambient occlusion, not radiance",
            "aov": "outputs AOV channels, not an estimate of radiance",
            "depth": "outputs distances, not radiance",
            "moment": "outputs moments of nested integrators (AOVs), not an estimate of radiance",
            "prb": "path's estimator (its primal pass is path's kernel): same curve",
            "prb_projective": "path's primal estimator (it adds boundary terms to derivatives only): same curve",
            "direct_projective": "path's primal estimator at max_depth 2 (boundary terms in derivatives only)"}
BENCHED = UNBIASED + tuple(BIASED)
REF_BATCHES = 16
CACHE_VERSION = 1
# Errors at which the time-to-target ratios are read (path reaches them at the defaults).
DEFAULT_TARGETS = {"cornell": 0.002, "indirect": 0.02, "caustic": 0.01, "crack": 0.01}
# Integrators a new scene dict is loaded for at each budget (their settings follow it).
RELOADED = ("radiosity", "mlt")


def scene_dicts(res):
    """The benchmark's scenes (without integrator) at ``res`` x ``res``."""
    all_scenes = bdpt_scenes(res)
    all_scenes["caustic"] = pbr.scenes.glass_caustic(res, light_size=0.1, radiance=480.0)
    all_scenes["crack"] = pbr.scenes.door_crack(res)
    return {name: all_scenes[name] for name in SCENES}


def scene_integrators(scene, integrators):
    """The integrators that run on ``scene``, in the order given."""
    return [n for n in integrators if n in SCENE_INTEGRATORS.get(scene, integrators)]


def integrator_dict(name, budget, max_depth, pixels=64 * 64):
    """(integrator dict, spp) of ``name`` at ``budget``."""
    if name == "mlt":
        # budget mutations per pixel; bootstrap samples (all depths) a quarter of the
        # mutations, so that the normalisation's error falls with the budget too.
        return {"type": "mlt", "max_depth": max_depth,
                "bootstrapsamples": max(256, pixels * budget // (4 * max(max_depth, 1)))}, budget
    if name == "radiosity":
        return {"type": "radiosity", "solver": "stochastic_jacobi", "max_area": 0.48 / budget,
                "rays_per_iteration": (1 << 14) * budget}, budget
    if name == "direct":
        return {"type": "direct"}, budget
    return {"type": name, "max_depth": max_depth}, budget


def load(d, integrator):
    d = dict(d)
    d["integrator"] = integrator
    return pbr.load_dict(d)




# -- reference ---------------------------------------------------------------------------
def reference(name, d, res, max_depth, spp, cache_dir):
    """(mean image, variance of the mean, seconds, cached?) of ``path`` (``REFERENCE``:
    another) at ``spp`` in 16 batches, cached under a key of the scene, resolution, depth
    and spp."""
    integ = {"type": REFERENCE.get(name, "path"), "max_depth": max_depth}
    key = hashlib.sha1(repr((CACHE_VERSION, sorted((k, repr(v)) for k, v in d.items()), integ, spp,
                             REF_BATCHES)).encode()).hexdigest()[:12]
    f = Path(cache_dir) / f"ref_{name}_{res}_d{max_depth}_{spp}_{key}.npz"
    if f.exists():
        z = np.load(f)
        return z["mean"], z["var"], float(z["seconds"]), True
    scene = load(d, integ)
    t = time.perf_counter()
    est = validate.estimate(lambda seed, spp: pbr.render(scene, spp=spp, seed=seed, progress=False),
                            spp, batches=REF_BATCHES, seed=7)
    sec = time.perf_counter() - t
    f.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(f, mean=est[0], var=est[1], seconds=sec)
    return est[0], est[1], sec, False


def floor_of(ref, var):
    """The reference's own contribution to the expected relMSE of an independent image."""
    return reference_floor(ref, var, RELMSE_EPS)


# -- analysis ----------------------------------------------------------------------------
def reach(r, target, unbiased, key="time_s"):
    """(seconds to reach ``target`` on the rows ``r`` of one curve, '' or '~' when
    extrapolated as 1/time from the last budget: unbiased curves whose slope is -1)."""
    t = time_to_reach([x[key] for x in r], [x["relmse"] for x in r], target)
    if t is not None or not unbiased or not r:
        return t, ""
    if slope([x["budget"] for x in r], [x["relmse"] for x in r]) < -0.75 and r[-1]["relmse"] > 0:
        return r[-1][key] * r[-1]["relmse"] / target, "~"
    return None, ""


def time_model(r, key="time_s"):
    """(a, c) of the least-squares fit time = a + c budget over a curve's rows, each
    residual relative to its time (so that short and long renders weigh alike)."""
    b = np.array([x["budget"] for x in r], float)
    t = np.array([x[key] for x in r], float)
    if len(r) < 2:
        return 0.0, float(t[0] / b[0])
    w = 1.0 / np.maximum(t, 1e-6)
    (a, c), *_ = np.linalg.lstsq(np.stack([w, w * b], axis=1), w * t, rcond=None)
    return float(a), float(c)


def reach_fitted(r, target, unbiased, key="time_s"):
    """(seconds to reach ``target`` on the fitted time model at the budget where the
    curve crosses it (log-log interpolation; '~': extrapolated as 1/budget), flag)."""
    if not r:
        return None, ""
    b_cross = time_to_reach([x["budget"] for x in r], [x["relmse"] for x in r], target)
    how = ""
    if b_cross is None:
        if not unbiased or not (slope([x["budget"] for x in r], [x["relmse"] for x in r]) < -0.75) \
                or r[-1]["relmse"] <= 0:
            return None, ""
        b_cross, how = r[-1]["budget"] * r[-1]["relmse"] / target, "~"
    a, c = time_model(r, key)
    return max(a + c * b_cross, 1e-9), how


def errors_decrease(rows, scene, name, factor=0.6):
    """True if ``name``'s relMSE on ``scene`` at its largest budget is below ``factor``
    times that at its smallest (an unbiased estimator: 1 / budget ratio)."""
    r = sorted((x for x in rows if x["scene"] == scene and x["integrator"] == name), key=lambda x: x["budget"])
    return len(r) >= 2 and r[-1]["relmse"] < factor * r[0]["relmse"]


def plot(rows, targets, path, title):
    """relMSE vs time, one line per integrator, one column per scene; top row wall-clock
    time, bottom row CPU time (when the rows have it). Returns the path, or None
    without matplotlib."""
    plt = pyplot()
    if plt is None:
        print("matplotlib is not installed (pip install -e '.[bench]'): no plot")
        return None
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    names = list(dict.fromkeys(r["integrator"] for r in rows))
    keys = [("time_s", "wall-clock time per image (s; load-dependent)")]
    if all("cpu_s" in r for r in rows):
        keys.append(("cpu_s", "CPU time per image (s, all threads)"))
    colors = ["#1f77b4", "#9ecae1", "#ff7f0e", "#bcbd22", "#2ca02c", "#17becf", "#d62728", "#e377c2",
              "#9467bd", "#8c564b", "#7f7f7f", "#000000"]
    markers = "osD^v<>phX*P"
    fig, axes = plt.subplots(len(keys), len(scenes), figsize=(6.5 * len(scenes), 4.8 * len(keys)), squeeze=False)
    for row, (key, label) in zip(axes, keys):
        for ax, sc in zip(row, scenes):
            for i, n in enumerate(names):
                r = [x for x in rows if x["scene"] == sc and x["integrator"] == n and x["relmse"] > 0]
                if r:
                    ax.loglog([x[key] for x in r], [x["relmse"] for x in r], color=colors[i % len(colors)],
                              marker=markers[i % len(markers)], ms=4, lw=1.4,
                              ls="-" if n in UNBIASED else "--", label=n)
            if sc in targets:
                ax.axhline(targets[sc], color="0.5", lw=0.8, ls=":")
            ax.set_title(sc)
            ax.set_xlabel(label)
            ax.set_ylabel("relMSE vs reference")
            ax.grid(True, which="both", alpha=0.25)
    axes[0][-1].legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5),
                       title="solid: unbiased\ndashed: biased/consistent", title_fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


# -- main ---------------------------------------------------------------------------------
def parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=None, help="image width = height (default 64; --quick 32)")
    ap.add_argument("--max-time", type=float, default=None,
                    help="stop an integrator after a render longer than this (s; default 2; --quick 0.3)")
    ap.add_argument("--max-spp", type=int, default=None, help="largest budget (default 4096; --quick 64)")
    ap.add_argument("--min-budgets", type=int, default=None,
                    help="budgets every integrator runs, however long its renders take (default 5; --quick 2)")
    ap.add_argument("--min-spp", type=int, default=4,
                    help="smallest budget (default 4: below, a render's fixed cost dominates its time)")
    ap.add_argument("--budgets", default=None, help="explicit budgets, e.g. 4,16 (instead of doubling from 1)")
    ap.add_argument("--ref-spp", type=int, default=None, help="reference spp (default 16384; --quick 2048)")
    ap.add_argument("--target", default="",
                    help="relMSE for the time-to-target ratios: one value, or scene=value pairs "
                         "(default " + ",".join(f"{k}={v:g}" for k, v in DEFAULT_TARGETS.items()) + ")")
    ap.add_argument("--max-depth", type=int, default=MAX_DEPTH)
    ap.add_argument("--reps", type=int, default=1,
                    help="independent images per budget, their relMSE averaged (heavy-tailed scenes: caustic, crack)")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--integrators", default=",".join(BENCHED))
    ap.add_argument("--quick", action="store_true", help="a smoke run (< 2 min)")
    ap.add_argument("--out", default=str(HERE.parent / "out"), help="folder of the CSV and PNG")
    ap.add_argument("--cache", default=str(HERE / ".cache"), help="folder of the cached references")
    ap.add_argument("--no-plot", action="store_true")
    ap.add_argument("--from-csv", default=None, help="re-analyse and re-plot a CSV of an earlier run (no rendering)")
    ap.add_argument("--backend", default="llvm")
    a = ap.parse_args(argv)
    q = a.quick
    a.res = a.res or (32 if q else 64)
    a.max_time = a.max_time if a.max_time is not None else (0.3 if q else 2.0)
    a.max_spp = a.max_spp or (64 if q else 4096)
    a.min_budgets = a.min_budgets if a.min_budgets is not None else (2 if q else 5)
    a.ref_spp = a.ref_spp or (2048 if q else 16384)
    if a.budgets:
        a.budgets = sorted({int(b) for b in a.budgets.split(",")})
        if a.budgets[0] < 1:
            ap.error("--budgets: every budget must be >= 1")
    else:
        a.budgets = [1 << k for k in range(int(math.log2(a.min_spp)), int(math.log2(a.max_spp)) + 1)]
    a.scenes = a.scenes.split(",")
    try:
        if a.target and "=" not in a.target:
            a.target = {sc: float(a.target) for sc in SCENES}
        else:
            a.target = {k: float(v) for k, v in (p.split("=") for p in a.target.split(",") if p)}
    except ValueError:
        ap.error(f"--target: expected a number or scene=number pairs, got {a.target!r}")
    for s in a.target:
        if s not in SCENES:
            ap.error(f"--target: unknown scene {s!r}")
    a.targets = {sc: a.target.get(sc, DEFAULT_TARGETS[sc]) for sc in SCENES}
    a.integrators = a.integrators.split(",")
    for s in a.scenes:
        if s not in SCENES:
            ap.error(f"--scenes: unknown scene {s!r} (choose from {', '.join(SCENES)})")
    for n in a.integrators:
        if n not in BENCHED:
            why = EXCLUDED.get(n, "not an integrator")
            ap.error(f"--integrators: {n!r} is not benchmarked ({why})")
    if a.ref_spp < REF_BATCHES:
        ap.error(f"--ref-spp must be >= {REF_BATCHES}")
    return a


def report_skipped():
    """Print why each registered integrator is benchmarked or not."""
    classes = {}
    for name, cls in INTEGRATORS.items():
        classes.setdefault(cls, []).append(name)
    for name, cls in INTEGRATORS.items():
        if name in BENCHED:
            continue
        if name in EXCLUDED:
            print(f"  not on the curves: {name:16s} ({EXCLUDED[name]})")
            continue
        alias = [n for n in classes[cls] if n in BENCHED]
        if alias:
            print(f"  not on the curves: {name:16s} (an alias of {alias[0]})")
        else:
            print(f"  WARNING: {name} is registered but has no benchmark configuration")


def check_prb(d, budget, max_depth):
    """prb's primal image equals path's at the same seed (why its curve is path's)."""
    imgs = [np.asarray(pbr.render(load(d, {"type": n, "max_depth": max_depth}), spp=budget, seed=11, progress=False))
            for n in ("path", "prb")]
    return float(np.abs(imgs[0] - imgs[1]).max())


def run(a):
    """Render every integrator at every budget on every scene: the CSV's rows, and the
    compile seconds per (scene, integrator): (warm-up, all budgets)."""
    dicts = scene_dicts(a.res)
    rows, compile_s, refs = [], {}, {}
    for sc in a.scenes:
        d = dicts[sc]
        names = scene_integrators(sc, a.integrators)
        for depth, spp in ((a.max_depth, a.ref_spp), (-1, a.ref_spp // 2)):
            if depth == -1 and "radiosity" not in names:
                continue
            ref, var, sec, cached = reference(sc, d, a.res, depth, spp, a.cache)
            refs[(sc, depth)] = (ref, floor_of(ref, var))
            print(f"[{sc}] reference max_depth {depth}: {spp} spp, {sec:.1f} s{' (cached)' if cached else ''}, "
                  f"own relMSE floor {refs[(sc, depth)][1]:.2e}", flush=True)
        pixels = a.res * a.res
        scenes = {n: load(d, integrator_dict(n, a.budgets[0], a.max_depth, pixels)[0]) for n in names
                  if n not in RELOADED}
        # Warm-up: compile each integrator's kernels at the smallest budget.
        for n in names:
            integ, spp = integrator_dict(n, a.budgets[0], a.max_depth, pixels)
            s = scenes[n] if n in scenes else load(d, integ)
            _, _, _, comp = timed_render(s, spp, seed=1, repeats=1)
            compile_s[(sc, n)] = [comp, comp]
        active = list(names)
        for level, b in enumerate(a.budgets):
            for n in list(active):
                integ, spp = integrator_dict(n, b, a.max_depth, pixels)
                s = scenes[n] if n in scenes else load(d, integ)
                if n == "mlt":   # its first render records the kernels it replays (untimed, as compiling)
                    timed_render(s, spp, seed=1, repeats=1)
                ref, floor = refs[(sc, -1 if n == "radiosity" else a.max_depth)]
                # --reps independent images (other seeds): their mean relMSE and time.
                raws, secs, cpus, means = [], [], [], []
                for k in range(1 if n == "radiosity" else a.reps):
                    # radiosity solves in its first render only: a repeat would time the view alone.
                    img, sec, cpu, comp = timed_render(s, spp, seed=1000 + level + 7919 * k,
                                                       repeats=1 if n == "radiosity" else 5)
                    compile_s[(sc, n)][1] += comp
                    raws.append(validate.relative_mse(img, ref, RELMSE_EPS))
                    secs.append(sec)
                    cpus.append(cpu)
                    means.append(float(img.mean() / ref.mean()))
                raw, sec, cpu = float(np.mean(raws)), float(np.mean(secs)), float(np.mean(cpus))
                rows.append({"scene": sc, "integrator": n, "budget": b, "spp": spp, "time_s": sec, "cpu_s": cpu,
                             "relmse": raw - floor, "relmse_raw": raw, "ref_floor": floor,
                             "mean_ratio": float(np.mean(means)),
                             "kind": "unbiased" if n in UNBIASED else "biased/consistent"})
                # path, the yardstick of the time-to-target ratios, goes on until it reaches the target.
                yardstick = n == "path" and raw - floor > a.targets[sc]
                if (sec > a.max_time and level + 1 >= a.min_budgets and not yardstick) or b >= a.max_spp:
                    active.remove(n)
            print(f"[{sc}] budget {b} done ({len(active)} integrators go on)", flush=True)
            if not active:
                break
        if "path" in names:
            print(f"[{sc}] prb vs path at {a.budgets[0]} spp, same seed: max |difference| "
                  f"{check_prb(d, a.budgets[0], a.max_depth):.3g}")
    return rows, compile_s


def read_csv(path):
    """Rows of a CSV written by this benchmark (numbers converted)."""
    conv = {"budget": int, "spp": int, "time_s": float, "cpu_s": float, "relmse": float, "relmse_raw": float,
            "ref_floor": float, "mean_ratio": float}
    with open(path, newline="") as f:
        return [{k: conv.get(k, str)(v) for k, v in r.items()} for r in csv.DictReader(f)]


def analyse(rows, scenes, integrators, targets, key="time_s", yardstick="path"):
    """Print the ratios (time to reach the target relMSE) / (``yardstick``'s), on the
    measured curves and on fitted times (``key``: ``time_s`` wall, ``cpu_s`` CPU); returns
    {(scene, integrator): (measured, fitted) cells}."""
    what = ("WALL-CLOCK time" if key == "time_s" else
            "CPU time (process time: the work done, steadier than wall time when other jobs load the machine)")
    print(f"\n{what} to reach the target relMSE, relative to {yardstick} (< 1: faster). 'measured': interpolated "
          f"on the measured curve; 'fitted': at the budget where the error curve crosses the target, "
          "on a least-squares fit time = a + c budget (less sensitive to load spikes); 'not reached': within "
          "the budgets run; '~': extrapolated as 1/budget from the last budget (unbiased curves only); "
          "slope: d log relMSE / d log budget over the last 3 budgets (-1: unbiased)")
    print(f"{'integrator':14s} " + " ".join(f"{f'{sc} ({targets[sc]:g})':>22s} {'slope':>6s} {'last relMSE':>11s}"
                                          for sc in scenes))
    print(f"{'':14s} " + " ".join(f"{'measured / fitted':>22s} {'':>6s} {'':>11s}" for sc in scenes))
    ratios = {}
    for n in integrators:
        cells = []
        for sc in scenes:
            r = [x for x in rows if x["scene"] == sc and x["integrator"] == n]
            rp = [x for x in rows if x["scene"] == sc and x["integrator"] == yardstick]
            if not r:
                cells.append(f"{'-':>22s} {'':6s} {'':11s}")
                continue
            pair = []
            for fn in (reach, reach_fitted):
                t, how = fn(r, targets[sc], n in UNBIASED, key)
                tp, how_p = fn(rp, targets[sc], True, key) if rp else (None, "")
                if tp is None:
                    pair.append(f"{yardstick}: n/r")
                elif t is None:
                    pair.append("not reached")
                else:
                    pair.append(f"{'~' if how or how_p else ''}{t / tp:.3g}")
            sl = slope([x["budget"] for x in r], [x["relmse"] for x in r])
            ratios[(sc, n)] = tuple(pair)
            cell = pair[0] if pair[0] == pair[1] == "not reached" else f"{pair[0]} / {pair[1]}"
            cells.append(f"{cell:>22s} {sl:6.2f} {r[-1]['relmse']:11.3e}")
        print(f"{n:14s} " + " ".join(cells))
    return ratios


def warn_bias(rows, scenes, integrators):
    """Warn where an unbiased integrator's error stops falling with the budget (only
    below relMSE 1: above, rare fireflies dominate single-image errors)."""
    for sc in scenes:
        for n in integrators:
            r = [x for x in rows if x["scene"] == sc and x["integrator"] == n]
            sl = slope([x["budget"] for x in r], [x["relmse"] for x in r])
            if n in UNBIASED and len(r) >= 3 and not sl < -0.6 and r[-1]["relmse"] < 1.0:
                print(f"WARNING: {n} on {sc}: relMSE stopped falling (slope {sl:.2f} over the last budgets, "
                      f"image mean / reference {r[-1]['mean_ratio']:.4f}); an unbiased estimator falls as "
                      f"1/budget: a bias?")


def main(argv=None):
    a = parse(argv)
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    print(f"load average at start: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f} on {os.cpu_count()} cores "
          f"(absolute times depend on the machine's load; integrators alternate at each budget)")
    if a.from_csv:
        rows = read_csv(a.from_csv)
        a.scenes = [s for s in a.scenes if any(r["scene"] == s for r in rows)]
        a.integrators = [n for n in a.integrators if any(r["integrator"] == n for r in rows)]
        print(f"rows from {a.from_csv} (no rendering)")
    else:
        pbr.set_backend(a.backend)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        print(f"bench_integrators: {a.res}x{a.res}, max_depth {a.max_depth}, budgets {a.budgets[0]}..{a.budgets[-1]} "
              f"(stop after a render > {a.max_time:g} s once {a.min_budgets} budgets are done), reference: pbr "
              f"path ({', '.join(f'{k}: {v}' for k, v in REFERENCE.items())}) {a.ref_spp} spp ({REF_BATCHES} batches; "
              f"radiosity: max_depth -1, {a.ref_spp // 2} spp), "
              f"backend {pbr.get_backend()}")
        report_skipped()
        for n in a.integrators:
            if n in BIASED:
                print(f"  {n:16s} {BIASED[n]}")
        rows, compile_s = run(a)
        print(f"\n{'scene':9s} {'integrator':14s} {'budget':>6s} {'time s':>8s} {'CPU s':>8s} {'relMSE':>10s} "
              f"{'raw':>10s} {'mean/ref':>8s}")
        for r in rows:
            print(f"{r['scene']:9s} {r['integrator']:14s} {r['budget']:6d} {r['time_s']:8.3f} {r['cpu_s']:8.3f} "
                  f"{r['relmse']:10.3e} {r['relmse_raw']:10.3e} {r['mean_ratio']:8.4f}")
        print("\ncompile seconds (Dr.Jit kernel history: warm-up at the smallest budget / all budgets; "
              "kernels found in ~/.drjit cost almost nothing):")
        for (sc, n), (c0, c) in compile_s.items():
            print(f"  {sc:9s} {n:14s} {c0:6.2f} / {c:6.2f}")

    targets = a.targets
    ratios = analyse(rows, a.scenes, a.integrators, targets)
    if all("cpu_s" in r for r in rows):
        ratios_cpu = analyse(rows, a.scenes, a.integrators, targets, key="cpu_s")
        ratios = {k: v + ratios_cpu[k] for k, v in ratios.items()}
    if "mlt" in a.integrators and "bdpt" in a.integrators:
        for key in ("time_s", "cpu_s") if all("cpu_s" in r for r in rows) else ("time_s",):
            analyse(rows, a.scenes, ["mlt"], targets, key=key, yardstick="bdpt")
    warn_bias(rows, a.scenes, a.integrators)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if not a.from_csv:
        csv_path = out / "bench_integrators.csv"
        with open(csv_path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        print(f"\nwrote {csv_path}")
    load1 = os.getloadavg()
    if not a.no_plot:
        how = (f"{a.res}x{a.res}, max_depth {a.max_depth}, {os.cpu_count()} shared cores, load "
               f"{load0[0]:.1f}-{load1[0]:.1f}" if not a.from_csv else f"replotted from {Path(a.from_csv).name}")
        p = plot(rows, a.targets, out / "bench_integrators.png",
                 f"pbr integrators: relMSE vs warm render time ({how}; dotted: target relMSE)")
        if p:
            print(f"wrote {p}")
    print(f"load average at end: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; "
          f"benchmark took {time.perf_counter() - t_start:.0f} s")
    return rows, ratios


if __name__ == "__main__":
    main()
