"""twosided: the back side uses the (second) nested BSDF, mirrored through the surface."""

import numpy as np
import mitsuba as mi
import pytest

import pbr
from bsdf_harness import OneBSDF, chi2_bsdf, direction
from mitsuba_scenes import material_box, compare_with_mitsuba


def test_back_side_mirrors_front():
    one = OneBSDF({"type": "roughconductor", "distribution": "ggx", "alpha": 0.3})
    two = OneBSDF({"type": "twosided", "b": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3}})
    wi, wo = direction(30, 10), direction(50, 200)
    below = lambda v: mi.Vector3f(v.x, v.y, -v.z)  # noqa: E731
    f1, p1 = one.eval_pdf(wi, wo)
    f2, p2 = two.eval_pdf(below(wi), below(wo))
    assert np.allclose(np.array(f1), np.array(f2)) and np.allclose(np.array(p1), np.array(p2))
    assert np.array(f1).max() > 0
    # A one-sided BSDF is black from below.
    assert np.array(one.eval_pdf(below(wi), below(wo))[0]).max() == 0


def test_two_different_sides():
    two = OneBSDF({"type": "twosided",
                   "front": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}},
                   "back": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.2, 0.2]}}})
    wi, wo = direction(20), direction(40)
    below = lambda v: mi.Vector3f(v.x, v.y, -v.z)  # noqa: E731
    front = np.array(two.eval_pdf(wi, wo)[0]).mean()
    back = np.array(two.eval_pdf(below(wi), below(wo))[0]).mean()
    assert front / back == pytest.approx(4.0, rel=0.05)


def test_chi2_from_below():
    ok, msg = chi2_bsdf({"type": "twosided", "b": {"type": "roughconductor", "alpha": 0.4}}, direction(140, 30))
    assert ok, msg


def test_errors_name_the_key():
    with pytest.raises(pbr.SceneError, match="scene.b: twosided takes one or two"):
        d = pbr.cornell_box(8, 4)
        d["b"] = {"type": "twosided"}
        pbr.load_dict(d)


def test_matches_mitsuba(scale):
    d = material_box({"type": "twosided", "x": {"type": "roughconductor", "alpha": 0.3, "material": "Al"}},
                     {"type": "twosided",
                      "f": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.6, 0.3]}},
                      "b": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.2, 0.2]}}}, scale)
    # Flip the large box's faces so that the camera sees their back sides.
    d["large-box"]["flip_normals"] = True
    res = compare_with_mitsuba(d, scale)
    print(res.summary())
    assert res.passed, res.summary()
