"""Where a render's time goes, pbr next to Mitsuba 3 on the same scene: the kernels each
launches (Dr.Jit's kernel history: operations, execution time, compile time), with
``--ir-dir`` their IR written out and, on CUDA with ``ptxas`` on the PATH, each PTX
kernel's registers, stack frame and spill bytes; then pbr's time under changed Dr.Jit
flags (symbolic calls off, call optimisation off, ...), and the gallery with every
sphere diffuse (``gallery-diffuse``: the cost of mixing 16 BSDF families in one warp).
Run it where the time is lost: on CUDA the gallery took 4.8x Mitsuba's time on an H100
(README, "CUDA"), the Cornell box 1.07x.

Scenes are ``benchmarks/bench_scenes.py``'s (``cornell``, ``cornell-glossy``, ``gallery``,
``caustic``, ``door``) plus ``gallery-diffuse``.

    python benchmarks/profile_kernels.py --backend cuda --scenes gallery,gallery-diffuse --res 1024 --spp 64
    python benchmarks/profile_kernels.py --scenes cornell --flags=-SymbolicCalls,-OptimizeCalls --ir-dir out/ir
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import time

import numpy as np

import pbr
import drjit as dr
import mitsuba as mi

from bench_scenes import scene_dicts
from pbr.scene.xml import to_xml


# Flags that change pbr's kernel without changing its result. Symbolic calls cannot be
# turned off inside pbr's symbolic loops (Dr.Jit keeps them symbolic), so they are not here.
DEFAULT_FLAGS = {"llvm": "-OptimizeCalls",
                 "cuda": "-OptimizeCalls,-ShaderExecutionReordering,-SpillToSharedMemory"}


def scenes(res: int, spp: int) -> dict:
    out = scene_dicts(res, spp)
    d = {k: v for k, v in out["gallery"].items()}
    for k in d:
        if k.startswith("sphere-"):
            d[k] = dict(d[k], bsdf={"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}})
    out["gallery-diffuse"] = d
    return out


def history(fn) -> tuple[float, list]:
    """Wall time of fn() and the kernels it launched."""
    dr.kernel_history()                                    # clear
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    t = time.perf_counter()
    fn()
    t = time.perf_counter() - t
    h = dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    return t, h


def ptxas_info(path: str) -> str:
    """Registers / stack / spills of a PTX file by ptxas -v (compile only), or why not."""
    exe = shutil.which("ptxas")
    if not exe:
        return "no ptxas"
    p = subprocess.run([exe, "-arch=sm_90", "-v", "-c", path, "-o", os.devnull], capture_output=True, text=True)
    log = p.stderr + p.stdout
    regs = re.findall(r"Used (\d+) registers", log)
    spill = re.findall(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", log)
    if p.returncode != 0 or not regs:
        return "ptxas: " + (log.strip().splitlines() or ["no output"])[-1][:160]
    out = f"registers max {max(map(int, regs))} over {len(regs)} functions"
    if spill:
        st = max(int(s[0]) for s in spill)
        sp = sum(int(s[1]) + int(s[2]) for s in spill)
        out += f", stack frame max {st} B, spill stores+loads {sp} B"
    return out


def report(name: str, who: str, t: float, h: list, ir_dir: str | None):
    jit = [k for k in h if k["type"] == dr.KernelType.JIT]
    other = len(h) - len(jit)
    run_ms = sum(k.get("execution_time", 0.0) for k in jit)
    print(f"  {who:8s} {t * 1e3:9.1f} ms wall, {len(jit)} JIT kernels ({run_ms:.1f} ms running), "
          f"{other} other operations (memcpy/memset/reductions)")
    for i, k in enumerate(sorted(jit, key=lambda k: -k.get("execution_time", 0.0))[:4]):
        line = (f"    kernel {i}: {k.get('operation_count', 0):6d} ops, size {k.get('size', 0):9d}, "
                f"{k.get('execution_time', 0.0):8.2f} ms, optix {bool(k.get('uses_optix'))}")
        if ir_dir and "ir" in k:
            ext = "ptx" if pbr.get_backend() == "cuda" else "ll"
            path = os.path.join(ir_dir, f"{name}_{who}_{i}.{ext}")
            with open(path, "w") as f:
                f.write(k["ir"].getvalue())
            line += f", IR -> {path}"
            if ext == "ptx":
                line += f"; {ptxas_info(path)}"
        print(line)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--scenes", default="cornell,gallery,gallery-diffuse")
    ap.add_argument("--flags", default=None,
                    help="Dr.Jit flags to turn off (-Name) or on (Name) one at a time for pbr; '' for none "
                         f"(default: {DEFAULT_FLAGS})")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--ir-dir", default=None, help="write the 4 slowest kernels' IR (and ptxas figures) here")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    if a.flags is None:
        a.flags = DEFAULT_FLAGS[pbr.get_backend()]
    if a.ir_dir:
        os.makedirs(a.ir_dir, exist_ok=True)
    dicts = scenes(a.res, a.spp)
    print(f"backend {pbr.get_backend()}, {a.res} wide, {a.spp} spp; times are medians of {a.reps}")
    for name in a.scenes.split(","):
        d = dicts[name]
        scene, mscene = pbr.load_dict(d), mi.load_string(to_xml(d))

        def run_pbr(seed=1):
            np.asarray(pbr.render(scene, spp=a.spp, seed=seed, progress=False))

        def run_mi(seed=1):
            img = mi.render(mscene, spp=a.spp, seed=seed)
            dr.eval(img)
            np.asarray(img)

        print(f"{name}:")
        for who, fn in (("pbr", run_pbr), ("mitsuba", run_mi)):
            fn(0)                                               # compile
            t, h = history(fn)
            t = float(np.median([t] + [history(lambda: fn(k + 2))[0] for k in range(a.reps - 1)]))
            report(name, who, t, h, a.ir_dir)
        base = float(np.median([history(lambda: run_pbr(k + 9))[0] for k in range(a.reps)]))
        for flag in filter(None, a.flags.split(",")):
            f = getattr(dr.JitFlag, flag.lstrip("-"))
            old = dr.flag(f)
            dr.set_flag(f, not flag.startswith("-"))
            try:
                run_pbr(0)
                t = float(np.median([history(lambda: run_pbr(k + 20))[0] for k in range(a.reps)]))
                print(f"  pbr with {flag:24s} {t * 1e3:9.1f} ms ({t / base:.2f}x the default's {base * 1e3:.1f} ms)")
            except Exception as e:   # a flag Dr.Jit rejects for this kernel: report it, go on
                print(f"  pbr with {flag:24s} failed: {str(e).splitlines()[0][:160]}")
            finally:
                dr.set_flag(f, old)


if __name__ == "__main__":
    main()
