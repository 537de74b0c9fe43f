"""pbr vs Mitsuba 3 over several scenes: time at equal spp and resolution (warm kernels,
same process, interleaved pairs) and the image-mean ratio as a sanity check of the
backend (a wrong backend shows up here first: the CUDA backend once rendered the Cornell
box 95x too bright).

Scenes (all Mitsuba-loadable dicts from ``pbr.scenes``, ``path`` integrator):

- ``cornell``: the built-in Cornell box (diffuse), max_depth 8;
- ``cornell-glossy``: the same with a rough copper and a rough plastic block;
- ``gallery``: the materials gallery without the 4 cells Mitsuba lacks (16 BSDF families
  on spheres and a hair tuft of B-spline curves), max_depth 12;
- ``caustic``: a glass sphere on a floor, light reaching it through the glass;
- ``door``: Veach's door scene, simplified (light through a slit).

Prints per scene pbr's and Mitsuba's median times, the time ratio (pbr / Mitsuba, target
<= 1; the median of per-pair ratios) and the image-mean ratio (expected 1 within noise),
then the geometric mean of the time ratios, and the memory of a render: the peak
resident set size it adds, and Dr.Jit's allocations at its peak over the scene's own
(what a renderer keeps between renders, Mitsuba's film block, counted in).

    python benchmarks/bench_scenes.py [--res 128] [--spp 16] [--reps 3] [--backend llvm] [--scenes cornell,gallery]
"""

from __future__ import annotations

import argparse
import gc
import os
import re
import tempfile
import time

import numpy as np

import pbr
import drjit as dr
import mitsuba as mi

from pbr.scene.xml import to_xml

# Gallery cells Mitsuba 3.9 cannot load (pbrt-v4 features); tests/test_gallery.py checks
# that each one fails there.
NOT_IN_MITSUBA = ("dispersive BK7", "coateddiffuse", "coatedconductor", "diffusetransmission", "subsurface")


def _T():
    return mi.ScalarTransform4f


def _checker_stage(res: int, spp: int, integrator: dict, light: bool = True) -> dict:
    """A sphere's stage: a checkerboard-textured diffuse floor, a camera looking down at
    it and (``light``) a square area light above; the sphere is added by the caller."""
    T = _T()
    d = {"type": "scene", "integrator": integrator,
         "sensor": {"type": "perspective", "fov": 40.0,
                    "to_world": T().look_at(origin=[0, 1.6, 3.2], target=[0, 0.0, 0], up=[0, 1, 0]),
                    "sampler": {"type": "independent", "sample_count": spp},
                    "film": {"type": "hdrfilm", "width": res, "height": res}},
         "floor": {"type": "rectangle", "to_world": T().translate([0, -0.5, 0]).rotate([1, 0, 0], -90).scale(3),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": 0.7,
                                                               "color1": 0.2, "to_uv": T().scale([6, 6, 1])}}}}
    if light:
        d["light"] = {"type": "rectangle", "to_world": T().translate([0.5, 2.5, 1.0]).rotate([1, 0, 0], 90).scale(0.6),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 5.5, 5.0]}}}
    return d


def _sphere(bsdf: dict) -> dict:
    return {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.5, "bsdf": bsdf}


def _bsdf_scenes(res, spp) -> dict:
    """``bsdf-<family>``: one sphere per BSDF family Mitsuba has (the gallery's settings)
    over the checkerboard floor, plus a checkerboard-textured diffuse sphere."""
    from pbr.scenes import GALLERY_MATERIALS
    out = {}
    mats = [m for m in GALLERY_MATERIALS if m[0] not in NOT_IN_MITSUBA and m[1]["type"] != "hair"]
    mats.append(("textured", {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": {"type": "rgb", "value": [0.8, 0.3, 0.1]},
                                                                 "color1": {"type": "rgb", "value": [0.1, 0.3, 0.8]},
                                                                 "to_uv": _T().scale([8, 4, 1])}}))
    for label, bsdf in mats:
        d = _checker_stage(res, spp, {"type": "path", "max_depth": 8})
        d["sphere"] = _sphere(bsdf)
        out["bsdf-" + label.split()[0]] = d
    return out


def _emitter_scenes(res, spp, tmp) -> dict:
    """``light-<kind>``: a diffuse sphere on the checkerboard floor lit by one emitter of
    each kind (the area light is the BSDF scenes' ``bsdf-diffuse``)."""
    T = _T()
    grey = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.6]}}
    frame = T().look_at(origin=[1.5, 2.5, 1.5], target=[0, -0.3, 0], up=[0, 1, 0])
    env = os.path.join(tmp, "sky.exr")
    if not os.path.exists(env):
        h, w = 32, 64
        th = (np.arange(h)[:, None] + 0.5) / h
        ph = (np.arange(w)[None, :] + 0.5) / w
        sky = np.stack([0.4 + 0.6 * (1 - th) + 0 * ph, 0.5 + 0.5 * (1 - th) + 0 * ph, 0.9 + 0 * th + 0 * ph], -1)
        sky[4:6, 20:22] = 400.0                                   # a small sun
        mi.Bitmap(sky.astype(np.float32)).write(env)
    lights = {
        "point": {"type": "point", "position": [1.0, 2.0, 1.0], "intensity": {"type": "rgb", "value": [8.0, 7.0, 6.0]}},
        "spot": {"type": "spot", "to_world": frame, "cutoff_angle": 30.0, "beam_width": 20.0,
                 "intensity": {"type": "rgb", "value": [20.0, 18.0, 15.0]}},
        "directional": {"type": "directional", "direction": [-0.4, -1.0, -0.3],
                        "irradiance": {"type": "rgb", "value": [3.0, 2.8, 2.5]}},
        "constant": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 0.9, 0.8]}},
        "envmap": {"type": "envmap", "filename": env},
        "projector": {"type": "projector", "to_world": frame, "fov": 50.0,
                      "irradiance": {"type": "rgb", "value": [8.0, 6.0, 4.0]}},
    }
    out = {}
    for kind, em in lights.items():
        d = _checker_stage(res, spp, {"type": "path", "max_depth": 8}, light=False)
        d["sphere"] = _sphere(grey)
        d["emitter"] = em
        out["light-" + kind] = d
    return out


def _many_lights(res, spp, n=128) -> dict:
    """``many-lights``: the checkerboard stage lit by ``n`` small area lights (random
    positions and colours, fixed seed) and no large one."""
    T = _T()
    rng = np.random.default_rng(7)
    d = _checker_stage(res, spp, {"type": "path", "max_depth": 6}, light=False)
    d["sphere"] = _sphere({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.6]}})
    for i in range(n):
        pos = [float(rng.uniform(-2.5, 2.5)), float(rng.uniform(1.0, 2.5)), float(rng.uniform(-2.5, 2.0))]
        d[f"l{i:03d}"] = {"type": "rectangle", "to_world": T().translate(pos).rotate([1, 0, 0], 90).scale(0.06),
                          "emitter": {"type": "area",
                                      "radiance": {"type": "rgb", "value": list(map(float, rng.uniform(5, 40, 3)))}}}
    return d


def _mesh(res, spp, tmp, subdiv=6) -> dict:
    """``mesh-100k``: a rough plastic icosphere of 20 * 4^6 = 81920 triangles (a PLY file
    written by trimesh) on the checkerboard floor: Embree on a dense mesh and the mesh
    surface interaction."""
    import trimesh
    path = os.path.join(tmp, f"ico{subdiv}.ply")
    if not os.path.exists(path):
        m = trimesh.creation.icosphere(subdivisions=subdiv, radius=0.5)
        m.export(path)
    d = _checker_stage(res, spp, {"type": "path", "max_depth": 8})
    d["mesh"] = {"type": "ply", "filename": path,
                 "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                          "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.7]}}}
    return d


def _media_scenes(res, spp, tmp) -> dict:
    """``medium-homogeneous`` (a scattering ball, HG phase, behind a null boundary) and
    ``medium-grid`` (a 32^3 density blob in a cube), ``volpath``."""
    from pbr.media.grid import write_vol
    T = _T()
    out = {}
    d = _checker_stage(res, spp, {"type": "volpath", "max_depth": 8})
    d["sphere"] = dict(_sphere({"type": "null"}), interior={"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.8,
                                                            "phase": {"type": "hg", "g": 0.6}})
    out["medium-homogeneous"] = d
    vol = os.path.join(tmp, "blob32.vol")
    if not os.path.exists(vol):
        n = 32
        z, y, x = np.mgrid[0:n, 0:n, 0:n] / (n - 1.0)
        g = np.exp(-((x - 0.5) ** 2 + (y - 0.4) ** 2 + (z - 0.6) ** 2) / 0.05) * 12.0
        write_vol(vol, g.astype(np.float32))
    d = _checker_stage(res, spp, {"type": "volpath", "max_depth": 8})
    d["cloud"] = {"type": "cube", "to_world": T().scale(0.5), "bsdf": {"type": "null"},
                  "interior": {"type": "heterogeneous", "albedo": 0.85,
                               "sigma_t": {"type": "gridvolume", "filename": vol,
                                           "to_world": T().translate([-0.5, -0.5, -0.5])}}}
    out["medium-grid"] = d
    return out


# The default set (the issue's varied set); ``--quick`` takes one of each group.
QUICK = ("cornell", "gallery", "bsdf-diffuse", "bsdf-roughplastic", "bsdf-textured", "light-point",
         "light-envmap", "medium-homogeneous", "many-lights", "mesh-100k")


def scene_dicts(res: int, spp: int, tmp: str | None = None) -> dict:
    """Every benchmark scene by name (files it needs are written under ``tmp``)."""
    from pbr.scenes import GALLERY_MATERIALS, glass_caustic, door_crack, materials_gallery
    tmp = tmp or os.path.join(tempfile.gettempdir(), "pbr_bench_scenes")
    os.makedirs(tmp, exist_ok=True)
    path = lambda depth: {"type": "path", "max_depth": depth}  # noqa: E731
    out = {}
    d = pbr.cornell_box(res, spp)
    d["integrator"] = path(8)
    out["cornell"] = d
    d = pbr.cornell_box(res, spp)
    d["integrator"] = path(8)
    d["small-box"]["bsdf"] = {"type": "roughconductor", "material": "Cu", "distribution": "ggx", "alpha": 0.2}
    d["large-box"]["bsdf"] = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                              "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}
    out["cornell-glossy"] = d
    mats = [m for m in GALLERY_MATERIALS if m[0] not in NOT_IN_MITSUBA]
    out["gallery"] = materials_gallery(res, spp, materials=mats)
    for name, d in (("caustic", glass_caustic(res, spp)), ("door", door_crack(res, spp))):
        d["integrator"] = path(8)
        out[name] = d
    out.update(_bsdf_scenes(res, spp))
    out.update(_emitter_scenes(res, spp, tmp))
    out["many-lights"] = _many_lights(res, spp)
    out["mesh-100k"] = _mesh(res, spp, tmp)
    out.update(_media_scenes(res, spp, tmp))
    return out


def _rss_peak_reset():
    """Reset the kernel's peak-RSS mark of this process (Linux: /proc/self/clear_refs)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def _jit_in_use() -> float:
    """Bytes Dr.Jit's allocator has handed out on the active backend (from ``dr.whos``:
    the Python API has the peak but not the current figure)."""
    name = "CUDA" if pbr.get_backend() == "cuda" else "LLVM"
    units = {"B": 1, "KiB": 2 ** 10, "MiB": 2 ** 20, "GiB": 2 ** 30, "TiB": 2 ** 40}
    m = re.search(rf"- {name}\s*: ([0-9.]+) (B|KiB|MiB|GiB|TiB)/", dr.whos(True))
    return float(m.group(1)) * units[m.group(2)] if m else 0.0


def _jit_settled() -> float:
    """Dr.Jit's allocations in use once Python's garbage and Dr.Jit's cache are released."""
    gc.collect()
    dr.flush_malloc_cache()
    return _jit_in_use()


def kept_by(fn) -> float:
    """Dr.Jit memory (MiB) that stays allocated after fn(), a first render: buffers a
    renderer keeps between renders (Mitsuba's film keeps its image block: 2.0 MiB at
    256x256), which :func:`memory_of` does not see as added by later renders."""
    jit0 = _jit_settled()
    fn()
    return (_jit_settled() - jit0) / 2.0 ** 20


def memory_of(fn) -> tuple[float, float]:
    """Memory fn() takes beyond what was in use before it, MiB: (peak resident set size,
    peak of Dr.Jit's allocations). Both renderers keep their scenes resident; this is what
    a render adds (its arrays, its kernel's buffers)."""
    be = dr.JitBackend.CUDA if pbr.get_backend() == "cuda" else dr.JitBackend.LLVM
    jit0 = _jit_settled()
    dr.detail.malloc_clear_statistics()
    _rss_peak_reset()
    rss0 = _status_kib("VmRSS")
    fn()
    peak = _status_kib("VmHWM")
    return (peak - rss0) / 1024.0, (dr.detail.malloc_watermark(be) - jit0) / 2.0 ** 20


def interleaved_cpu(fa, fb, reps):
    """As ``bench_cornell.interleaved`` (one warm-up each, then alternating calls), with
    the process CPU time (all threads) of each call beside its wall time: on a machine
    shared with other jobs the CPU time is the steadier figure. Returns the medians
    (wall a, wall b, wall ratio, cpu a, cpu b, cpu ratio); ratios are medians of pairs."""
    fa(), fb()
    w, c = {0: [], 1: []}, {0: [], 1: []}
    for _ in range(reps):
        for k, fn in ((0, fa), (1, fb)):
            t0, c0 = time.perf_counter(), time.process_time()
            fn()
            w[k].append(time.perf_counter() - t0)
            c[k].append(time.process_time() - c0)
    med = lambda x: float(np.median(x))  # noqa: E731
    wa, wb, ca, cb = (np.array(v) for v in (w[0], w[1], c[0], c[1]))
    return med(wa), med(wb), med(wa / wb), med(ca), med(cb), med(ca / cb)


def geomean(x) -> float:
    return float(np.exp(np.mean(np.log(x))))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64, help="image width (height follows the scene's aspect)")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--scenes", default=None, help="comma-separated names (default: all; see --list)")
    ap.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}")
    ap.add_argument("--list", action="store_true", help="list the scenes and exit")
    ap.add_argument("--no-memory", action="store_true", help="skip the memory measurement")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    dicts = scene_dicts(a.res, a.spp)
    if a.list:
        print("\n".join(dicts))
        return
    names = a.scenes.split(",") if a.scenes else list(QUICK if a.quick else dicts)
    unknown = [n for n in names if n not in dicts]
    if unknown:
        raise SystemExit(f"unknown scene(s) {unknown}; known: {', '.join(dicts)}")
    print(f"{a.res} wide, {a.spp} spp, backend {pbr.get_backend()}, median of {a.reps} interleaved pairs; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"{'scene':20s} {'pbr s':>7s} {'Mi s':>7s} {'wall':>6s} {'cpu':>6s} {'mean':>6s}"
          f" {'RSS MiB pbr/Mi':>15s} {'Dr.Jit MiB pbr/Mi':>18s}")
    walls, cpus = [], []
    for name in names:
        d = dicts[name]
        # Mitsuba reads the scene as pbr's XML writer gives it (its dict loader takes no
        # NumPy matrices, which the gallery's twosided checkerboard uses for to_uv).
        scene, mscene = pbr.load_dict(d), mi.load_string(to_xml(d))
        seed = [0]
        last = {}

        def run_pbr():
            seed[0] += 1
            # Copies (np.array): a view would keep the renderer's image allocated.
            last["pbr"] = np.array(pbr.render(scene, spp=a.spp, seed=seed[0], progress=False))

        def run_mi():
            seed[0] += 1
            img = mi.render(mscene, spp=a.spp, seed=seed[0])
            dr.eval(img)
            last["mi"] = np.array(img)[..., :3]

        keep = (kept_by(run_pbr), kept_by(run_mi)) if not a.no_memory else None
        t_pbr, t_mi, ratio, _, _, cratio = interleaved_cpu(run_pbr, run_mi, a.reps)
        mean_ratio = float(last["pbr"].mean() / max(last["mi"].mean(), 1e-12))
        walls.append(ratio)
        cpus.append(cratio)
        mem = ""
        if not a.no_memory:
            (rp, jp), (rm, jm) = memory_of(run_pbr), memory_of(run_mi)
            # Dr.Jit: the peak over the scene's own memory (kept between renders + added).
            mem = f" {rp:7.1f}/{rm:<7.1f} {keep[0] + jp:9.1f}/{keep[1] + jm:<8.1f}"
        print(f"{name:20s} {t_pbr:7.3f} {t_mi:7.3f} {ratio:6.2f} {cratio:6.2f} {mean_ratio:6.3f}{mem}", flush=True)
        del scene, mscene
    print(f"geometric mean over {len(walls)} scenes: wall {geomean(walls):.3f}, cpu {geomean(cpus):.3f}; "
          f"scenes above 1.0 (cpu): {sum(c > 1.0 for c in cpus)}; load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
