"""One inverse-rendering iteration (render + backward + Adam step + clamp + parameter
update) in pbr vs Mitsuba 3's ``prb``, on the same scene, spp and process.

The scene is the albedo-texture example's (Cornell box, back wall with an RGB bitmap;
examples/optimize_albedo_texture.py), on ``--backend`` (``llvm`` default, or ``cuda``)
with Mitsuba's variant of the same backend (``{llvm,cuda}_ad_spectral``). The
parameter (``--param``) is the bitmap's texels (``texture``, default) or the red wall's
RGB albedo (``albedo``, ``red.reflectance.value``). Reported per renderer, after
``--warmup`` iterations:

* time: median wall time of an iteration over ``--reps`` interleaved pairs;
* peak memory: Dr.Jit's allocator watermark (``dr.detail.malloc_watermark``, reset before
  the iteration: memory Dr.Jit allocates for kernels and arrays; NumPy buffers mapped
  into Dr.Jit and Embree's BVH are not included), and the process's peak resident set
  (VmHWM; a whole-process maximum, so pbr and Mitsuba are run in one child process each
  for it, including loading and the reference render, at the same spp);
* kernel launches and kernel-cache misses per iteration (``dr.detail.launch_stats``);
* ``dr.freeze`` of the whole step (forward + backward + update, since gradients do not
  cross a frozen boundary): per-iteration time when it works, else the error. Each
  freeze attempt runs in a child process (a failing recording may abort the process).

    python benchmarks/bench_optim.py [--res 64] [--spp 16] [--texels 16] [--param texture] [--reps 7]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "examples"))

import pbr  # noqa: E402  (first: it chooses the libLLVM Dr.Jit loads)
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
from pbr.validate import mitsuba_variant  # noqa: E402

import optimize_albedo_texture as example  # noqa: E402

KEYS = {"texture": example.KEY, "albedo": "red.reflectance.value"}
LR = 0.02


def _scene_dict(a, integrator: str) -> dict:
    d = example.scene_dict(a.texels, a.res, a.spp)
    d["integrator"] = dict(d["integrator"], type=integrator)
    return d


class Optimisation:
    """One renderer's optimisation state: scene, parameters, Adam, reference image."""

    def __init__(self, renderer: str, integrator: str, a):
        self.renderer, self.spp = renderer, a.spp
        d = _scene_dict(a, integrator)
        if renderer == "pbr":
            self.scene = pbr.load_dict(d)
            self._traverse = pbr.traverse
            self._render = lambda scene, params, seed, seed_grad: pbr.render(
                scene, params, spp=self.spp, seed=seed, seed_grad=seed_grad, progress=False)
            ref = pbr.render(self.scene, spp=a.spp, seed=1 << 20)
        else:
            mitsuba_variant()
            self.scene = mi.load_dict(d)
            self._traverse = mi.traverse
            self._render = lambda scene, params, seed, seed_grad: mi.render(
                scene, params, spp=self.spp, seed=seed, seed_grad=seed_grad)
            ref = mi.render(self.scene, spp=a.spp, seed=1 << 20)
        self.params = self._traverse(self.scene)
        self.ref = mi.TensorXf(np.asarray(ref))
        self.opt = dr.opt.Adam(lr=LR)
        self.key = KEYS[a.param]
        self.params[self.key] = (mi.TensorXf(example.initial_texture(a.texels)) if a.param == "texture"
                                 else mi.Color3f(0.4, 0.3, 0.2))
        self.opt[self.key] = self.params[self.key]
        self.params.update(self.opt)
        self.it = 0

    def step(self, scene, opt, ref, seed, seed_grad):
        """One iteration on explicit state (``dr.freeze`` sees only its arguments):
        apply the optimiser's values, render, backpropagate the loss, step, clamp.
        Returns the loss (a Dr.Jit array)."""
        params = self._traverse(scene)
        params.update(opt)
        img = self._render(scene, params, seed, seed_grad)
        loss = dr.mean(dr.square(img - ref), axis=None)
        dr.backward(loss)
        opt.step()
        opt[self.key] = dr.clip(opt[self.key], 0.0, 1.0)
        return loss

    def timed_step(self):
        self.it += 1
        t = time.perf_counter()
        loss = self.step(self.scene, self.opt, self.ref, self.it, 1_000_003 + self.it)
        dr.eval(loss, self.opt[self.key])
        dr.sync_thread()
        return time.perf_counter() - t


def measure_memory(o: Optimisation):
    """Of one warm iteration: Dr.Jit allocator peak (MiB), kernel launches, kernel-cache
    misses, and the time spent compiling kernels (ms; codegen + backend compiler, from the kernel
    history)."""
    dr.flush_malloc_cache()
    dr.detail.malloc_clear_statistics()
    l0 = dr.detail.launch_stats()
    dr.kernel_history()                                   # clear
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    o.timed_step()
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    hist = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    l1 = dr.detail.launch_stats()
    peak = dr.detail.malloc_watermark(dr.backend_v(mi.Float)) / 2 ** 20
    compile_ms = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in hist)
    return peak, l1[0] - l0[0], (l1[1] - l0[1]) + (l1[2] - l0[2]), compile_ms


def _rss_mib():
    """Peak resident set of this process (MiB): VmHWM of /proc/self/status, which starts
    afresh at exec; ``getrusage``'s ru_maxrss would include the parent's peak, which
    Linux carries over into a child across fork + exec."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


# -- child processes: peak RSS and dr.freeze ------------------------------------------------
def child(a):
    """Run in a child process: ``--child rss:<name>`` or ``--child freeze:<name>``."""
    what, name = a.child.split(":")
    renderer, integrator = name.split("/")
    o = Optimisation(renderer, integrator, a)
    out = {}
    if what == "rss":
        for _ in range(a.warmup + a.reps):
            o.timed_step()
        out["rss_mib"] = _rss_mib()
    else:
        # The whole step frozen, its state passed as arguments. The seed is an opaque
        # array (an int would be baked into the recording); seed_grad=0 lets the renderer
        # derive the adjoint seed inside the recording.
        frozen = (pbr.freeze if renderer == "pbr" else dr.freeze)(o.step)

        times = []
        for i in range(a.warmup + a.reps):
            s, sg = dr.opaque(mi.UInt32, i + 1), 0
            t = time.perf_counter()
            loss = frozen(o.scene, o.opt, o.ref, s, sg)
            dr.eval(loss, o.opt[o.key])
            dr.sync_thread()
            times.append(time.perf_counter() - t)
        out["freeze_s"] = float(np.median(times[a.warmup:]))
        out["recordings"] = int(frozen.n_recordings)
    print("RESULT " + json.dumps(out), flush=True)


def run_child(a, what: str, name: str) -> dict:
    args = [sys.executable, os.path.abspath(__file__), "--child", f"{what}:{name}",
            "--res", str(a.res), "--spp", str(a.spp), "--texels", str(a.texels), "--param", a.param,
            "--reps", str(a.reps), "--warmup", str(a.warmup), "--backend", a.backend]
    p = subprocess.run(args, capture_output=True, text=True, timeout=1800)
    for line in p.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    lines = [ln.strip() for ln in (p.stderr + p.stdout).splitlines() if ln.strip()]
    # The first error message is the cause (later ones re-raise it).
    cause = [ln for ln in lines if "Error:" in ln or ln.startswith("what():")] or lines[-1:] or ["no output"]
    return {"error": f"exit code {p.returncode}: {cause[0]}"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--texels", type=int, default=16)
    ap.add_argument("--param", choices=sorted(KEYS), default="texture")
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--backend", default="llvm", help="llvm, cuda or auto")
    ap.add_argument("--no-children", action="store_true", help="skip the RSS and dr.freeze child runs")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    if a.child:
        return child(a)

    from pbr.integrators import INTEGRATORS
    pbr_names = [n for n in ("path", "prb") if n in INTEGRATORS]
    runs = {f"pbr/{n}": Optimisation("pbr", n, a) for n in pbr_names}
    runs["mitsuba/prb"] = Optimisation("mitsuba", "prb", a)
    for _ in range(a.warmup):
        for o in runs.values():
            o.timed_step()
    times = {k: [] for k in runs}
    for _ in range(a.reps):                       # interleaved: load drift hits all alike
        for k, o in runs.items():
            times[k].append(o.timed_step())
    stats = {k: dict(zip(("peak_mib", "launches", "misses", "compile_ms"), measure_memory(o)))
             for k, o in runs.items()}
    for k in runs:
        stats[k]["time_s"] = float(np.median(times[k]))
        if not a.no_children:
            stats[k].update(run_child(a, "rss", k))
            fz = run_child(a, "freeze", k)
            stats[k].update({("freeze_error" if "error" in fz else k2): v for k2, v in fz.items()})

    mi_s = stats["mitsuba/prb"]
    what = f"back-wall texture {a.texels}x{a.texels}" if a.param == "texture" else "red wall albedo"
    print(f"One optimisation iteration: Cornell box {a.res}x{a.res}, {a.spp} spp, parameter {what} "
          f"(render + backward + Adam + clamp + update), {pbr.get_backend()}, median of {a.reps} after {a.warmup} warm-up")
    for k, s in stats.items():
        line = (f"  {k:12s} time {s['time_s'] * 1e3:7.1f} ms (compiling kernels {s['compile_ms']:.0f} ms)   "
                f"Dr.Jit peak {s['peak_mib']:6.2f} MiB   kernels {s['launches']:3d} (cache misses {s['misses']})")
        if "rss_mib" in s:
            line += f"   peak RSS {s['rss_mib']:.1f} MiB"
        print(line)
        if "freeze_s" in s:
            print(f"  {'':12s} dr.freeze: {s['freeze_s'] * 1e3:.1f} ms/iteration "
                  f"({s['time_s'] / s['freeze_s']:.1f}x faster, {s['recordings']} recording(s))")
        elif "freeze_error" in s:
            print(f"  {'':12s} dr.freeze failed: {s['freeze_error']}")
    for k, s in stats.items():
        if k.startswith("pbr"):
            r = f"  {k} / mitsuba/prb: time {s['time_s'] / mi_s['time_s']:.2f}, Dr.Jit peak memory " \
                f"{s['peak_mib'] / max(mi_s['peak_mib'], 1e-9):.2f}"
            if "rss_mib" in s and "rss_mib" in mi_s:
                r += f", peak RSS {s['rss_mib'] / mi_s['rss_mib']:.2f}"
            print(r)
    return stats


if __name__ == "__main__":
    main()
