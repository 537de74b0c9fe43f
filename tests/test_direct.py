"""``direct`` vs Mitsuba's ``direct`` (pbr.validate's statistical image test).

The material box (a diffuse and a smooth-plastic block, so that both the light samples
and the BSDF samples of a delta lobe reach the emitters) under an area light, a point
light and an environment map, with Mitsuba's sample counts. A variant without MIS
weights (both techniques counted in full) must fail."""

import numpy as np
import pytest

import pbr
from pbr import validate
from pbr.integrators import direct as direct_module
from mitsuba_scenes import BATCHES, SPP, lit_box

DIFFUSE = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}}
PLASTIC = {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}


def scene(lighting, scale, emitter_samples=1, bsdf_samples=1):
    d = lit_box(DIFFUSE, PLASTIC, lighting, scale)
    d["integrator"] = {"type": "direct", "emitter_samples": emitter_samples, "bsdf_samples": bsdf_samples,
                       "hide_emitters": True}
    return d


def check(d_pbr, d_mi, scale, spp=SPP // 2):
    s = pbr.load_dict(d_pbr)
    res = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(s, seed=seed, spp=spp)),
                                   validate.mitsuba_render_fn(d_mi), spp=spp * scale, batches=BATCHES,
                                   seed_a=31, seed_b=32)
    print(res.summary())
    return res


@pytest.mark.parametrize("lighting", ["area", "point", "envmap"])
def test_direct_matches_mitsuba(lighting, scale):
    d = scene(lighting, scale)
    assert check(d, d, scale)


@pytest.mark.parametrize("counts", [(4, 0), (0, 4), (3, 2)])
def test_direct_sample_counts_match_mitsuba(counts, scale):
    """With one count 0 the other technique has weight 1 (Mitsuba's fractions)."""
    d = scene("area", scale, *counts)
    assert check(d, d, scale)


def test_direct_delta_lights_weighted_per_sample(scale):
    """Mitsuba 3.9 adds a delta light's sample with weight 1 for each of the
    emitter_samples (4 samples: 4x too bright); pbr weights each by 1/4, so pbr's
    (4, 0) image equals Mitsuba's (1, 0) one."""
    assert check(scene("point", scale, 4, 0), scene("point", scale, 1, 0), scale)


def test_direct_without_mis_fails(monkeypatch, scale):
    """Counting both techniques in full (no MIS weights) must be detected."""
    monkeypatch.setattr(direct_module, "power_heuristic", lambda a, b: dr_one(a))
    d = scene("area", scale)
    res = check(d, d, scale)
    assert not res.passed and res.mean_ratio > 1.0


def dr_one(x):
    return x * 0.0 + 1.0


@pytest.mark.parametrize("params, key", [
    ({"emitter_samples": 0, "bsdf_samples": 0}, "scene.integrator.emitter_samples"),
    ({"shading_samples": 2, "bsdf_samples": 1}, "scene.integrator.shading_samples"),
    ({"emitter_samples": -1}, "scene.integrator.emitter_samples"),
])
def test_direct_invalid_parameters(params, key):
    d = pbr.cornell_box(8, 4)
    d["integrator"] = dict({"type": "direct"}, **params)
    with pytest.raises(pbr.SceneError, match=key):
        pbr.load_dict(d)
