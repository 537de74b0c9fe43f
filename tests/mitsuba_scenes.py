"""Shared test scenes for comparisons with Mitsuba (pbr.validate)."""

import numpy as np
import mitsuba as mi

import pbr
from pbr import validate

RES, SPP, BATCHES = 24, 1024, 16


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
