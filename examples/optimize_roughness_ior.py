"""Recover the roughness ``alpha`` and the index of refraction ``eta`` of a rough glass
sphere (``roughdielectric``, GGX) from images taken from two viewpoints (one in the
small configuration).

The sphere stands in front of an emitting checkerboard and under a dim constant sky:
``eta`` sets how the sphere magnifies and flips the checkerboard seen through it (and
its Fresnel reflection of the sky), ``alpha`` how much it blurs it. Errors: absolute
errors of ``alpha`` and ``eta`` (``Result.error`` is the larger one).

    python examples/optimize_roughness_ior.py [--small]
"""

from __future__ import annotations

import os
import sys


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402  (imports pbr first)

import pbr  # noqa: E402
import mitsuba as mi  # noqa: E402

ALPHA, ETA = "glass.bsdf.alpha.value", "glass.bsdf.eta"
TRUE = {ALPHA: 0.08, ETA: 1.5}
INIT = {ALPHA: 0.25, ETA: 1.3}
BOUNDS = {ALPHA: (0.02, 1.0), ETA: (1.05, 2.5)}
FULL = dict(res=64, views=2, spp=16, ref_spp=1024, n_iter=100, lr={ALPHA: 0.02, ETA: 0.02}, lr_final=0.1)
SMALL = dict(res=24, views=1, spp=16, ref_spp=256, n_iter=12, lr={ALPHA: 0.04, ETA: 0.04}, lr_final=0.3)
VIEWS = [(0.0, 0.3, 4.0), (2.6, 1.2, 3.0)]        # front, and from the upper right


def scene_dict(res: int, spp: int, views: int = 2, alpha: float = TRUE[ALPHA], eta: float = TRUE[ETA]) -> dict:
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 6}}
    for i, o in enumerate(VIEWS[:views]):
        d[f"sensor_{i}"] = C.look_at_sensor(o, (0, 0, 0), fov=32.0, res=res, spp=spp)
    d["glass"] = {"type": "sphere", "radius": 0.6,
                  "bsdf": {"type": "roughdielectric", "distribution": "ggx", "alpha": alpha,
                           "int_ior": eta, "ext_ior": 1.0}}
    d["backdrop"] = {"type": "rectangle", "to_world": C.transform().translate([0, 0, -1.6]).scale(3.0),
                     "emitter": {"type": "area", "radiance": {
                         "type": "checkerboard", "color0": {"type": "rgb", "value": [1.0, 0.9, 0.6]},
                         "color1": {"type": "rgb", "value": [0.1, 0.2, 0.6]},
                         "to_uv": C.transform().scale([8.0, 8.0, 1.0])}}}
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.3, 0.3, 0.3]}}
    return d


def main(small: bool = False, grad_scale: float = 1.0, log: bool = True, **overrides) -> C.Result:
    cfg = dict(SMALL if small else FULL, **overrides)
    scene = pbr.load_dict(scene_dict(cfg["res"], cfg["spp"], cfg["views"]))
    refs = C.render_references(scene, cfg["ref_spp"])

    def error(params):
        return max(abs(float(params[k].array[0]) - TRUE[k]) for k in TRUE)

    init = {k: mi.Float(v) for k, v in INIT.items()}
    res = C.optimize(scene, init, refs, n_iter=cfg["n_iter"], lr=cfg["lr"], lr_final=cfg["lr_final"],
                     spp=cfg["spp"], bounds=BOUNDS, error=error, grad_scale=grad_scale, log=log,
                     name="roughness_ior")
    if log:
        for k in TRUE:
            v = float(res.values[k].ravel()[0])
            print(f"  {k}: {INIT[k]:.3f} -> {v:.4f} (true {TRUE[k]}, |error| {abs(v - TRUE[k]):.4f})")
        C.summary("optimize_roughness_ior", res, "max |error|")
    return res


if __name__ == "__main__":
    C.cli(main, __doc__)
