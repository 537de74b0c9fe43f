"""Embree ray queries per render, pbr vs Mitsuba 3 (LLVM backend): for closest-hit and
shadow-ray queries, the lanes traced, the shadow rays found blocked, their mean length and
the time spent inside Embree. Both renderers trace through Mitsuba's Embree scene, so a
small ``LD_PRELOAD`` library around ``mitsuba::rtcIntersect16`` / ``rtcOccluded16``
(Mitsuba 3.9's namespaced Embree 3, 16-wide packets) sees every query of both; it is
compiled here with the system C compiler and the script re-runs itself with it loaded.

    python benchmarks/ray_counts.py [--scenes door,cornell] [--res 64] [--spp 16] [--max-depth 3]

docs/performance.md ("door: the time is in Embree") has the figures it gave.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import subprocess
import sys
import tempfile

OCC = "_ZN7mitsuba13rtcOccluded16EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_8RTCRay16E"
ISECT = "_ZN7mitsuba14rtcIntersect16EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_11RTCRayHit16E"

# Counters: 0 shadow packets, 1 lanes, 2 blocked, 3 length sum (x1000), 4 ns;
# 5 closest-hit packets, 6 lanes, 7 ns.
SHIM = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <time.h>
typedef struct { float ox[16], oy[16], oz[16], tnear[16], dx[16], dy[16], dz[16], time[16], tfar[16];
                 unsigned mask[16], id[16], flags[16]; } Ray16;
typedef void (*query_t)(const int*, void*, void*, void*);
static query_t occ, isect;
static void* lib;
static volatile long long c[8];
static long long now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec * 1000000000LL + t.tv_nsec; }
static void* sym(const char* name) {
  if (!lib) lib = dlopen(EMBREE, RTLD_LAZY | RTLD_NOLOAD);   /* loaded RTLD_LOCAL by Python: no RTLD_NEXT */
  return dlsym(lib, name);
}
void counts_reset(void) { for (int i = 0; i < 8; i++) c[i] = 0; }
void counts_get(long long* out) { for (int i = 0; i < 8; i++) out[i] = c[i]; }
void OCC(const int* valid, void* s, void* ctx, Ray16* r) {
  if (!occ) occ = (query_t) sym("OCC");
  int n = 0; double len = 0; for (int i = 0; i < 16; i++) if (valid[i]) { n++; len += r->tfar[i]; }
  long long t0 = now(); occ(valid, s, ctx, r); long long t1 = now();
  int b = 0; for (int i = 0; i < 16; i++) if (valid[i] && r->tfar[i] < 0) b++;   /* Embree sets tfar = -inf */
  __sync_fetch_and_add(&c[0], 1); __sync_fetch_and_add(&c[1], n); __sync_fetch_and_add(&c[2], b);
  __sync_fetch_and_add(&c[3], (long long) (len * 1000)); __sync_fetch_and_add(&c[4], t1 - t0);
}
void ISECT(const int* valid, void* s, void* ctx, Ray16* r) {
  if (!isect) isect = (query_t) sym("ISECT");
  int n = 0; for (int i = 0; i < 16; i++) if (valid[i]) n++;
  long long t0 = now(); isect(valid, s, ctx, r); long long t1 = now();
  __sync_fetch_and_add(&c[5], 1); __sync_fetch_and_add(&c[6], n); __sync_fetch_and_add(&c[7], t1 - t0);
}
"""


def _build_shim() -> str:
    import mitsuba
    embree = os.path.join(os.path.dirname(mitsuba.__file__), "libembree3.so")
    if not os.path.exists(embree):
        raise SystemExit(f"{embree} not found: this counts Mitsuba 3.9's bundled Embree 3 only")
    out = os.path.join(tempfile.gettempdir(), "pbr_ray_counts.so")
    src = out[:-3] + ".c"
    with open(src, "w") as f:
        f.write(SHIM.replace("OCC", OCC).replace("ISECT", ISECT).replace("EMBREE", f'"{embree}"'))
    subprocess.run(["cc", "-O2", "-shared", "-fPIC", "-o", out, src, "-ldl"], check=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="door,cornell", help="bench_scenes.py names, comma-separated")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--max-depth", type=int, default=None, help="the path integrator's max_depth (default: the scene's)")
    ap.add_argument("--backend", default="llvm", choices=["llvm"], help="Embree's queries: the LLVM backend only")
    a = ap.parse_args(argv)
    shim = os.environ.get("PBR_RAY_COUNTS")
    if not shim or shim not in os.environ.get("LD_PRELOAD", ""):
        shim = _build_shim()
        env = dict(os.environ, PBR_RAY_COUNTS=shim, LD_PRELOAD=shim)
        sys.exit(subprocess.run([sys.executable, os.path.abspath(__file__), *(argv or sys.argv[1:])], env=env).returncode)

    import numpy as np
    import mitsuba as mi
    import pbr
    from pbr.scene.xml import to_xml
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_scenes import scene_dicts
    pbr.set_backend(a.backend)
    lib = ctypes.CDLL(shim)
    dicts = scene_dicts(a.res, a.spp)
    print(f"{a.res} wide, {a.spp} spp, one warm render each")
    print(f"{'scene':14s} {'who':4s} {'shadow lanes':>12s} {'blocked':>8s} {'mean len':>8s} {'ms':>6s} {'ns/lane':>7s}"
          f" {'hit lanes':>10s} {'ms':>6s} {'ns/lane':>7s} {'image mean':>10s}")
    for name in a.scenes.split(","):
        d = dicts[name]
        if a.max_depth is not None:
            d["integrator"] = {"type": "path", "max_depth": a.max_depth}
        scene, ms = pbr.load_dict(d), mi.load_string(to_xml(d))
        for who, render in (("pbr", lambda: pbr.render(scene, spp=a.spp, seed=1, progress=False)),
                            ("mi", lambda: mi.render(ms, spp=a.spp, seed=1))):
            np.asarray(render())
            lib.counts_reset()
            img = np.asarray(render())
            c = (ctypes.c_longlong * 8)()
            lib.counts_get(c)
            n, nh = max(c[1], 1), max(c[6], 1)
            print(f"{name:14s} {who:4s} {c[1]:12,d} {c[2] / n:8.3f} {c[3] / 1000 / n:8.3f} {c[4] / 1e6:6.1f}"
                  f" {c[4] / n:7.0f} {c[6]:10,d} {c[7] / 1e6:6.1f} {c[7] / nh:7.0f} {img.mean():10.4f}", flush=True)


if __name__ == "__main__":
    main()
