"""Recover a deformed mesh from images taken from several viewpoints, starting from a
sphere, with Laplacian-preconditioned steps (Nicolet et al. 2021, "Large Steps in
Inverse Rendering of Geometry") and the projective integrator ``direct_projective``.

The mesh is an icosphere (``trimesh``, watertight; subdivision 2, 162 vertices, in the
small configuration) whose target is the same mesh stretched, squashed and bulged; it is
lit by an area light and a dim sky. The optimised variable is not the vertex positions x
but u = (I + lambda L) x (L: the mesh's uniform graph Laplacian): an Adam step on u moves
x by a smooth field, which keeps the surface from tangling, and the gradient w.r.t. u is
(I + lambda L)^-1 times the gradient w.r.t. x. The ``largesteps`` package (PyTorch,
cholespy) is not used: pbr's example factors the small system once with NumPy (dense
Cholesky, fine up to a few thousand vertices). Error: the symmetric mean distance between
the vertex sets of the current and the true mesh (Chamfer), in scene units (the sphere's
radius is 0.5).

    python examples/optimize_shape.py [--small]
"""

from __future__ import annotations

import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402  (imports pbr first)

import numpy as np  # noqa: E402
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
import pbr  # noqa: E402

KEY = "blob.vertex_positions"
FULL = dict(subdiv=3, res=48, views=4, spp=16, ref_spp=256, n_iter=80, lr=0.02, lr_final=0.2, lam=20.0)
SMALL = dict(subdiv=2, res=20, views=3, spp=8, ref_spp=128, n_iter=12, lr=0.05, lr_final=0.3, lam=10.0)


def sphere(subdiv: int):
    """(vertices (n, 3), faces (m, 3)) of an icosphere of radius 0.5."""
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=subdiv, radius=0.5)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def target_shape(v: np.ndarray) -> np.ndarray:
    """The true shape: the sphere stretched along x, squashed along y, bulged at +z."""
    out = v * np.array([1.3, 0.8, 1.0])
    bump = np.exp(-np.sum(np.square(v - np.array([0.0, 0.1, 0.5])), axis=1) / 0.08)
    return out + 0.25 * bump[:, None] * v / np.linalg.norm(v, axis=1, keepdims=True)


def write_obj(path: str, v: np.ndarray, f: np.ndarray) -> None:
    with open(path, "w") as out:
        out.writelines(f"v {a:.7f} {b:.7f} {c:.7f}\n" for a, b, c in v)
        out.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)


def scene_dict(obj: str, res: int, spp: int, views: int) -> dict:
    T = C.transform()
    d = {"type": "scene", "integrator": {"type": "direct_projective"}}
    d.update(C.orbit_sensors(views, 2.6, height=0.8, phase=0.3, fov=40.0, res=res, spp=spp))
    d["blob"] = {"type": "obj", "filename": obj,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.4, 0.3, 0.25]}}}
    d["lamp"] = {"type": "rectangle", "to_world": T.look_at([1.5, 2.5, 2.0], [0, 0, 0], [0, 1, 0]).scale(0.6),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [8.0, 8.0, 8.0]}}}
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.8, 0.85, 0.9]}}
    return d


def laplacian_system(n: int, faces: np.ndarray, lam: float) -> np.ndarray:
    """The Cholesky factor of I + lam L, L the uniform graph Laplacian of the mesh."""
    A = np.zeros((n, n))
    for i, j in ((0, 1), (1, 2), (2, 0)):
        A[faces[:, i], faces[:, j]] = 1.0
        A[faces[:, j], faces[:, i]] = 1.0
    L = np.diag(A.sum(axis=1)) - A
    return np.linalg.cholesky(np.eye(n) + lam * L)


def solve(chol: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(I + lam L)^-1 b from its Cholesky factor."""
    return np.linalg.solve(chol.T, np.linalg.solve(chol, b))


def chamfer(a: np.ndarray, b: np.ndarray) -> float:
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return float(0.5 * (d.min(axis=1).mean() + d.min(axis=0).mean()))


class Adam:
    """Adam on a NumPy array (the variable u lives on the host between solves)."""

    def __init__(self, shape, beta1=0.9, beta2=0.999, eps=1e-8):
        self.m, self.v, self.t = np.zeros(shape), np.zeros(shape), 0
        self.b1, self.b2, self.eps = beta1, beta2, eps

    def step(self, x, g, lr):
        self.t += 1
        self.m = self.b1 * self.m + (1 - self.b1) * g
        self.v = self.b2 * self.v + (1 - self.b2) * g * g
        mh, vh = self.m / (1 - self.b1 ** self.t), self.v / (1 - self.b2 ** self.t)
        return x - lr * mh / (np.sqrt(vh) + self.eps)


def main(small: bool = False, grad_scale: float = 1.0, log: bool = True, **overrides) -> C.Result:
    cfg = dict(SMALL if small else FULL, **overrides)
    v_init, faces = sphere(cfg["subdiv"])
    v_true = target_shape(v_init)
    with tempfile.TemporaryDirectory() as tmp:
        obj = os.path.join(tmp, "blob.obj")
        write_obj(obj, v_init, faces)
        scene = pbr.load_dict(scene_dict(obj, cfg["res"], cfg["spp"], cfg["views"]))
    params = pbr.traverse(scene)
    # Mitsuba's OBJ reader orders vertices its own way: match them to the file's
    mine = np.array(params[KEY]).reshape(-1, 3)
    perm = np.argmin(np.linalg.norm(mine[:, None, :] - v_init[None, :, :].astype(np.float32), axis=2), axis=1)

    def to_mesh(v):
        return mi.Float(v[perm].astype(np.float32).ravel())

    params[KEY] = to_mesh(v_true)
    params.update()
    refs = C.render_references(scene, cfg["ref_spp"])

    chol = laplacian_system(len(v_init), faces, cfg["lam"])
    u = np.linalg.multi_dot([chol, chol.T, v_init])   # u = (I + lam L) x
    adam = Adam(u.shape)
    e0, losses, errors = chamfer(v_init, v_true), [], []
    n_views, n_iter = len(refs), cfg["n_iter"]
    t0 = time.perf_counter()
    for it in range(n_iter):
        lr = cfg["lr"] * cfg["lr_final"] ** (it / max(n_iter - 1, 1))
        x = solve(chol, u)
        xd = to_mesh(x)
        dr.enable_grad(xd)
        params[KEY] = xd
        params.update()
        total = C.views_backward(scene, params, refs, cfg["spp"], it * n_views)
        g = np.zeros_like(x)
        np.add.at(g, perm, np.array(dr.grad(xd), np.float64).reshape(-1, 3) * grad_scale)
        u = adam.step(u, solve(chol, g), lr)
        losses.append(total)
        errors.append(chamfer(solve(chol, u), v_true))
        if log:
            print(f"shape iter {it:3d}  loss {total:.6g}  chamfer {errors[-1]:.4f}", flush=True)
    seconds = time.perf_counter() - t0
    x = solve(chol, u)
    params[KEY] = to_mesh(x)
    params.update()
    res = C.Result(errors[-1], losses, e0, errors, {"vertices": x}, seconds, scene, refs)
    if log:
        C.summary("optimize_shape", res, "Chamfer distance")
    return res


if __name__ == "__main__":
    C.cli(main, __doc__)
