"""mask (opacity) and null (pass-through)."""

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

from bsdf_harness import OneBSDF, chi2_bsdf, direction
from mitsuba_scenes import material_box, compare_with_mitsuba


def test_null_passes_straight_through():
    b = OneBSDF({"type": "null"})
    wi = direction(35, 70)
    bs = b.sample(wi, mi.Float(0.3), mi.Point2f(0.2, 0.9))
    assert np.allclose(np.array(bs.wo).ravel(), -np.array(wi).ravel())
    assert np.allclose(np.array(bs.weight), 1.0) and bool(bs.delta[0])


def test_mask_probability_and_eval_scale():
    m = OneBSDF({"type": "mask", "opacity": 0.3, "b": {"type": "diffuse", "reflectance": 0.6}})
    d = OneBSDF({"type": "diffuse", "reflectance": 0.6})
    wi, wo = direction(20), direction(50, 120)
    assert np.allclose(np.array(m.eval_pdf(wi, wo)[0]), 0.3 * np.array(d.eval_pdf(wi, wo)[0]), rtol=1e-5)
    n = 1 << 16
    u = (dr.arange(mi.Float, n) + 0.5) / n
    bs = m.sample(wi, u, mi.Point2f(u, 1.0 - u))
    through = np.array(bs.delta)
    assert through.mean() == pytest.approx(0.7, abs=2e-3)
    assert np.allclose(np.array(bs.wo)[:, through], -np.array(wi), atol=1e-6)


def test_chi2_masked_lobe():
    ok, msg = chi2_bsdf({"type": "mask", "opacity": 0.4,
                         "b": {"type": "roughconductor", "alpha": 0.3}}, direction(40))
    assert ok, msg


def test_matches_mitsuba(scale):
    d = material_box({"type": "mask", "opacity": 0.35,
                      "b": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.8, 0.3]}}},
                     {"type": "mask", "opacity": 0.6,
                      "b": {"type": "twosided", "c": {"type": "roughconductor", "alpha": 0.2}}}, scale)
    res = compare_with_mitsuba(d, scale)
    print(res.summary())
    assert res.passed, res.summary()
