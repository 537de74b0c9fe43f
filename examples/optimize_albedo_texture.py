"""Recover a diffuse albedo bitmap (the Cornell box's back wall) from images.

The box (without its two blocks, so that the whole back wall is seen) is rendered by
pbr with a colourful true texture; the optimisation starts from a flat grey-ish wall
and fits every texel with Adam (``back.bsdf.reflectance.data``, clamped to [0, 1]).
Error: RMSE over all texels and channels (linear sRGB albedo).

    python examples/optimize_albedo_texture.py [--small]
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402  (imports pbr first)

import pbr  # noqa: E402
import mitsuba as mi  # noqa: E402

KEY = "back.bsdf.reflectance.data"
FULL = dict(texels=16, res=64, spp=16, ref_spp=1024, n_iter=150, lr=0.03, lr_final=0.1)
SMALL = dict(texels=8, res=24, spp=16, ref_spp=256, n_iter=20, lr=0.04, lr_final=0.25)


def true_texture(n: int) -> np.ndarray:
    """A smooth colourful albedo pattern with values in [0.1, 0.9]."""
    y, x = np.mgrid[0:n, 0:n] / (n - 1)
    r = 0.15 + 0.7 * x
    g = 0.15 + 0.7 * y
    b = 0.5 + 0.35 * np.sin(5.0 * x) * np.cos(4.0 * y)
    return np.stack([r, g, b], -1).astype(np.float32)


def initial_texture(n: int) -> np.ndarray:
    # Slightly off grey: at exact greys (r == g == b) pbr's RGB-to-spectrum table lookup
    # has a zero derivative in g and b (its flat-spectrum branch depends on r only).
    return np.broadcast_to(np.array([0.5, 0.48, 0.46], np.float32), (n, n, 3)).copy()


def scene_dict(texels: int, res: int, spp: int) -> dict:
    d = pbr.cornell_box(res, spp)
    del d["small-box"], d["large-box"]
    d["integrator"] = {"type": "path", "max_depth": 4, "hide_emitters": True}
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["back"]["bsdf"] = {"type": "diffuse",
                         "reflectance": {"type": "bitmap", "data": mi.TensorXf(true_texture(texels))}}
    return d


def main(small: bool = False, grad_scale: float = 1.0, log: bool = True, **overrides) -> C.Result:
    cfg = dict(SMALL if small else FULL, **overrides)
    n = cfg["texels"]
    scene = pbr.load_dict(scene_dict(n, cfg["res"], cfg["spp"]))
    refs = C.render_references(scene, cfg["ref_spp"])
    truth = true_texture(n)

    def error(params):
        return C.rmse(params[KEY], truth)

    res = C.optimize(scene, {KEY: mi.TensorXf(initial_texture(n))}, refs, n_iter=cfg["n_iter"],
                     lr=cfg["lr"], lr_final=cfg["lr_final"], spp=cfg["spp"], bounds={KEY: (0.0, 1.0)}, error=error,
                     grad_scale=grad_scale, log=log, name="albedo")
    if log:
        C.summary("optimize_albedo_texture", res, "texture RMSE")
    return res


if __name__ == "__main__":
    C.cli(main, __doc__)
