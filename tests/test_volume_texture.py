"""Mitsuba's ``volume`` texture (a ``gridvolume`` read at the surface point's world
position; the Mitsuba tutorials' lego scene declares one): renders against Mitsuba with an
RGB grid smaller than the surfaces it colours (the lookup clamps outside the grid's box),
the XML form of the tutorial, and errors naming the key path.

Must fail: before the ``volume`` texture existed the scenes did not load; with the
lookup bounded as a medium's (zero outside the box) the render comparison fails."""

import numpy as np
import pytest

import pbr
from pbr.media.grid import write_vol
from pbr.plugins.props import SceneError
from mitsuba_scenes import material_box, compare_with_mitsuba

# 2x2x2 RGB voxels, all different (nz, ny, nx, 3).
GRID = np.array([[[[0.9, 0.1, 0.1], [0.1, 0.9, 0.1]], [[0.1, 0.1, 0.9], [0.8, 0.8, 0.1]]],
                 [[[0.1, 0.8, 0.8], [0.8, 0.1, 0.8]], [[0.5, 0.5, 0.5], [0.95, 0.6, 0.3]]]], np.float32)


def volume_texture(path, to_world=None):
    vol = {"type": "gridvolume", "filename": path}
    if to_world is not None:
        vol["to_world"] = to_world
    return {"type": "volume", "volume": vol}


def test_volume_texture_matches_mitsuba(tmp_path, scale):
    """The grid's box covers [-0.5, 0.5]^3, less than the blocks: the rest is clamped."""
    import mitsuba as mi
    f = str(tmp_path / "grid.vol")
    write_vol(f, GRID)
    box = mi.ScalarTransform4f().translate([-0.5, -0.5, -0.5])
    tex = volume_texture(f, box)
    d = material_box({"type": "diffuse", "reflectance": tex}, {"type": "diffuse", "reflectance": tex}, scale)
    res = compare_with_mitsuba(d, scale)
    print(res.summary())
    assert res.passed, res.summary()


TUTORIAL = """<scene version="3.0.0">
    <bsdf type="diffuse" id="main-bsdf">
        <texture type="volume" name="reflectance">
            <volume type="gridvolume" name="volume">
                <string name="filename" value="{}"/>
            </volume>
        </texture>
    </bsdf>
    <shape type="sphere"/>
</scene>"""

LAM = (450.0, 520.0, 600.0, 680.0)
# A voxel centre, a point between voxels, points outside the unit cube (clamped).
POINTS = np.array([[0.25, 0.25, 0.25], [0.6, 0.3, 0.45], [2.0, -1.0, 0.5], [-3.0, 0.7, 9.0]])


def test_volume_texture_values_match_mitsuba(tmp_path):
    """The tutorial's XML form (lego/scene.xml) loads, and the texture's values at surface
    points inside and outside the grid's box equal Mitsuba's ``volume`` texture's."""
    import drjit as dr
    import mitsuba as mi
    f = str(tmp_path / "grid.vol")
    write_vol(f, GRID)
    scene = pbr.load_string(TUTORIAL.format(f))
    T = scene.textures
    slot = [s for s, t in enumerate(T.items) if type(t).__name__ == "VolumeTexture"]
    assert len(slot) == 1
    n = len(POINTS)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.p = mi.Point3f(*(mi.Float(POINTS[:, k]) for k in range(3)))
    si.wavelengths = mi.Spectrum(*[mi.Float([l] * n) for l in LAM])
    ours = np.array(T.eval(mi.UInt32([slot[0]] * n), si, si.wavelengths, mi.Bool(True), False))
    theirs = np.array(mi.load_dict(volume_texture(f)).eval(si))
    assert np.allclose(ours, theirs, rtol=1e-4, atol=1e-6), (ours, theirs)
    assert np.ptp(ours) > 0.3     # the points see different voxels


def test_volume_texture_errors(tmp_path):
    with pytest.raises(SceneError, match=r"scene\.b\.reflectance\.volume: expected a gridvolume"):
        pbr.load_dict({"type": "scene", "b": {"type": "diffuse", "reflectance": {"type": "volume"}}})
    with pytest.raises(SceneError, match=r"reflectance\.volume.*filename"):
        pbr.load_dict({"type": "scene", "b": {"type": "diffuse", "reflectance": {
            "type": "volume", "volume": {"type": "gridvolume", "filename": str(tmp_path / "missing.vol")}}}})
