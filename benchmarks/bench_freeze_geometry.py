"""A frozen optimisation step that moves a mesh: pbr (``pbr.freeze``) vs the same step
unfrozen, and Mitsuba 3's ``prb`` in ``llvm_ad_rgb`` frozen (``dr.freeze``) and unfrozen,
in one process.

Scene: an icosphere (``--subdiv``, 1280 triangles at 3) under a point light and a
constant sky, ``--res`` pixels square, ``--spp`` samples, ``prb`` (max_depth 3); the
parameter is the mesh's ``vertex_positions``, started 0.3 to the right of the reference
and moved by Adam. Each step renders, takes the loss (L2 to the reference) and its
gradient, steps Adam and assigns the positions (``params.update()``: Mitsuba rebuilds
the mesh and Embree's BVH). pbr's frozen step assigns them last (the BVH is rebuilt by
``pbr.freeze`` after the call); Mitsuba's frozen step is measured in both orders
(``params.update(opt)`` first, as in Mitsuba's tutorials, or last). Reported: median
wall time per step over ``--iters`` steps after ``--warmup``, and the number of
recordings (``n_recordings``) of each frozen step. Also: whether Mitsuba's frozen
render with the update inside replays the geometry it is given (image error against the
same render unfrozen, per call), and the gradient error of Mitsuba's step frozen with its
update between the calls (smooth and face normals).

    python benchmarks/bench_freeze_geometry.py [--res 64] [--spp 16] [--iters 10] [--warmup 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

import pbr  # first: it chooses the libLLVM Dr.Jit loads
import drjit as dr
import mitsuba as mi


def write_icosphere(path: str, subdiv: int) -> None:
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=subdiv, radius=0.7)
    with open(path, "w") as f:
        f.writelines(f"v {x} {y} {z}\n" for x, y, z in m.vertices)
        f.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in m.faces)


def scene_dict(obj: str, res: int, spp: int) -> dict:
    T = mi.ScalarTransform4f
    return {"type": "scene", "integrator": {"type": "prb", "max_depth": 3},
            "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": res, "height": res},
                       "sampler": {"type": "independent", "sample_count": spp}},
            "light": {"type": "point", "position": [0.5, 0.5, 2.0], "intensity": {"type": "rgb", "value": [5, 5, 5]}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.3, 0.3, 0.3]}},
            "ball": {"type": "obj", "filename": obj, "bsdf": {"type": "diffuse"}}}


KEY = "ball.vertex_positions"


def shifted(v, dx):
    pos = dr.unravel(mi.Point3f, mi.Float(v))
    pos[0] += dx
    return dr.ravel(pos)


def setup(load, traverse, render, d, spp):
    scene = load(d)
    params = traverse(scene)
    ref = mi.TensorXf(np.asarray(render(scene, spp=spp, seed=1 << 20)))
    opt = dr.opt.Adam(lr=0.02)
    opt[KEY] = mi.Float(shifted(dr.detach(params[KEY]), 0.3))
    params.update(opt)
    return scene, params, ref, opt


def time_steps(fn, args_of, warmup, iters):
    times = []
    for i in range(warmup + iters):
        t0 = time.perf_counter()
        loss = fn(*args_of(i))
        dr.eval(loss)
        dr.sync_thread()
        times.append(time.perf_counter() - t0)
    return float(np.median(times[warmup:])) * 1e3, float(loss.array[0])


def bench_pbr(d, a):
    out = {}
    for frozen in (False, True):
        scene, params, ref, opt = setup(pbr.load_dict, pbr.traverse, pbr.render, d, a.spp)

        def step(scene, params, opt, ref, seed):
            img = pbr.render(scene, params, spp=a.spp, seed=seed)
            loss = dr.mean(dr.square(img - ref), axis=None)
            dr.backward(loss)
            opt.step()
            params.update(opt)          # last: pbr.freeze rebuilds the BVH after the call
            return loss

        f = pbr.freeze(step) if frozen else step
        ms, loss = time_steps(f, lambda i: (scene, params, opt, ref, dr.opaque(mi.UInt32, i + 1)), a.warmup, a.iters)
        out["frozen" if frozen else "unfrozen"] = (ms, loss, getattr(f, "n_recordings", None))
    # the host part alone: Mitsuba's rebuild (BVH) and pbr's geometry_changed
    scene, params, ref, opt = setup(pbr.load_dict, pbr.traverse, pbr.render, d, a.spp)
    ts = []
    for i in range(a.iters):
        params[KEY] = mi.Float(shifted(dr.detach(opt[KEY]), 0.001 * (i + 1)))
        dr.eval(params[KEY])
        t0 = time.perf_counter()
        params.update()
        ts.append(time.perf_counter() - t0)
    out["update"] = float(np.median(ts)) * 1e3
    return out


def bench_mitsuba(d, a):
    variant = mi.variant()
    mi.set_variant(f"{a.backend}_ad_rgb")   # Mitsuba's RGB variant of the chosen backend
    try:
        out = {}
        md = dict(d)
        for order in ("none", "first", "last", "outside"):
            scene, params, ref, opt = setup(mi.load_dict, mi.traverse, mi.render, md, a.spp)

            def step(scene, params, opt, ref, seed):
                if order in ("none", "first"):
                    params.update(opt)
                img = mi.render(scene, params, spp=a.spp, seed=seed)
                loss = dr.mean(dr.square(img - ref), axis=None)
                dr.backward(loss)
                opt.step()
                if order == "last":
                    params.update(opt)
                return loss

            f = step if order == "none" else dr.freeze(step, warn_after=10 ** 6)
            if order == "outside":     # the update between the frozen calls, by hand
                def g(*args):
                    loss = f(*args)
                    params.update(opt)
                    return loss
            else:
                g = f
            try:
                ms, loss = time_steps(g, lambda i: (scene, params, opt, ref, dr.opaque(mi.UInt32, i + 1)),
                                      a.warmup, a.iters)
                out[order] = (ms, loss, getattr(f, "n_recordings", None))
            except RuntimeError as e:
                cause = e.__cause__ or e
                out[order] = str(cause).strip().splitlines()[0][:160]
        # the render alone, with the update inside, against the same render unfrozen
        scenes = [setup(mi.load_dict, mi.traverse, mi.render, md, a.spp) for _ in range(2)]
        v0 = dr.detach(scenes[0][1][KEY])

        def moved_render(scene, params, dx, seed):
            params[KEY] = shifted(v0, dx)
            params.update()
            return mi.render(scene, params, spp=a.spp, seed=seed)
        frozen = dr.freeze(moved_render, warn_after=10 ** 6)
        errors = []
        for i in range(8):
            args = (mi.Float(0.1 * i), dr.opaque(mi.UInt32, 1))
            img = np.asarray(frozen(*scenes[0][:2], *args))
            errors.append(float(np.abs(img - np.asarray(moved_render(*scenes[1][:2], *args))).max()))
        out["render_only"] = (frozen.n_recordings, errors)
        out["split_gradients"] = {n: split_gradient_errors(d, a, n) for n in ("smooth", "face")}
        return out
    finally:
        mi.set_variant(variant)


def split_gradient_errors(d, a, normals):
    """Mitsuba's step frozen without its update (render, loss, backward, Adam), the update
    between the calls: the relative error of its gradient at each step against the same
    steps unfrozen (``normals``: the mesh's smooth vertex normals or face normals)."""
    d = dict(d, ball=dict(d["ball"], face_normals=normals == "face"))
    grads = []
    for frozen in (False, True):
        scene, params, ref, opt = setup(mi.load_dict, mi.traverse, mi.render, d, a.spp)

        def step(scene, params, opt, ref, seed):
            img = mi.render(scene, params, spp=a.spp, seed=seed)
            loss = dr.mean(dr.square(img - ref), axis=None)
            dr.backward(loss)
            grad = dr.detach(dr.grad(opt[KEY]))
            opt.step()
            return loss, grad
        f = dr.freeze(step, warn_after=10 ** 6) if frozen else step
        out = []
        for i in range(5):
            _, grad = f(scene, params, opt, ref, dr.opaque(mi.UInt32, i + 1))
            params.update(opt)
            out.append(np.asarray(grad))
        grads.append(out)
    return [float(np.abs(g1 - g0).max() / np.abs(g0).max()) for g0, g1 in zip(*grads)]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--subdiv", type=int, default=3)
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=3)
    a = ap.parse_args()
    pbr.set_backend(a.backend)
    with tempfile.TemporaryDirectory() as tmp:
        obj = os.path.join(tmp, "ball.obj")
        write_icosphere(obj, a.subdiv)
        d = scene_dict(obj, a.res, a.spp)
        p = bench_pbr(d, a)
        m = bench_mitsuba(d, a)
    print(f"{a.res}x{a.res}, {a.spp} spp, icosphere subdiv {a.subdiv}; median of {a.iters} steps after {a.warmup}")
    for name, r in (("pbr unfrozen", p["unfrozen"]), ("pbr frozen (update last)", p["frozen"]),
                    ("Mitsuba unfrozen", m["none"]), ("Mitsuba frozen, update first", m["first"]),
                    ("Mitsuba frozen, update last", m["last"]),
                    ("Mitsuba frozen, update outside", m["outside"])):
        if isinstance(r, str):
            print(f"  {name:30s} fails: {r}")
            continue
        ms, loss, n = r
        rec = "" if n is None else f", {n} recordings in {a.warmup + a.iters} calls"
        print(f"  {name:30s} {ms:8.1f} ms/step  (final loss {loss:.5f}{rec})")
    n, errors = m["render_only"]
    print(f"  Mitsuba frozen render with the update inside (no gradient): {n} recordings in 8 calls; "
          f"largest pixel error against unfrozen per call: {', '.join(f'{e:.2f}' for e in errors)}")
    for normals, errors in m["split_gradients"].items():
        print(f"  Mitsuba frozen, update outside, {normals} normals: gradient relative error per step "
              f"{', '.join(f'{e:.2f}' for e in errors)}")
    print(f"  pbr geometry update alone (Mitsuba rebuild + geometry_changed): {p['update']:.1f} ms")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
