"""pbrt-v4's ``randomwalk`` and ``simplepath`` vs pbr's ``path`` (an independent estimator
with NEE and MIS, itself checked against Mitsuba) at the same path length.

Depth: pbrt-v4's ``maxdepth`` d is Mitsuba's ``max_depth`` d + 1, so ``maxdepth 2``
must match ``path`` at ``max_depth 3``; one bounce fewer must fail. The scene is the
Cornell box with its ceiling removed, lit by a constant environment through the open
top and front: randomwalk finds that light often (a small ceiling lamp is hit by a
uniform direction too rarely for a test-sized render), and no emitter touches a wall
(light sampling of a lamp next to a wall has an unbounded 1/r^2 tail without MIS)."""

import numpy as np
import pytest

import pbr
from pbr import validate
from mitsuba_scenes import BATCHES, RES

SPP = 1024


def open_box(integrator, scale=1):
    d = pbr.cornell_box(RES * scale, 16)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = dict(integrator, hide_emitters=True)
    del d["light"], d["ceiling"]
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [1.5, 1.2, 0.8]}}
    return d


def render_fn(d):
    s = pbr.load_dict(d)
    return lambda seed=0, spp=0: np.asarray(pbr.render(s, seed=seed, spp=spp))


def check(integrator, scale, path_depth=4):
    res = validate.compare_renders(render_fn(open_box(integrator, scale)),
                                   render_fn(open_box({"type": "path", "max_depth": path_depth}, scale)),
                                   spp=SPP * scale, batches=BATCHES, seed_a=51, seed_b=52)
    print(integrator, res.summary())
    return res


def test_randomwalk_matches_path(scale):
    assert check({"type": "randomwalk", "maxdepth": 3}, scale)


@pytest.mark.parametrize("lights, bsdf", [(True, True), (False, True), (True, False), (False, False)])
def test_simplepath_matches_path(lights, bsdf, scale):
    assert check({"type": "simplepath", "max_depth": 4, "samplelights": lights, "samplebsdf": bsdf}, scale)


def test_randomwalk_one_bounce_fewer_fails(scale):
    """maxdepth 2 (Mitsuba's max_depth 3) against path at max_depth 4."""
    res = check({"type": "randomwalk", "maxdepth": 2}, scale)
    assert not res.passed and res.mean_ratio < 1.0


@pytest.mark.parametrize("integrator", ["randomwalk", "simplepath"])
def test_depth_names(integrator):
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": integrator, "maxdepth": 3}
    assert pbr.load_dict(d).integrator.max_depth == 4
    d["integrator"] = {"type": integrator, "max_depth": 3}
    assert pbr.load_dict(d).integrator.max_depth == 3
    d["integrator"] = {"type": integrator, "maxdepth": 3, "max_depth": 4}
    with pytest.raises(pbr.SceneError, match="scene.integrator.max_depth"):
        pbr.load_dict(d)
    d["integrator"] = {"type": integrator, "maxdepth": -1}
    with pytest.raises(pbr.SceneError, match="scene.integrator.maxdepth"):
        pbr.load_dict(d)
