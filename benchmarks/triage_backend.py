"""Triage of a backend (written for CUDA): small renders, each in its own process.

Each case renders a 32x32 Cornell box (a diffuse and a plastic block, box filter) with
one integrator configuration on ``--backend``, in a child process, so that a crash of
Dr.Jit (an abort: ``Critical Dr.Jit compiler failure``, an OptiX pipeline error, an
illegal address) ends that case only. Reported per case: the exit code, Dr.Jit's own
failure message, the image mean and Mitsuba's (same variant and scene) where Mitsuba has
the integrator, the first render's time (kernel compilation included, from
``dr.kernel_history``) and a warm render's time.

The cases bisect the aborts that ``direct`` and ``whitted`` showed on an H100 (issue 15):
with and without ``hide_emitters`` (a symbolic loop that re-traces camera rays through
emitters, with a SurfaceInteraction in its state), light or BSDF samples only, whitted's
depth levels, and ``path`` as the control. ``--flags`` reruns the cases with Dr.Jit flags
changed (``-Name`` turns a default flag off, ``Name`` on), e.g. ``LaunchBlocking`` to make
the failing kernel report at its launch, ``-SymbolicLoops`` (loops evaluated kernel by
kernel), ``-ShaderExecutionReordering``, ``-SpillToSharedMemory``, ``-OptimizeCalls``.

    python benchmarks/triage_backend.py --backend cuda
    python benchmarks/triage_backend.py --backend cuda --cases direct,whitted --flags all
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time

CASES = {
    "path": {"type": "path", "max_depth": 6, "hide_emitters": True},
    "direct": {"type": "direct", "hide_emitters": True},
    "direct-visible": {"type": "direct", "hide_emitters": False},
    "direct-lights-only": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
    "direct-bsdf-only": {"type": "direct", "emitter_samples": 0, "bsdf_samples": 1},
    "whitted": {"type": "whitted", "hide_emitters": True},
    "whitted-visible": {"type": "whitted", "hide_emitters": False},
    "whitted-depth1": {"type": "whitted", "max_depth": 1},
    "whitted-depth2": {"type": "whitted", "max_depth": 2},
}
MITSUBA_HAS = ("path", "direct")
FLAG_SETS = ["LaunchBlocking", "-SymbolicLoops", "-SymbolicCalls", "-OptimizeCalls", "-MergeFunctions",
             "-ShaderExecutionReordering", "-SpillToSharedMemory", "-PacketOps", "-ScatterReduceLocal"]


def scene_dict(case: str, res: int, spp: int) -> dict:
    import pbr
    d = pbr.cornell_box(res, spp)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["small-box"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}}
    d["large-box"]["bsdf"] = {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}
    d["integrator"] = dict(CASES[case])
    return d


def child(a) -> None:
    import numpy as np
    import pbr
    import drjit as dr
    import mitsuba as mi
    pbr.set_backend(a.backend)
    for f in filter(None, a.flag.split(",")):
        dr.set_flag(getattr(dr.JitFlag, f.lstrip("-")), not f.startswith("-"))
    d = scene_dict(a.child, a.res, a.spp)
    out = {}
    scene = pbr.load_dict(d)
    dr.kernel_history()                                   # clear
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    t = time.perf_counter()
    img = np.asarray(pbr.render(scene, seed=0))
    out["first_s"] = time.perf_counter() - t
    hist = dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    jit = [k for k in hist if k["type"] == dr.KernelType.JIT]
    out["kernels"] = len(jit)
    out["compile_s"] = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in jit) / 1000
    t = time.perf_counter()
    img2 = np.asarray(pbr.render(scene, seed=1))
    out["warm_s"] = time.perf_counter() - t
    out["mean"] = float(0.5 * (img.mean() + img2.mean()))
    out["finite"] = bool(np.isfinite(img).all() and np.isfinite(img2).all())
    if d["integrator"]["type"] in MITSUBA_HAS:
        from pbr import validate
        ref = validate.mitsuba_render_fn(d)
        out["mitsuba_mean"] = float(0.5 * (ref(seed=0, spp=a.spp).mean() + ref(seed=1, spp=a.spp).mean()))
    out["variant"] = mi.variant()
    print("RESULT " + json.dumps(out), flush=True)


def run_case(a, case: str, flag: str) -> dict:
    args = [sys.executable, os.path.abspath(__file__), "--child", case, f"--flag={flag}", "--backend", a.backend,
            "--res", str(a.res), "--spp", str(a.spp)]
    t = time.perf_counter()
    try:
        p = subprocess.run(args, capture_output=True, text=True, timeout=a.timeout)
    except subprocess.TimeoutExpired:
        return {"case": case, "flag": flag, "status": f"timeout after {a.timeout} s"}
    r = {"case": case, "flag": flag, "rc": p.returncode, "wall_s": time.perf_counter() - t}
    for line in p.stdout.splitlines():
        if line.startswith("RESULT "):
            r.update(json.loads(line[7:]))
            r["status"] = "ok"
            return r
    lines = [ln.strip() for ln in (p.stderr + p.stdout).splitlines() if ln.strip()]
    # Dr.Jit's own failure first, else the Python exception (the traceback's last line).
    fatal = [ln for ln in lines if any(k in ln for k in ("Critical Dr.Jit", "jit_optix", "cuda_check", "Fatal Python"))]
    raised = [ln for ln in lines if re.match(r"[\w.]*(Error|Exception)\b.*:", ln)]
    r["status"] = "crashed" if p.returncode < 0 else "error"
    r["message"] = (fatal[:1] or raised[-1:] or lines[-1:] or ["no output"])[0][:300]
    r["log_tail"] = "\n".join(lines[-40:])
    return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="llvm", help="llvm, cuda or auto")
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, from {', '.join(CASES)}")
    ap.add_argument("--flags", default="", help=f"comma-separated; 'all' = {', '.join(FLAG_SETS)}")
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--timeout", type=int, default=300, help="seconds per case")
    ap.add_argument("--out", default=None, help="write the results (JSON) here")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--flag", default="", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        return child(a)
    cases = [c for c in a.cases.split(",") if c]
    bad = [c for c in cases if c not in CASES]
    if bad:
        ap.error(f"unknown case(s) {bad}; known: {', '.join(CASES)}")
    flags = [""]
    for f in filter(None, a.flags.split(",")):
        flags += FLAG_SETS if f == "all" else [f]
    results = []
    print(f"backend {a.backend}, {a.res}x{a.res}, {a.spp} spp")
    for flag in flags:
        for case in cases:
            r = run_case(a, case, flag)
            results.append(r)
            ratio = (f"{r['mean'] / r['mitsuba_mean']:.3f}" if r.get("mitsuba_mean") else "-") if "mean" in r else "-"
            what = (f"mean {r['mean']:.4f} (/Mitsuba {ratio}), first {r['first_s']:.2f} s "
                    f"({r['kernels']} kernels, compile {r['compile_s']:.2f} s), warm {r['warm_s']:.3f} s"
                    if r["status"] == "ok" else f"rc {r.get('rc')}: {r.get('message', '')}")
            print(f"  {case:20s} {flag or 'default':28s} {r['status']:8s} {what}", flush=True)
    if a.out:
        with open(a.out, "w") as f:
            json.dump(results, f, indent=1)
    return results


if __name__ == "__main__":
    main()
