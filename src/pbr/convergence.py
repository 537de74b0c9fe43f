"""Error vs time as an API: ``pbr.convergence`` renders a scene with several
integrators and samplers at doubling spp and measures each image's relMSE against a
reference, and the warm render time (kernel compilation subtracted).

    table = pbr.convergence(pbr.cornell_box(64), integrators=["path", "bdpt"],
                            samplers=[{"type": "independent"}], budget=5.0)
    table.plot()                    # relMSE vs time, log-log (matplotlib)
    table.time_to(0.01)             # seconds each configuration needs for relMSE 0.01

``relMSE = mean over pixels and channels of (x - r)^2 / (r^2 + eps)`` (``pbr.validate.
relative_mse``); a reference rendered here (or a ``pbr.validate.Estimate``) also gives
its own noise's share of that error, which is subtracted (column ``relmse``;
``relmse_raw`` keeps it). The helpers (``timed_render``, ``time_to_reach``, ``slope``)
are those of ``benchmarks/bench_integrators.py``.
"""

from __future__ import annotations

import copy
import math
import time

import drjit as dr
import numpy as np

from . import validate
from .plotting import pyplot

RELMSE_EPS = 1e-2


def timed_render(scene, spp, seed, repeat_below=0.2, repeats=5, **kw):
    """(image float64, warm wall seconds, warm CPU seconds, compile seconds): the wall
    and process CPU time of one ``pbr.render``, minus the kernel compilation Dr.Jit's
    kernel history reports for it. Renders shorter than ``repeat_below`` seconds are
    timed ``repeats`` times (same seed, warm) and the medians kept: at that length the
    load of other jobs makes single timings jumpy. ``kw`` goes to ``pbr.render``."""
    from .render import render
    walls, cpus, comp, img = [], [], 0.0, None
    flag = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for _ in range(repeats):
            dr.kernel_history()                              # clear
            t, c0 = time.perf_counter(), time.process_time()
            out = np.asarray(render(scene, spp=spp, seed=seed, progress=False, **kw), dtype=np.float64)
            wall, cpu = time.perf_counter() - t, time.process_time() - c0
            c = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in dr.kernel_history()) / 1000.0
            img = out if img is None else img
            comp += c
            walls.append(max(wall - c, 0.0))
            cpus.append(max(cpu - c, 0.0))
            if walls[0] >= repeat_below:
                break
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, flag)
    return img, float(np.median(walls)), float(np.median(cpus)), comp


def time_to_reach(times, errors, target):
    """Seconds at which a curve first reaches ``target`` (log-log interpolation between
    the points around the crossing); None if it never does."""
    prev = None
    for t, e in zip(times, errors):
        if e <= target:
            if prev is None or prev[1] <= 0 or e <= 0 or prev[0] <= 0 or t <= 0:
                return t
            (t0, e0), lt = prev, math.log(target)
            w = (math.log(e0) - lt) / (math.log(e0) - math.log(e))
            return math.exp(math.log(t0) + w * (math.log(t) - math.log(t0)))
        prev = (t, e)
    return None


def slope(budgets, errors, last=3):
    """Least-squares slope of log error vs log budget over the last ``last`` points (-1
    for relMSE of an unbiased estimator; toward 0 where a bias dominates)."""
    pts = [(math.log(b), math.log(e)) for b, e in zip(budgets, errors) if e > 0][-last:]
    if len(pts) < 2:
        return float("nan")
    x, y = np.array(pts).T
    return float(np.polyfit(x, y, 1)[0])


def reference_floor(ref, var, eps=RELMSE_EPS) -> float:
    """The share of a reference's own noise (``var``: the variance of its mean) in the
    expected relMSE of an independent image against it: mean(var / (ref^2 + eps))."""
    return float(np.mean(np.asarray(var) / (np.asarray(ref) ** 2 + eps)))


class ConvergenceTable:
    """Rows (dicts) of :func:`convergence`: ``label``, ``integrator``, ``sampler``,
    ``spp``, ``time_s`` (warm wall seconds), ``cpu_s``, ``relmse``, ``relmse_raw``,
    ``ref_floor``, ``mean_ratio`` (image mean / reference mean). Tables add (``+``)."""

    def __init__(self, rows=()):
        self.rows = list(rows)

    def __iter__(self):
        return iter(self.rows)

    def __len__(self):
        return len(self.rows)

    def __getitem__(self, i):
        return self.rows[i]

    def __add__(self, other):
        return ConvergenceTable(self.rows + list(other))

    def labels(self):
        return list(dict.fromkeys(r["label"] for r in self.rows))

    def curve(self, label):
        """The rows of one configuration, by spp."""
        return sorted((r for r in self.rows if r["label"] == label), key=lambda r: r["spp"])

    def time_to(self, target, key="time_s"):
        """{label: seconds to reach relMSE ``target``} (log-log interpolation on the
        measured curve; None where a curve does not reach it)."""
        return {lb: time_to_reach([r[key] for r in c], [r["relmse"] for r in c], target)
                for lb, c in ((lb, self.curve(lb)) for lb in self.labels())}

    def spp_to(self, target):
        """{label: spp at which relMSE reaches ``target``} (interpolated; None: not reached)."""
        return {lb: time_to_reach([r["spp"] for r in c], [r["relmse"] for r in c], target)
                for lb, c in ((lb, self.curve(lb)) for lb in self.labels())}

    def slopes(self):
        """{label: d log relMSE / d log spp over the last 3 points} (-1: unbiased)."""
        return {lb: slope([r["spp"] for r in c], [r["relmse"] for r in c]) for lb, c in
                ((lb, self.curve(lb)) for lb in self.labels())}

    def __repr__(self):
        head = f"{'label':32s} {'spp':>6s} {'time s':>8s} {'relMSE':>10s} {'mean/ref':>8s}"
        lines = [head] + [f"{r['label'][:32]:32s} {r['spp']:6d} {r['time_s']:8.3f} {r['relmse']:10.3e} "
                          f"{r['mean_ratio']:8.4f}" for r in self.rows]
        return "\n".join(lines)

    def plot(self, ax=None, x="time_s", target=None, title=None):
        """relMSE vs ``x`` ('time_s', 'cpu_s' or 'spp'), log-log, one line per
        configuration (``target``: a dotted line). Returns the matplotlib Axes (None
        without matplotlib)."""
        plt = pyplot()
        if plt is None:
            return None
        if ax is None:
            _, ax = plt.subplots(figsize=(6.5, 4.5))
        for lb in self.labels():
            c = [r for r in self.curve(lb) if r["relmse"] > 0]
            ax.loglog([r[x] for r in c], [r["relmse"] for r in c], marker="o", ms=3, label=lb)
        if target is not None:
            ax.axhline(target, color="0.5", lw=0.8, ls=":")
        ax.set_xlabel({"time_s": "render time (s, warm)", "cpu_s": "CPU time (s)", "spp": "samples per pixel"}
                      .get(x, x))
        ax.set_ylabel("relMSE vs reference")
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=8)
        if title:
            ax.set_title(title)
        return ax


def _named(kind, v):
    """An integrator or sampler dict from a dict or a type name."""
    if isinstance(v, str):
        return {"type": v}
    if isinstance(v, dict) and isinstance(v.get("type"), str):
        return dict(v)
    raise TypeError(f"convergence: {kind}: expected a type name or a dict with a 'type', got {v!r}")


def _configs(kind, v, default):
    """{label: dict} of the configurations given as a name, a dict, a list of them, or a
    {label: name or dict} mapping (None: ``default``)."""
    if v is None:
        v = [default]
    if isinstance(v, str) or (isinstance(v, dict) and "type" in v):
        v = [v]
    if isinstance(v, dict):
        return {str(k): _named(kind, x) for k, x in v.items()}
    out = {}
    for x in v:
        d = _named(kind, x)
        out[_label(d)] = d
    if not out:
        raise ValueError(f"convergence: {kind}: empty")
    return out


def _label(d):
    extra = ", ".join(f"{k}={v}" for k, v in d.items() if k not in ("type", "sample_count"))
    return d["type"] + (f" ({extra})" if extra else "")


def convergence(scene, integrators=None, samplers=None, reference=None, budget=10.0, spp=None, max_spp=4096,
                reference_spp=None, reference_integrator=None, seed=0, reps=1, eps=RELMSE_EPS, progress=False):
    """relMSE vs time and spp of each (integrator, sampler) on ``scene`` (a scene dict:
    ``pbr.cornell_box()``, ``pbr.scenes.*``, or a dict of your own).

    ``integrators``: integrator dicts or type names (default: the scene's), or a dict
    {label: integrator dict}. ``samplers``: sampler dicts (Mitsuba's, e.g.
    ``{'type': 'independent'}``; ``sample_count`` is set to each spp) put in the
    sensor's ``sampler`` entry (default: the scene's), or {label: sampler dict}.
    ``reference``: an image (H, W, 3), a ``pbr.validate.Estimate``, or None: rendered
    here with ``reference_integrator`` (default: the first integrator) at
    ``reference_spp`` (default 16x the largest spp reached) in 16 batches.
    ``spp``: the spp to render (default doubling from 4 to ``max_spp`` while a
    configuration's renders together take less than ``budget`` seconds). ``reps``:
    independent images (other seeds) per spp, their relMSE and time averaged (a single
    image's relMSE jumps between spp on small images and heavy-tailed scenes).
    Returns a :class:`ConvergenceTable`."""
    from .scene import load_dict
    if not isinstance(scene, dict):
        raise TypeError("convergence: scene must be a scene dict (its sensor's sampler and its integrator "
                        f"are replaced), got {type(scene).__name__}")
    sensor = scene.get("sensor")
    if not isinstance(sensor, dict):
        raise ValueError("convergence: scene['sensor'] must be a sensor dict")
    integ = _configs("integrators", integrators, scene.get("integrator", {"type": "path"}))
    samp = _configs("samplers", samplers, sensor.get("sampler", {"type": "independent"}))
    if isinstance(reps, bool) or not isinstance(reps, int) or reps < 1:
        raise ValueError(f"convergence: reps must be a positive integer, got {reps!r}")
    if not isinstance(budget, (int, float)) or budget <= 0:
        raise ValueError(f"convergence: budget must be a positive number of seconds, got {budget!r}")
    spps = list(spp) if spp is not None else [1 << k for k in range(2, int(math.log2(max_spp)) + 1)]
    if any(not isinstance(s, int) or s < 1 for s in spps):
        raise ValueError(f"convergence: spp must be positive integers, got {spps!r}")

    def scene_with(i, s, n):
        d = copy.copy(scene)
        d["sensor"] = dict(sensor)
        d["sensor"]["sampler"] = dict(s, sample_count=n)
        d["integrator"] = i
        return load_dict(d)

    # Render every configuration at doubling spp (the budget bounds each curve's total time).
    runs = []
    for ilabel, i in integ.items():
        for slabel, s in samp.items():
            label = ilabel if len(samp) == 1 else f"{ilabel} / {slabel}"
            total = 0.0
            for k, n in enumerate(spps):
                sc = scene_with(i, s, n)
                out = [timed_render(sc, n, seed=seed + 1 + k + 7919 * j) for j in range(reps)]
                wall, cpu = float(np.mean([o[1] for o in out])), float(np.mean([o[2] for o in out]))
                runs.append({"label": label, "integrator": ilabel, "sampler": slabel, "spp": n, "time_s": wall,
                             "cpu_s": cpu, "images": [o[0] for o in out]})
                total += wall * reps
                if spp is None and total + 2 * wall > budget:
                    break
    # The reference.
    floor = 0.0
    if reference is None:
        n_ref = reference_spp or 16 * max(r["spp"] for r in runs)
        if not isinstance(n_ref, int) or n_ref < 16:
            raise ValueError(f"convergence: reference_spp must be an integer >= 16, got {n_ref!r}")
        n_ref = max(16, n_ref - n_ref % 16)
        ri = _named("reference_integrator", reference_integrator) if reference_integrator else next(iter(integ.values()))
        from .render import render
        ref_scene = scene_with(ri, next(iter(samp.values())), n_ref)
        reference = validate.estimate(lambda seed, spp: render(ref_scene, seed=seed, spp=spp, progress=progress),
                                      n_ref, batches=16, seed=seed + 7)
    if isinstance(reference, validate.Estimate):
        ref, var = reference.mean, reference.var
        floor = reference_floor(ref, var, eps)
    else:
        ref = np.asarray(reference, np.float64)
    rows = []
    for r in runs:
        imgs = r.pop("images")
        if imgs[0].shape != ref.shape:
            raise ValueError(f"convergence: the reference is {ref.shape}, the images {imgs[0].shape}")
        raw = float(np.mean([validate.relative_mse(img, ref, eps) for img in imgs]))
        mean = float(np.mean([img.mean() for img in imgs]))
        rows.append({**r, "relmse": raw - floor, "relmse_raw": raw, "ref_floor": floor,
                     "mean_ratio": mean / ref.mean() if ref.mean() else float("nan")})
    table = ConvergenceTable(rows)
    table.reference = ref
    return table
