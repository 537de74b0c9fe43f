"""Recover the pose (translation and rotation about the vertical axis) of a box from
images taken from two viewpoints (one in the small configuration), with the projective
integrator ``direct_projective``: the box's silhouette and shadow move with its pose,
so the derivatives need boundary terms (``prb`` alone gives only the shading's).

The box is Mitsuba's ``cube`` (24 split vertices; pbr welds them to find its 12 true
silhouette edges), scaled to a 0.8 x 0.5 x 0.6 box, on a grey floor under an area
light and a dim sky. The pose moves the mesh's ``vertex_positions`` (``traverse`` key
``box.vertex_positions``) through a differentiable function of four numbers. Errors: the
translation's distance to the true one, and the angle's error (radians);
``Result.error`` is the larger.

    python examples/optimize_pose.py [--small]
"""

from __future__ import annotations

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402  (imports pbr first)

import numpy as np  # noqa: E402
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
import pbr  # noqa: E402

KEY = "box.vertex_positions"
TRUE = np.array([0.15, 0.0, -0.1, 0.35])      # x, y (up), z translation; yaw (radians)
INIT = np.array([-0.2, 0.1, 0.2, 0.0])
FULL = dict(res=48, views=2, spp=16, ref_spp=512, n_iter=60, lr=0.04, lr_final=0.1)
SMALL = dict(res=24, views=1, spp=32, ref_spp=128, n_iter=12, lr=0.06, lr_final=0.3)
VIEWS = [(0.0, 2.0, 3.5), (3.0, 2.2, 1.5)]


def scene_dict(res: int, spp: int, views: int = 2) -> dict:
    T = C.transform()
    d = {"type": "scene", "integrator": {"type": "direct_projective"}}
    for i, o in enumerate(VIEWS[:views]):
        d[f"sensor_{i}"] = C.look_at_sensor(o, (0, 0.2, 0), fov=40.0, res=res, spp=spp)
    d["box"] = {"type": "cube", "to_world": T.translate([0, 0.3, 0]).scale([0.4, 0.25, 0.3]),
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.3, 0.2]}}}
    d["floor"] = {"type": "rectangle", "to_world": T.translate([0, 0.05, 0]).rotate([1, 0, 0], -90).scale(2.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.6]}}}
    d["lamp"] = {"type": "rectangle", "to_world": T.translate([0.5, 2.5, 0.5]).rotate([1, 0, 0], 90).scale(0.4),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [12.0, 12.0, 12.0]}}}
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.2, 0.2, 0.25]}}
    return d


def posed(v0: mi.Float, pose) -> mi.Float:
    """Vertex positions ``v0`` (flat) turned by ``pose[3]`` about the vertical axis
    through the box's centre, then moved by ``pose[:3]`` (differentiable in ``pose``)."""
    p = dr.unravel(mi.Point3f, v0)
    c = [float(dr.mean(p[k])[0]) for k in range(3)]
    x, z = p.x - c[0], p.z - c[2]
    t = [dr.gather(mi.Float, pose, k) for k in range(4)]   # (indexing would detach)
    cs, sn = dr.cos(t[3]), dr.sin(t[3])
    q = mi.Point3f(cs * x + sn * z + c[0] + t[0], p.y + t[1], -sn * x + cs * z + c[2] + t[2])
    return dr.ravel(q)


def _pose(values) -> mi.Float:
    return mi.Float(np.asarray(values, np.float32))


def main(small: bool = False, grad_scale: float = 1.0, log: bool = True, **overrides) -> C.Result:
    cfg = dict(SMALL if small else FULL, **overrides)
    scene = pbr.load_dict(scene_dict(cfg["res"], cfg["spp"], cfg["views"]))
    params = pbr.traverse(scene)
    v0 = mi.Float(np.array(params[KEY]))
    params[KEY] = posed(v0, _pose(TRUE))
    params.update()
    refs = C.render_references(scene, cfg["ref_spp"])

    def error(pose):
        return max(float(np.linalg.norm(pose[:3] - TRUE[:3])), abs(float(pose[3] - TRUE[3])))

    opt = dr.opt.Adam(lr=cfg["lr"])
    opt["pose"] = _pose(INIT)
    e0, losses, errors = error(INIT), [], []
    n_views, n_iter = len(refs), cfg["n_iter"]
    t0 = time.perf_counter()
    for it in range(n_iter):
        opt.set_learning_rate(cfg["lr"] * cfg["lr_final"] ** (it / max(n_iter - 1, 1)))
        params[KEY] = posed(v0, opt["pose"])
        params.update()
        total = C.views_backward(scene, params, refs, cfg["spp"], it * n_views)
        opt.step(grad_scale=grad_scale if grad_scale != 1.0 else None)
        pose = np.array(opt["pose"])
        losses.append(total)
        errors.append(error(pose))
        if log:
            print(f"pose iter {it:3d}  loss {total:.6g}  error {errors[-1]:.4f}  pose {np.round(pose, 3)}", flush=True)
    seconds = time.perf_counter() - t0
    params[KEY] = posed(v0, dr.detach(opt["pose"]))
    params.update()
    res = C.Result(errors[-1], losses, e0, errors, {"pose": np.array(opt["pose"])}, seconds, scene, refs)
    if log:
        print(f"  pose: {INIT} -> {np.round(res.values['pose'], 4)} (true {TRUE})")
        C.summary("optimize_pose", res, "max error (translation distance, angle)")
    return res


if __name__ == "__main__":
    C.cli(main, __doc__)
