"""Shared test scenes for comparisons with Mitsuba (pbr.validate)."""

import os

import numpy as np
import mitsuba as mi

import pbr
from pbr import validate

RES, SPP, BATCHES = 24, 1024, 16


def gradient_png(tmp_path) -> str:
    """An 8x8 colour-gradient PNG (a bitmap texture for comparisons); returns its path."""
    img = np.zeros((8, 8, 3), np.float32)
    img[..., 0] = np.linspace(0.05, 0.9, 8)[None, :]
    img[..., 1] = np.linspace(0.9, 0.1, 8)[:, None]
    img[..., 2] = 0.3
    png = str(tmp_path / "tex.png")
    pbr.write_image(png, img)
    return png


def run_notebook(path: str, replace: dict | None = None) -> dict:
    """Execute a notebook's code cells in order (after the textual ``replace``ments, e.g.
    smaller sizes) and return its namespace. No Jupyter needed."""
    import json
    nb = json.load(open(path))
    ns = {}
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            src = "".join(cell["source"])
            for a, b in (replace or {}).items():
                src = src.replace(a, b)
            exec(compile(src, os.path.basename(path), "exec"), ns)
    return ns


def sky_image(h=16, w=32):
    """A small synthetic HDR sky: a bright sun-like blob over a blue-to-orange gradient."""
    y, x = np.mgrid[0:h, 0:w]
    img = np.zeros((h, w, 3), np.float32)
    t = y / (h - 1)
    img[..., 0] = 0.3 + 0.7 * t
    img[..., 1] = 0.4 + 0.2 * t
    img[..., 2] = 1.0 - 0.6 * t
    sun = np.exp(-((x - w * 0.3) ** 2 + (y - h * 0.3) ** 2) / 3.0)
    return img + 20.0 * sun[..., None] * np.array([1.0, 0.9, 0.7], np.float32)


def lit_box(bsdf_small: dict, bsdf_large: dict | None = None, lighting: str = "area", scale=1):
    """material_box under another light: 'point' (a point light inside the box instead of
    the ceiling light) or 'envmap' (an environment seen through the open front; the box's
    back wall is removed so that the sky lights the scene)."""
    d = material_box(bsdf_small, bsdf_large, scale)
    if lighting == "point":
        del d["light"]
        d["point"] = {"type": "point", "position": [0.2, 0.7, 0.6],
                      "intensity": {"type": "rgb", "value": [3.0, 2.6, 2.2]}}
    elif lighting == "envmap":
        del d["light"], d["back"], d["ceiling"]
        d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(sky_image()), "scale": 1.0}
    return d


def material_box(bsdf_small: dict, bsdf_large: dict | None = None, scale=1, max_depth=6):
    """The Cornell box with the two blocks made of the given BSDFs. Emitters are hidden
    (small variance of the image mean; see test_mitsuba_compare) and the film uses a box
    filter: with filter importance sampling, a black pixel next to bright ones receives
    their light only through rare far-tail samples, whose per-batch variance estimate is
    usually 0, which breaks the z-test's normal approximation (seen on a mirror box
    reflecting the open front). The Gaussian film itself is tested in test_mitsuba_compare."""
    d = pbr.cornell_box(RES * scale, 16)
    d["integrator"] = {"type": "path", "max_depth": max_depth, "hide_emitters": True}
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["small-box"]["bsdf"] = bsdf_small
    if bsdf_large is not None:
        d["large-box"]["bsdf"] = bsdf_large
    return d


def compare_with_mitsuba(d, scale=1, spp=SPP, seed_a=21, seed_b=22):
    scene = pbr.load_dict(d)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))  # noqa: E731
    return validate.compare_renders(fa, validate.mitsuba_render_fn(d), spp=spp * scale, batches=BATCHES,
                                    seed_a=seed_a, seed_b=seed_b)
