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


# ------------------------------------------------------------------ mesh files

CUBE_OBJ = """v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1
vn 0 0 -1\nvn 0 0 1\nvn 0 -1 0\nvn 1 0 0\nvn 0 1 0\nvn -1 0 0
f 1/1/1 4/4/1 3/3/1 2/2/1\nf 5/1/2 6/2/2 7/3/2 8/4/2\nf 1/1/3 2/2/3 6/3/3 5/4/3
f 2/1/4 3/2/4 7/3/4 6/4/4\nf 3/1/5 4/2/5 8/3/5 7/4/5\nf 4/1/6 1/2/6 5/3/6 8/4/6
"""


def _mesh_buffers(shape):
    p = mi.traverse(shape)
    return {k: np.array(p[k]) for k in ("vertex_positions", "vertex_normals", "vertex_texcoords", "faces")}


def test_obj_corners_split_like_mitsuba(tmp_path):
    """An OBJ vertex with different normals or uvs at different corners (a cube with
    per-face normals, Mitsuba's test meshes) becomes one vertex per distinct corner, as
    Mitsuba's loader makes it: same buffers, so the same shading normals and uvs (a single
    vertex per position gave the lit side of an emitting cube the wrong normals)."""
    path = tmp_path / "cube.obj"
    path.write_text(CUBE_OBJ)
    T = mi.ScalarTransform4f().translate([0.5, -1, 2]).rotate([0.6, 0.8, 0], 30).scale([1, 2, 0.5])
    d = {"type": "obj", "filename": str(path), "to_world": T}
    scene = pbr.load_dict({"type": "scene", "cube": d})
    ours, theirs = _mesh_buffers(scene.mi_scene.shapes()[0]), _mesh_buffers(mi.load_dict(d))
    assert len(ours["vertex_positions"]) == 24 * 3
    for k in theirs:
        assert np.allclose(ours[k], theirs[k], atol=1e-6), k


def _write_serialized(path, meshes):
    """Mitsuba's serialized format, version 4: per mesh a header and a zlib stream
    (flags, name, counts, float32 positions [, normals][, uvs], uint32 faces); then the
    meshes' offsets and their count."""
    import struct
    import zlib
    out, offsets = b"", []
    for v, f, uv in meshes:
        offsets.append(len(out))
        flags = 0x1000 | (0x0002 if uv is not None else 0)
        body = struct.pack("<I", flags) + b"m\0" + struct.pack("<QQ", len(v), len(f))
        body += np.asarray(v, "<f4").tobytes() + (np.asarray(uv, "<f4").tobytes() if uv is not None else b"")
        body += np.asarray(f, "<u4").tobytes()
        out += struct.pack("<HH", 0x041C, 4) + zlib.compress(body)
    out += np.asarray(offsets, "<u8").tobytes() + struct.pack("<I", len(meshes))
    path.write_bytes(out)


def test_serialized_meshes(tmp_path):
    """``serialized`` meshes load (the shape of ``shape_index``, with ``to_world``) as in Mitsuba."""
    quad = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    faces = [[0, 1, 2], [0, 2, 3]]
    path = tmp_path / "two.serialized"
    _write_serialized(path, [(quad, faces, None), (quad * [3, 1, 1], faces, quad[:, :2] * 0.5 + 0.5)])
    d = {"type": "serialized", "filename": str(path), "shape_index": 1,
         "to_world": mi.ScalarTransform4f().translate([0, 0, 2])}
    scene = pbr.load_dict({"type": "scene", "s": d})
    ours, theirs = _mesh_buffers(scene.mi_scene.shapes()[0]), _mesh_buffers(mi.load_dict(d))
    for k in theirs:
        assert np.allclose(ours[k], theirs[k]), k
    assert np.allclose(np.array(scene.mi_scene.bbox().max), [3, 1, 2])
    with pytest.raises(SceneError, match=r"scene\.s\.filename: cannot read mesh .*out of range"):
        pbr.load_dict({"type": "scene", "s": {**d, "shape_index": 5}})
