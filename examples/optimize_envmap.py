"""Recover an environment map (a low-resolution latitude-longitude ``envmap``) from
images of a diffuse and a glossy sphere it lights, seen from several viewpoints.

The views circle the spheres near the horizon, so they see part of the environment
directly (the background) and the rest reflected by the glossy (rough aluminium)
sphere; the diffuse sphere constrains its low frequencies. The parameter is
``sky.data`` (texels of linear RGB radiance, clamped to >= 0). Error: the RMSE over the
texels of the upper hemisphere (the sky, which the views see directly and reflected in
both spheres; the ground below the horizon is seen only in the spheres' lower halves),
each texel row weighted by its solid angle, in units of radiance. The same measure
over all texels is printed too.

    python examples/optimize_envmap.py [--small]
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402  (imports pbr first)

import pbr  # noqa: E402
import mitsuba as mi  # noqa: E402

KEY = "sky.data"
FULL = dict(height=8, res=48, views=4, spp=16, ref_spp=1024, n_iter=100, lr=0.2, lr_final=0.05)
SMALL = dict(height=6, res=32, views=3, spp=8, ref_spp=256, n_iter=16, lr=0.3, lr_final=0.2)


def true_envmap(h: int) -> np.ndarray:
    """A sky: blue above, warm near the horizon, dark ground, a broad bright sun."""
    w = 2 * h
    theta = (np.arange(h) + 0.5) / h * np.pi             # 0 at the zenith (Mitsuba's +Y up)
    phi = (np.arange(w) + 0.5) / w * 2 * np.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    up = np.cos(t)
    sky = np.stack([0.4 + 0.4 * (1 - up), 0.5 + 0.2 * (1 - up), 0.9 - 0.3 * (1 - up)], -1)
    ground = np.array([0.25, 0.2, 0.15])
    img = np.where(up[..., None] > 0, sky, ground)
    sun = np.exp(-((t - 0.9) ** 2 + (p - 2.0) ** 2) / 0.35)
    return (img + 3.0 * sun[..., None] * np.array([1.0, 0.85, 0.6])).astype(np.float32)


def initial_envmap(h: int) -> np.ndarray:
    # Off grey on purpose (see optimize_albedo_texture.initial_texture).
    return np.broadcast_to(np.array([0.5, 0.48, 0.46], np.float32), (h, 2 * h, 3)).copy()


def solid_angle_weights(h: int, upper_only: bool = True) -> np.ndarray:
    """Relative solid angle of each texel row of a latitude-longitude map (H, 1, 1);
    rows below the horizon get 0 with ``upper_only``."""
    edges = np.linspace(0.0, np.pi, h + 1)
    w = (np.cos(edges[:-1]) - np.cos(edges[1:]))[:, None, None]
    if upper_only:
        w[h // 2:] = 0.0
    return w


def scene_dict(height: int, res: int, views: int, spp: int) -> dict:
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 3}}
    d.update(C.orbit_sensors(views, radius=4.0, height=0.8, phase=0.3, fov=45.0, res=res, spp=spp))
    d["diffuse"] = {"type": "sphere", "center": [-0.55, 0.0, 0.0], "radius": 0.5,
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}}}
    d["glossy"] = {"type": "sphere", "center": [0.55, 0.0, 0.0], "radius": 0.5,
                   "bsdf": {"type": "roughconductor", "material": "Al", "distribution": "ggx", "alpha": 0.08}}
    d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(true_envmap(height)), "scale": 1.0}
    return d


def main(small: bool = False, grad_scale: float = 1.0, log: bool = True, **overrides) -> C.Result:
    cfg = dict(SMALL if small else FULL, **overrides)
    h = cfg["height"]
    scene = pbr.load_dict(scene_dict(h, cfg["res"], cfg["views"], cfg["spp"]))
    refs = C.render_references(scene, cfg["ref_spp"])
    truth, weights = true_envmap(h), solid_angle_weights(h)

    def error(params):
        return C.rmse(params[KEY], truth, weights)

    res = C.optimize(scene, {KEY: mi.TensorXf(initial_envmap(h))}, refs, n_iter=cfg["n_iter"],
                     lr=cfg["lr"], lr_final=cfg["lr_final"], spp=cfg["spp"], bounds={KEY: (0.0, 1e4)},
                     error=error, grad_scale=grad_scale, log=log, name="envmap")
    if log:
        print(f"  all texels (whole sphere): RMSE {C.rmse(res.values[KEY], truth, solid_angle_weights(h, False)):.4f}")
        C.summary("optimize_envmap", res, "upper-hemisphere RMSE")
    return res


if __name__ == "__main__":
    C.cli(main, __doc__)
