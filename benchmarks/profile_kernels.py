"""Where a render's time goes, pbr next to Mitsuba 3 on the same scene: the kernels each
launches (Dr.Jit's kernel history: operations, execution time, compile time), with
``--ir-dir`` their IR written out and, on CUDA with ``ptxas`` on the PATH, each PTX
kernel's registers, stack frame and spill bytes (on LLVM, the float vectors live across
each ray-tracing call: ``ir_liveness.py``); then pbr's time under changed Dr.Jit
flags (symbolic calls off, call optimisation off, ...), and the gallery with every
sphere diffuse (``gallery-diffuse``: the cost of mixing 16 BSDF families in one warp).
Run it where the time is lost: on CUDA the gallery took 4.8x Mitsuba's time on an H100
(README, "CUDA"), the Cornell box 1.07x.

Scenes are ``benchmarks/bench_scenes.py``'s (``--list`` there) plus ``gallery-diffuse``.

Per kernel the IR size (characters of LLVM IR / PTX) is printed, and the wall time is
split into kernel execution, Dr.Jit code generation and the rest (Python tracing of the
integrator, host work): ``trace ms``.

``--ablate``: attribution by ablation. Each named change is applied to the scene for
both renderers where both have it, and the time ratio changed/default (process CPU
time, interleaved pairs) is printed for pbr and Mitsuba: a part whose removal saves
more in pbr than in Mitsuba is where pbr loses time. Changes: ``uniform-lights``
(integrator ``light_sampler`` uniform: pbr only, Mitsuba always samples uniformly),
``constant-textures`` (every checkerboard replaced by its first colour),
``box-filter`` (film filter box instead of Gaussian), ``diffuse-only`` (every BSDF a
grey diffuse one: the cost of the scene's BSDF families and their dispatch),
``no-nee`` (``path`` without emitter sampling is not in Mitsuba: skipped),
``gathered-area-light`` (pbr only: a one-light scene's light tables gathered where
used instead of loaded before the path loop, which keeps them live across every trace).

``--freeze``: per-call time of ``pbr.render`` and of the same call under ``pbr.freeze``
(no Python tracing once recorded) next to ``mi.render``, at the scene's resolution.

    python benchmarks/profile_kernels.py --backend cuda --scenes gallery,gallery-diffuse --res 1024 --spp 64
    python benchmarks/profile_kernels.py --scenes cornell --flags=-SymbolicCalls,-OptimizeCalls --ir-dir out/ir
    python benchmarks/profile_kernels.py --scenes bsdf-diffuse,light-point --flags= --ablate all --freeze
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

from bench_scenes import scene_dicts, interleaved_cpu
from ir_liveness import trace_liveness
from pbr.scene.xml import to_xml


# Flags that change pbr's kernel without changing its result. Symbolic calls cannot be
# turned off inside pbr's symbolic loops (Dr.Jit keeps them symbolic), so they are not here.
DEFAULT_FLAGS = {"llvm": "-OptimizeCalls",
                 "cuda": "-OptimizeCalls,-ShaderExecutionReordering,-SpillToSharedMemory"}


def _walk(d, fn):
    """Apply fn(key, value) -> value to every (key, dict value) of a nested scene dict."""
    for k, v in list(d.items()):
        if isinstance(v, dict):
            d[k] = fn(k, v)
            if isinstance(d[k], dict):
                _walk(d[k], fn)
    return d


def _constant_textures(d):
    return _walk(d, lambda k, v: v.get("color0", 0.4) if v.get("type") == "checkerboard" else v)


def _box_filter(d):
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    return d


def _diffuse_only(d):
    grey = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}
    return _walk(d, lambda k, v: dict(grey) if k == "bsdf" or (k not in ("emitter", "sensor", "integrator", "film")
                                                              and v.get("type") in BSDF_TYPES) else v)


def _uniform_lights(d):
    d["integrator"] = dict(d["integrator"], light_sampler="uniform")
    return d


def _gathered_area_light(scene):
    """pbr only, on its loaded scene: a scene with one area light gets that light's tables
    twice (the same light, still light 0), so the kernel gathers its corners, normal and
    area where it samples the light instead of loading them once before the path loop:
    13 float vectors that are otherwise live across every trace (``ir_liveness.py``)."""
    a = scene.lights.families.get("area")
    if a is None or a.n_sub != 1:
        raise ValueError("not a scene with one area light")
    two = mi.UInt32(0, 0)

    def dup(x):
        if isinstance(x, list):
            return [dup(y) for y in x]
        if dr.is_array_v(x) and dr.width(x) == 1:
            return dr.gather(type(x), x, two)
        return x
    for k, v in list(vars(a).items()):
        vars(a)[k] = dup(v)
    return scene


# name -> (change to the dict, whether Mitsuba has it, change to pbr's loaded scene)
ABLATIONS = {"uniform-lights": (_uniform_lights, False, None), "constant-textures": (_constant_textures, True, None),
             "box-filter": (_box_filter, True, None), "diffuse-only": (_diffuse_only, True, None),
             "gathered-area-light": (lambda d: d, False, _gathered_area_light)}
BSDF_TYPES = ()


def _copy(d):
    """A copy of a scene dict deep in its dicts (transforms and arrays shared)."""
    return {k: _copy(v) if isinstance(v, dict) else v for k, v in d.items()}


def ablate(name, d, spp, reps, changes):
    """Print, for each change, pbr's and Mitsuba's time ratio changed/default."""
    def runners(dd, dm, scene_fn=None):
        sc, ms = pbr.load_dict(dd), mi.load_string(to_xml(dm))
        if scene_fn is not None:
            sc = scene_fn(sc)
        seed = [100]

        def rp():
            seed[0] += 1
            np.asarray(pbr.render(sc, spp=spp, seed=seed[0], progress=False))

        def rm():
            seed[0] += 1
            img = mi.render(ms, spp=spp, seed=seed[0])
            dr.eval(img)
            np.asarray(img)
        return rp, rm

    base_p, base_m = runners(d, d)
    for ch in changes:
        fn, in_mi, scene_fn = ABLATIONS[ch]
        try:
            alt = fn(_copy(d))
            alt_p, alt_m = runners(alt, alt if in_mi else d, scene_fn)
        except Exception as e:   # a change that does not apply to this scene
            print(f"  ablate {ch:18s} not applicable: {str(e).splitlines()[0][:120]}")
            continue
        *_, rp_wall, _, _, rp = interleaved_cpu(alt_p, base_p, reps)
        # kernel time too: on CUDA the process CPU time does not contain the GPU's work
        rk = np.median([kernel_ms(history(alt_p)[1]) / max(kernel_ms(history(base_p)[1]), 1e-9)
                        for _ in range(reps)])
        line = f"  ablate {ch:18s} pbr {rp:5.2f}x (wall {rp_wall:5.2f}x, kernels {rk:5.2f}x)"
        if in_mi:
            *_, rm_wall, _, _, rm = interleaved_cpu(alt_m, base_m, reps)
            line += f"   Mitsuba {rm:5.2f}x (wall {rm_wall:5.2f}x)"
        print(line, flush=True)


def freeze_calls(d, spp, reps):
    """Per-call wall and CPU time of pbr.render, pbr.freeze(pbr.render) and mi.render."""
    sc, ms = pbr.load_dict(d), mi.load_string(to_xml(d))
    frozen = pbr.freeze(lambda scene, seed: pbr.render(scene, spp=spp, seed=seed, progress=False,
                                                       on_nonfinite="ignore"))
    k = [0]

    def plain():
        k[0] += 1
        np.asarray(pbr.render(sc, spp=spp, seed=k[0], progress=False))

    def froz():
        k[0] += 1
        np.asarray(frozen(sc, dr.opaque(mi.UInt32, k[0])))

    def mits():
        k[0] += 1
        img = mi.render(ms, spp=spp, seed=k[0])
        dr.eval(img)
        np.asarray(img)

    froz()                           # record
    wf, wp, rw, cf, cp, rc = interleaved_cpu(froz, plain, reps)
    _, wm, rwm, _, cm, rcm = interleaved_cpu(plain, mits, reps)
    print(f"  freeze: pbr.render {wp * 1e3:8.1f} ms ({cp * 1e3:8.1f} cpu), frozen {wf * 1e3:8.1f} ms "
          f"({cf * 1e3:8.1f} cpu): frozen/plain {rw:.2f} wall, {rc:.2f} cpu; Mitsuba {wm * 1e3:8.1f} ms "
          f"({cm * 1e3:8.1f} cpu): plain/Mitsuba {rwm:.2f} wall, {rcm:.2f} cpu", flush=True)


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
    """Registers / stack / spills of a PTX file by ptxas -v, or why not. OptiX kernels call
    OptiX's intrinsics (``_optix_trace_*``), unresolved here, so they are compiled one
    function at a time (``-c``), which refuses Dr.Jit's ``.pragma "enable_smem_spilling"``
    (spills to shared memory; measured on an H200: "not allowed for per-function
    compilation modes"): that line is left out, so the spill figures are those without it."""
    exe = shutil.which("ptxas")
    if not exe:
        return "no ptxas"
    with open(path) as f:
        ptx = f.read()
    note = ""
    if "enable_smem_spilling" in ptx:
        path = path + ".nosmem.ptx"
        with open(path, "w") as f:
            f.write("".join(line for line in ptx.splitlines(True) if "enable_smem_spilling" not in line))
        note = " (without enable_smem_spilling)"
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
    return out + note


def kernel_ms(h: list) -> float:
    """Execution time of the JIT kernels of a kernel history, ms."""
    return sum(k.get("execution_time", 0.0) for k in h if k["type"] == dr.KernelType.JIT)


def report(name: str, who: str, t: float, h: list, ir_dir: str | None, run_ms: float | None = None):
    """One renderer's line: median wall time ``t`` (s), kernel time ``run_ms`` (median; by
    default that of ``h``), and the kernels of history ``h``."""
    jit = [k for k in h if k["type"] == dr.KernelType.JIT]
    other = len(h) - len(jit)
    run_ms = kernel_ms(h) if run_ms is None else run_ms
    gen_ms = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in jit)
    other_ms = sum(k.get("execution_time", 0.0) for k in h if k["type"] != dr.KernelType.JIT)
    print(f"  {who:8s} {t * 1e3:9.1f} ms wall, {len(jit)} JIT kernels ({run_ms:.1f} ms running, "
          f"{gen_ms:.1f} ms IR generation and compilation, {sum(bool(k.get('cache_hit')) for k in jit)} cached), {other} other operations ({other_ms:.1f} ms); "
          f"trace and host {t * 1e3 - run_ms - gen_ms - other_ms:.1f} ms")
    for i, k in enumerate(sorted(jit, key=lambda k: -k.get("execution_time", 0.0))[:4]):
        line = (f"    kernel {i}: {k.get('operation_count', 0):6d} ops, size {k.get('size', 0):9d}, "
                f"{k.get('execution_time', 0.0):8.2f} ms, IR {len(k['ir'].getvalue()) if 'ir' in k else 0:8d} chars, "
                f"optix {bool(k.get('uses_optix'))}")
        if ir_dir and "ir" in k:
            ext = "ptx" if pbr.get_backend() == "cuda" else "ll"
            path = os.path.join(ir_dir, f"{name}_{who}_{i}.{ext}")
            with open(path, "w") as f:
                f.write(k["ir"].getvalue())
            line += f", IR -> {path}"
            if ext == "ptx":
                line += f"; {ptxas_info(path)}"
        if "ir" in k and pbr.get_backend() == "llvm":
            live = trace_liveness(k["ir"].getvalue())
            if live:
                line += "; float vectors (+ uniform vectors) live across " + ", ".join(
                    f"{t.kind} {t.live['float']} (+{t.live['uniform float']})" for t in live)
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
    ap.add_argument("--ablate", default="", help=f"comma-separated changes or 'all' ({', '.join(ABLATIONS)})")
    ap.add_argument("--freeze", action="store_true", help="time pbr.render under pbr.freeze too")
    ap.add_argument("--no-kernels", action="store_true", help="skip the kernel report")
    a = ap.parse_args(argv)
    global BSDF_TYPES
    from pbr.bsdfs import bsdf_names
    BSDF_TYPES = tuple(bsdf_names())
    changes = list(ABLATIONS) if a.ablate == "all" else [c for c in a.ablate.split(",") if c]
    pbr.set_backend(a.backend)
    if a.flags is None:
        a.flags = DEFAULT_FLAGS[pbr.get_backend()]
    if a.ir_dir:
        os.makedirs(a.ir_dir, exist_ok=True)
    dicts = scenes(a.res, a.spp)
    print(f"backend {pbr.get_backend()}, {a.res} wide, {a.spp} spp; times are medians of {a.reps}; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    for name in a.scenes.split(","):
        d = dicts[name]
        scene, mscene = pbr.load_dict(d), mi.load_string(to_xml(d))

        def run_pbr(seed=1):
            np.asarray(pbr.render(scene, spp=a.spp, seed=seed, progress=False))

        def run_mi(seed=1):
            img = mi.render(mscene, spp=a.spp, seed=seed)
            dr.eval(img)
            np.asarray(img)

        print(f"{name}:", flush=True)
        if changes:
            ablate(name, d, a.spp, a.reps, changes)
        if a.freeze:
            try:
                freeze_calls(d, a.spp, a.reps)
            except RuntimeError as e:   # e.g. the gallery: a virtual call Dr.Jit cannot record
                print(f"  freeze: recording failed: {str(e).splitlines()[0][:200]}")
        if a.no_kernels:
            continue
        run_pbr(0), run_mi(0)                                   # compile
        hs = {"pbr": [], "mitsuba": []}
        for k in range(a.reps):                                 # interleaved
            for who, fn in (("pbr", run_pbr), ("mitsuba", run_mi)):
                hs[who].append(history(lambda: fn(k + 2)))
        for who, runs in hs.items():
            walls, kms = [t for t, _ in runs], [kernel_ms(h) for _, h in runs]
            report(name, who, float(np.median(walls)), runs[int(np.argsort(kms)[len(kms) // 2])][1], a.ir_dir,
                   float(np.median(kms)))
        kr = np.median([kernel_ms(hp) / max(kernel_ms(hm), 1e-9) for (_, hp), (_, hm) in zip(hs["pbr"], hs["mitsuba"])])
        wr = np.median([tp / tm for (tp, _), (tm, _) in zip(hs["pbr"], hs["mitsuba"])])
        print(f"  pbr/Mitsuba: kernels {kr:.2f}, wall {wr:.2f} (medians of {a.reps} pairs)", flush=True)
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
