"""Throughput of pbr.distributed.render on a LocalCluster of 1, 2, 4 worker processes.

    python benchmarks/bench_distributed.py [--res 128 --spp 64 --chunks 8 --renders 3 --workers 1,2,4]
                                           [--cold-kernel-cache] [--backend llvm]

Prints, per cluster size: renders/s (after a warm-up render), the first pass on each
fresh worker (process start-up, backend, scene load, kernel tracing and compilation or
a hit in Dr.Jit's kernel cache) against later passes, and the per-pass overhead (wall
time times workers, less the time spent in the tasks, per pass: scheduling, transfers,
the client adding sums); and the round trip of an empty Dask task. The baseline is
``pbr.render`` in this process with the same passes and Dr.Jit on every core. Each
worker's Dr.Jit pool gets cores / workers threads (at least 1). ``--cold-kernel-cache``
starts the workers with an empty Dr.Jit kernel cache (``DRJIT_CACHE_DIR``, a new
directory), so that their first pass compiles its kernels. Dr.Jit's kernel history on the
workers counts the kernels each render launched, how many were compiled (not found in
the in-memory or on-disk cache) and the time spent compiling.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import drjit as dr
import numpy as np

import pbr
from pbr import distributed as pd


def _noop(x):
    return x


def _start_history():
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()


def _history():
    """Kernels launched in this worker since the last call: (launched, loaded from the disk
    cache, compiled, seconds of code generation + compilation or loading)."""
    h = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
    disk = [k for k in h if k["cache_disk"]]
    compiled = [k for k in h if not k["cache_hit"] and not k["cache_disk"]]
    return len(h), len(disk), len(compiled), sum(k["codegen_time"] + k["backend_time"] for k in h) / 1e3


def _on_each(client, fn):
    """``fn()`` as a task on each worker (Dr.Jit's flags are per thread: the task thread's)."""
    return client.gather([client.submit(fn, workers=[w], pure=False, allow_other_workers=False)
                          for w in client.scheduler_info()["workers"]])


def _kernels(client):
    out = _on_each(client, _history)
    return tuple(sum(o[i] for o in out) for i in range(4))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--chunks", type=int, default=8, help="samples per pixel per pass (one task each)")
    ap.add_argument("--renders", type=int, default=3, help="timed renders per cluster size")
    ap.add_argument("--cold-kernel-cache", action="store_true", help="workers start with an empty kernel cache")
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--integrator", default="path")
    ap.add_argument("--backend", default="llvm", help="this process's and the workers' backend")
    args = ap.parse_args()

    pbr.set_backend(args.backend)
    d = pbr.cornell_box(args.res, args.spp)
    d["integrator"] = {"type": args.integrator}
    n_pass = args.spp // args.chunks
    cores = os.cpu_count() or 1
    print(f"cornell box {args.res}x{args.res}, {args.spp} spp, {args.integrator}: {n_pass} passes of "
          f"{args.chunks} spp; {cores} cores; {pbr.get_backend()}")

    ref = np.asarray(pd.render(d, spp=args.spp, chunks=args.chunks, progress=False))   # warm-up

    for n in [int(x) for x in args.workers.split(",")]:
        # The baseline again before each cluster: the machine is shared, its load changes.
        t0, cpu0 = time.perf_counter(), time.process_time()
        for i in range(args.renders):
            pd.render(d, spp=args.spp, chunks=args.chunks, seed=0, progress=False)
        local = args.renders / (time.perf_counter() - t0)
        local_cpu = (time.process_time() - cpu0) / args.renders
        print(f"in this process (pbr.render, same passes, {pbr.backend.dr.thread_count()} Dr.Jit threads): "
              f"{local:.2f} renders/s, {local_cpu:.2f} CPU s per render")
        t0 = time.perf_counter()
        if args.cold_kernel_cache:
            # inherited by the worker processes (they import drjit before a Nanny's env applies)
            os.environ["DRJIT_CACHE_DIR"] = tempfile.mkdtemp(prefix="pbr-bench-")
        client = pd.local_client(n)
        _on_each(client, _start_history)
        start = time.perf_counter() - t0
        try:
            t1 = time.perf_counter()
            client.gather(client.map(_noop, range(200), pure=False))
            noop_ms = (time.perf_counter() - t1) / 200 * 1e3
            warm = []
            t1 = time.perf_counter()
            img = np.asarray(pd.render(d, spp=args.spp, chunks=args.chunks, client=client, progress=False,
                                       stats=warm, backend=args.backend))
            first_render = time.perf_counter() - t1
            k_first = _kernels(client)
            assert np.array_equal(img, ref), "distributed render differs from the local one"
            stats, t1, cpu1 = [], time.perf_counter(), time.process_time()
            for i in range(args.renders):
                pd.render(d, spp=args.spp, chunks=args.chunks, client=client, progress=False, stats=stats,
                          backend=args.backend)
            wall = time.perf_counter() - t1
            client_cpu = (time.process_time() - cpu1) / args.renders
            k_later = _kernels(client)
            worker_cpu = sum(s["cpu_seconds"] for s in stats) / args.renders
            firsts = [s for s in warm if s["first"]]
            later = [s["render_seconds"] for s in stats]
            busy = sum(s["seconds"] for s in stats)
            overhead = (wall * n - busy) / (args.renders * n_pass)
            print(f"{n} worker{'s' if n > 1 else ''} ({max(1, cores // n)} Dr.Jit thread(s) each): "
                  f"{args.renders / wall:.2f} renders/s ({args.renders / wall / local:.2f}x this process); "
                  f"cluster start {start:.1f} s, first render {first_render:.2f} s")
            print(f"    first pass per worker: {statistics.mean(s['seconds'] for s in firsts):.3f} s in the task "
                  f"(backend {statistics.mean(s['backend_seconds'] for s in firsts):.3f} s, scene load "
                  f"{statistics.mean(s['load_seconds'] for s in firsts):.3f} s, render "
                  f"{statistics.mean(s['render_seconds'] for s in firsts):.3f} s); later passes: render "
                  f"{statistics.median(later) * 1e3:.1f} ms (median)")
            print(f"    kernels (all workers): first render {k_first[0]} launched, {k_first[1]} from the disk cache, "
                  f"{k_first[2]} compiled, {k_first[3]:.2f} s building; {args.renders} later renders {k_later[0]} "
                  f"launched, {k_later[1]} from disk, {k_later[2]} compiled, {k_later[3]:.2f} s building")
            print(f"    CPU s per render: workers {worker_cpu:.2f} + client {client_cpu:.2f} (this process alone: "
                  f"{local_cpu:.2f})")
            print(f"    overhead per pass {overhead * 1e3:.1f} ms (idle worker time per pass); empty task round "
                  f"trip {noop_ms:.2f} ms; passes per worker: "
                  f"{sorted(np.unique([s['pid'] for s in stats], return_counts=True)[1].tolist())}")
        finally:
            client.close()


if __name__ == "__main__":
    main()
