"""Mitsuba scene features that Mitsuba's own render-test scenes use (issue 16): defaults
and value types pbr must read exactly as Mitsuba does. Whole-scene comparisons with
Mitsuba's references are in tests/test_mitsuba_suite.py."""

import numpy as np
import pytest

import pbr  # noqa: F401  (configures libLLVM before mitsuba is imported)
import mitsuba as mi

from pbr.cameras import SENSORS
from pbr.plugins.props import Props, SceneError


def _sensor(d):
    return SENSORS[d["type"]](Props(d, "scene.sensor"))


@pytest.mark.parametrize("size", [(40, 30), (30, 40), (48, 48)])
@pytest.mark.parametrize("extra", [{}, {"focal_length": "35mm"}, {"fov": 30.0, "fov_axis": "smaller"},
                                   {"fov": 50.0, "fov_axis": "diagonal"}, {"fov": 20.0, "fov_axis": "y"}])
def test_perspective_fov_matches_mitsuba(size, extra):
    """Without ``fov`` Mitsuba's perspective camera has a 50 mm focal length (a 35 mm
    film's diagonal); pbr's horizontal field of view equals Mitsuba's ``x_fov``."""
    film = {"type": "hdrfilm", "width": size[0], "height": size[1]}
    d = {"type": "perspective", "film": film, **extra}
    ref = float(mi.traverse(mi.load_dict(d))["x_fov"][0])
    assert _sensor(d).x_fov == pytest.approx(ref, rel=1e-5)


def test_perspective_fov_errors():
    film = {"type": "hdrfilm", "width": 8, "height": 8}
    with pytest.raises(SceneError, match="scene.sensor.fov: give either 'fov' or 'focal_length'"):
        _sensor({"type": "perspective", "film": film, "fov": 40.0, "focal_length": "50mm"})
    with pytest.raises(SceneError, match="scene.sensor.focal_length: expected e.g. '50mm'"):
        _sensor({"type": "perspective", "film": film, "focal_length": "wide"})


def test_transforms_of_any_mitsuba_variant():
    """Transform objects made under any variant are accepted (their Python type names
    differ: ``AffineTransform4f`` under ``scalar_rgb``); a 3x3 ``ScalarTransform3f``
    (a texture's ``to_uv``) expands as Mitsuba expands it (2x2 part and translation)."""
    T4 = mi.scalar_rgb.Transform4f().translate([1, 2, 3]).scale(2.0)  # named AffineTransform4f
    m = Props({"to_world": T4}, "scene.s").transform("to_world")
    assert np.allclose(m, np.array(T4.matrix))
    for T3 in (mi.scalar_rgb.ScalarTransform3f().scale([2, 3]).translate([0.5, 0.25]),
               mi.ScalarTransform3f().scale([2, 3]).translate([0.5, 0.25])):
        m = Props({"to_uv": T3}, "scene.t").transform("to_uv")
        expect = np.eye(4)
        expect[0, 0], expect[1, 1], expect[0, 3], expect[1, 3] = 2, 3, 1.0, 0.75
        assert np.allclose(m, expect)
    with pytest.raises(SceneError, match="scene.s.to_world: expected a transform"):
        Props({"to_world": "rotate"}, "scene.s").transform("to_world")
