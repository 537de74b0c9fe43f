"""``depth`` (Mitsuba's depth integrator) against Mitsuba 3's own plugin (the statistical
image test, llvm_ad_spectral), on a Cornell box whose back wall is gone: pixels that
see through the opening miss (0), pixels on the edge average hits and misses.

The comparison's sensitivity is checked on two conventions that Mitsuba fixes: the
distance counted from the near clip plane (set to 0.5 here), not from the pinhole; and a
miss counted as 0, not as the far clip distance. Both variants must fail.
"""

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

import pbr
from pbr import validate
from pbr.integrators import depth as depth_mod

RES, SPP, BATCHES = 16, 256, 16


def scene():
    d = pbr.cornell_box(RES, 16)
    del d["back"]
    d["sensor"]["near_clip"] = 0.5
    # Box filter: with Mitsuba's Gaussian, pixels 2 away from an edge get its tail, which
    # Mitsuba splats into them from every sample and pbr samples (filter importance
    # sampling) so rarely that 256 spp see none: equal means, but no variance to test.
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = {"type": "depth"}
    return d


def compare(d):
    scene = pbr.load_dict(d)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))   # noqa: E731
    res = validate.compare_renders(fa, validate.mitsuba_render_fn(d), spp=SPP, batches=BATCHES, seed_a=5, seed_b=6)
    print(res.summary())
    return res


def test_depth_matches_mitsuba():
    res = compare(scene())
    assert res.passed, res.summary()


def test_distance_from_the_pinhole_fails(monkeypatch):
    sample = depth_mod.DepthIntegrator.sample

    def from_pinhole(self, scene, rng, ray, wl, mode, dL, L_in, active):
        L, hit = sample(self, scene, rng, ray, wl, mode, dL, L_in, active)
        cam = scene.sensors[0]
        local_z = dr.dot(ray.d, mi.Vector3f(*cam.to_world[:3, 2].tolist()))
        return dr.select(hit, L + cam.near_clip / local_z, L), hit
    monkeypatch.setattr(depth_mod.DepthIntegrator, "sample", from_pinhole)
    assert not compare(scene()).passed


def test_misses_at_the_far_clip_fail(monkeypatch):
    """Another renderer's convention: a miss at the far clip distance instead of 0."""
    sample = depth_mod.DepthIntegrator.sample

    def far(self, scene, rng, ray, wl, mode, dL, L_in, active):
        L, hit = sample(self, scene, rng, ray, wl, mode, dL, L_in, active)
        return dr.select(hit, L, ray.maxt), hit
    monkeypatch.setattr(depth_mod.DepthIntegrator, "sample", far)
    assert not compare(scene()).passed


def test_no_parameters_no_gradients():
    d = scene()
    d["integrator"] = {"type": "depth", "max_depth": 3}
    with pytest.raises(pbr.SceneError, match=r"scene\.integrator\.max_depth"):
        pbr.load_dict(d)
    sc = pbr.load_dict(scene())
    with pytest.raises(NotImplementedError, match="depth"):
        sc.integrator.render_forward(sc, spp=1)
