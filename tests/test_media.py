"""Participating media and the volumetric integrators (volpath, simplevolpath).

Statistical image comparisons with Mitsuba's ``volpath`` (pbr.validate), consistency
checks that need no reference (the majorant grid changes nothing but the cost; the
simple and MIS estimators agree), phase-function sampling (chi-square), and the
extremes of the parameter ranges."""

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import validate
from pbr.media.grid import write_vol, read_vol, cell_maxima

from mitsuba_scenes import material_box, compare_with_mitsuba


def fog_ball(medium, bsdf="null", integrator="volpath", max_depth=6):
    """The material box (hidden ceiling light, box filter) with a sphere of medium."""
    d = material_box({"type": "diffuse"}, max_depth=max_depth)
    d["integrator"]["type"] = integrator
    d["ball"] = {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.35,
                 "bsdf": {"type": bsdf} if isinstance(bsdf, str) else bsdf, "interior": medium}
    return d


def blob(n=16):
    """A smooth density blob (max 12) with an empty slab: sparse enough for the majorant grid."""
    z, y, x = np.mgrid[0:n, 0:n, 0:n] / (n - 1.0)
    g = np.exp(-((x - 0.5) ** 2 + (y - 0.4) ** 2 + (z - 0.6) ** 2) / 0.05) * 12.0
    g[:, :, : n // 4] = 0.0
    return g.astype(np.float32)


def grid_cube(vol_path, albedo=0.85):
    T = mi.ScalarTransform4f
    d = material_box({"type": "diffuse"})
    d["integrator"]["type"] = "volpath"
    # Above both blocks: a medium boundary must not overlap or touch other surfaces
    # (a cloud cube at the origin cuts the large block and is coplanar with the small
    # block's top, and the two renderers then resolve the ambiguity differently).
    c, h = np.array([0.1, 0.55, 0.1]), 0.3
    d["cloud"] = {"type": "cube", "to_world": T().translate(c.tolist()).scale(h), "bsdf": {"type": "null"},
                  "interior": {"type": "heterogeneous", "albedo": albedo,
                               "sigma_t": {"type": "gridvolume", "filename": vol_path,
                                           "to_world": T().translate((c - h).tolist()).scale(2 * h)}}}
    return d


def _check(res, label):
    print(f"{label}: {res}")
    assert res.passed, f"{label}: {res}"


# -- statistical comparisons with Mitsuba's volpath ------------------------------------------
COMPARISONS = {
    "homogeneous-null": lambda tmp: fog_ball({"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.8,
                                              "phase": {"type": "hg", "g": 0.6}}),
    "homogeneous-dielectric": lambda tmp: fog_ball(
        {"type": "homogeneous", "sigma_t": 2.0, "albedo": {"type": "rgb", "value": [0.9, 0.6, 0.3]}},
        bsdf={"type": "dielectric", "int_ior": 1.33}),
    "chromatic": lambda tmp: fog_ball({"type": "homogeneous", "scale": 8.0, "albedo": 0.9,
                                       "sigma_t": {"type": "rgb", "value": [0.1, 0.5, 0.9]}}),
    "rayleigh": lambda tmp: fog_ball({"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.9,
                                      "phase": {"type": "rayleigh"}}),
}


@pytest.mark.parametrize("name", sorted(COMPARISONS))
def test_volpath_matches_mitsuba(name, tmp_path, scale):
    _check(compare_with_mitsuba(COMPARISONS[name](tmp_path), scale), name)


def test_heterogeneous_grid_matches_mitsuba(tmp_path, scale):
    vol = str(tmp_path / "blob.vol")
    write_vol(vol, blob())
    _check(compare_with_mitsuba(grid_cube(vol), scale), "grid")
