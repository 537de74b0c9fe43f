"""Tests for pbr.scene.xml: Mitsuba XML -> Mitsuba dict, checked against Mitsuba."""
import os
import re

import numpy as np
import pytest

import pbr  # noqa: F401  (configures libLLVM before mitsuba is imported)
import mitsuba as mi

from pbr.scene.xml import XMLError, parse_file, parse_string

# Mitsuba's variant is pbr's (conftest selects PBR_TEST_BACKEND's before this import).

CORNELL = """<?xml version="1.0"?>
<scene version="3.0.0">
    <default name="res" value="16"/>
    <default name="spp" value="4"/>
    <integrator type="path">
        <integer name="max_depth" value="4"/>
    </integrator>
    <sensor type="perspective" id="cam">
        <float name="fov" value="39.3"/>
        <transform name="to_world">
            <lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="$spp"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="$res"/>
            <integer name="height" value="$res"/>
            <rfilter type="gaussian"/>
            <string name="pixel_format" value="rgb"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="white">
        <rgb name="reflectance" value="0.885809, 0.698859, 0.666422"/>
    </bsdf>
    <bsdf type="diffuse" id="red">
        <rgb name="reflectance" value="0.570068, 0.0430135, 0.0443706"/>
    </bsdf>
    <bsdf type="diffuse" id="green">
        <spectrum name="reflectance" value="400:0.1, 500:0.6, 600:0.1, 700:0.05"/>
    </bsdf>
    <shape type="rectangle" id="light">
        <transform name="to_world">
            <scale x="0.23" y="0.19" z="1"/>
            <rotate x="1" angle="90"/>
            <translate y="0.99" z="-0.01"/>
        </transform>
        <ref id="white"/>
        <emitter type="area">
            <rgb name="radiance" value="18.387, 13.9873, 6.75357"/>
        </emitter>
    </shape>
    <shape type="rectangle" id="floor">
        <transform name="to_world"><rotate value="1 0 0" angle="-90"/>
            <translate value="0, -1, 0"/></transform>
        <ref name="bsdf" id="white"/>
    </shape>
    <shape type="rectangle" id="ceiling">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle" id="back">
        <transform name="to_world"><translate z="-1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle" id="greenwall">
        <transform name="to_world"><rotate y="1" angle="-90"/><translate x="1"/></transform>
        <ref id="green"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate y="1" angle="90"/><translate x="-1"/></transform>
        <ref id="red"/>
    </shape>
    <shape type="cube">
        <transform name="to_world">
            <matrix value="0.3 0 0 0.3  0 0.6 0 -0.4  0 0 0.3 -0.3  0 0 0 1"/>
            <rotate y="1" angle="20"/>
        </transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>
</scene>
"""


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def scene_xml(body, version="3.0.0"):
    return f'<scene version="{version}">\n{body}\n</scene>\n'


def mat(t):
    return np.array(t.matrix, dtype=np.float64)


# ---------------------------------------------------------------- end to end

def test_cornell_matches_mitsuba_load_file(tmp_path):
    path = write(tmp_path, "cornell.xml", CORNELL)
    d = parse_file(path, res=24)
    assert d["type"] == "scene"
    assert d["light"]["ref_0"] == {"type": "ref", "id": "white"}
    assert d["floor"]["bsdf"] == {"type": "ref", "id": "white"}
    assert d["cam"]["film_0"]["width"] == 24
    assert d["green"]["reflectance"]["value"][0] == (400.0, 0.1)
    ref_scene = mi.load_file(path, res=24)
    our_scene = mi.load_dict(d)
    ref = np.asarray(mi.render(ref_scene, spp=4, seed=0))
    ours = np.asarray(mi.render(our_scene, spp=4, seed=0))
    assert ref.shape == ours.shape == (24, 24, 3)
    assert ref.max() > 0.05  # the image is not black
    # Mitsuba's CUDA film splats the gaussian filter with float atomics, whose order varies
    # between launches: the same scene then differs from itself (on LLVM it does not).
    again = np.asarray(mi.render(ref_scene, spp=4, seed=0))
    assert np.allclose(ours, ref, atol=1e-6 + 2 * np.abs(again - ref).max(), rtol=0)
    # Different seeds give different images, so the comparison above has teeth.
    other = np.asarray(mi.render(our_scene, spp=4, seed=1))
    assert not np.allclose(other, ref, atol=1e-6, rtol=0)


# ---------------------------------------------------------------- properties

def test_property_kinds(tmp_path):
    d = parse_string(scene_xml("""
    <shape type="sphere" id="s">
        <float name="radius" value="2.5e-1"/>
        <integer name="n" value=" 7 "/>
        <boolean name="flip_normals" value="True"/>
        <boolean name="b2" value="false"/>
        <string name="s" value="hello world"/>
        <point name="center" value="1, 2, 3"/>
        <vector name="v" x="4" y="5" z="-6"/>
        <point name="p1" value="2"/>
        <bsdf type="diffuse" name="mat"><rgb name="reflectance" value="0.25"/></bsdf>
    </shape>
    <bsdf type="roughconductor" id="c">
        <rgb name="eta" value="0.1 0.2 0.3"/>
        <spectrum name="k" value="0.5"/>
        <spectrum name="specular_reflectance" value="400:0.1, 500:0.2 600:0.3"/>
        <blackbody name="bb" temperature="3000"/>
        <texture type="bitmap" name="alpha" id="tex">
            <string name="filename" value="does_not_exist.png"/>
        </texture>
        <spectrum type="uniform" name="other"><float name="value" value="2"/></spectrum>
    </bsdf>"""))
    s = d["s"]
    assert s["type"] == "sphere" and "id" not in s
    assert s["radius"] == 0.25 and isinstance(s["radius"], float)
    assert s["n"] == 7 and isinstance(s["n"], int)
    assert s["flip_normals"] is True and s["b2"] is False
    assert s["s"] == "hello world"
    assert s["center"] == [1.0, 2.0, 3.0]
    assert s["v"] == [4.0, 5.0, -6.0]
    assert s["p1"] == [2.0, 2.0, 2.0]
    assert s["mat"] == {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.25] * 3}}
    c = d["c"]
    assert c["eta"] == {"type": "rgb", "value": [0.1, 0.2, 0.3]}
    assert c["k"] == {"type": "spectrum", "value": 0.5}
    assert c["specular_reflectance"] == {"type": "spectrum",
                                         "value": [(400.0, 0.1), (500.0, 0.2), (600.0, 0.3)]}
    assert c["bb"] == {"type": "blackbody", "temperature": 3000.0}
    # nested object with name and id: keyed by name, carries its id
    assert c["alpha"] == {"type": "bitmap", "id": "tex", "filename": "does_not_exist.png"}
    assert c["other"] == {"type": "uniform", "value": 2.0}


def test_spectrum_filename_and_relative_paths(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "a.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "eta.spd").write_text("400 1.5\n700 1.4\n")
    path = write(tmp_path, "s.xml", scene_xml("""
    <shape type="obj" id="mesh"><string name="filename" value="meshes/a.obj"/></shape>
    <shape type="obj" id="missing"><string name="filename" value="meshes/none.obj"/></shape>
    <bsdf type="dielectric" id="d"><spectrum name="int_ior" filename="eta.spd"/></bsdf>"""))
    old = os.getcwd()
    os.chdir("/")  # relative paths must not depend on the working directory
    try:
        d = parse_file(path)
    finally:
        os.chdir(old)
    assert d["mesh"]["filename"] == str(tmp_path / "meshes" / "a.obj")
    assert d["missing"]["filename"] == "meshes/none.obj"
    assert d["d"]["int_ior"] == {"type": "spectrum", "filename": str(tmp_path / "eta.spd")}
    scene = mi.load_dict({"type": "scene", "mesh": d["mesh"]})
    assert np.allclose(np.array(scene.bbox().max), [1, 1, 0])


def test_generated_keys_and_ids(tmp_path):
    d = parse_string(scene_xml("""
    <shape type="sphere"/>
    <shape type="sphere"><bsdf type="diffuse" id="m"/></shape>
    <shape type="sphere" id="shape_0"/>
    <shape type="sphere"><ref id="m"/><ref id="m" name="x"/></shape>
    <emitter type="constant"/>"""))
    # the explicit id "shape_0" displaced the generated key of the first shape
    assert list(d) == ["type", "shape_2", "shape_1", "shape_0", "shape_3", "emitter_0"]
    assert d["shape_2"] == {"type": "sphere"}
    assert d["shape_1"]["m"] == {"type": "diffuse", "id": "m"}
    assert d["shape_3"] == {"type": "sphere", "ref_0": {"type": "ref", "id": "m"},
                            "x": {"type": "ref", "id": "m"}}
    # the nested id is referable once Mitsuba loads the dict
    scene = mi.load_dict({"type": "scene", "a": d["shape_1"],
                          "b": {"type": "sphere", "bsdf": {"type": "ref", "id": "m"}}})
    assert [s.bsdf().id() for s in scene.shapes()] == ["m", "m"]


def test_alias_and_forward_reference():
    d = parse_string(scene_xml("""
    <shape type="sphere"><ref id="later"/></shape>
    <bsdf type="diffuse" id="later"/>
    <alias id="later" as="other"/>
    <shape type="sphere"><ref id="other"/></shape>"""))
    assert d["shape_0"]["ref_0"]["id"] == "later"
    assert d["shape_1"]["ref_0"]["id"] == "later"
    assert "other" not in d
    mi.load_dict(d)


def test_non_scene_root():
    d = parse_string('<bsdf version="3.0.0" type="diffuse">'
                     '<rgb name="reflectance" value="0.1, 0.2, 0.3"/></bsdf>')
    assert d == {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.1, 0.2, 0.3]}}


# ----------------------------------------------------- defaults, $subst, include

def test_defaults_and_overrides(tmp_path):
    text = scene_xml("""
    <default name="r" value="0.5"/>
    <default name="kind" value="sphere"/>
    <default name="flag" value="false"/>
    <shape type="$kind" id="s_$kind">
        <float name="radius" value="$r"/>
        <string name="label" value="r=$r, kind=$kind!"/>
        <boolean name="flip_normals" value="$flag"/>
    </shape>""")
    path = write(tmp_path, "d.xml", text)
    d = parse_file(path)
    assert d["s_sphere"] == {"type": "sphere", "radius": 0.5, "label": "r=0.5, kind=sphere!",
                             "flip_normals": False}
    d = parse_file(path, r=2, flag=True)
    assert d["s_sphere"]["radius"] == 2.0 and d["s_sphere"]["flip_normals"] is True
    assert parse_string(text, r="0.25")["s_sphere"]["radius"] == 0.25
    # a parameter with no <default> may be supplied by keyword
    d = parse_string(scene_xml('<shape type="sphere" id="a"><float name="radius" value="$x"/>'
                               '</shape>'), x=3)
    assert d["a"]["radius"] == 3.0
    # matches Mitsuba
    path = write(tmp_path, "e.xml", scene_xml("""
    <default name="r" value="0.5"/>
    <shape type="sphere"><float name="radius" value="$r"/></shape>"""))
    s1 = mi.load_dict(parse_file(path, r=2))
    s2 = mi.load_file(path, r=2)
    assert np.allclose(np.array(s1.bbox().max), np.array(s2.bbox().max))
    assert np.allclose(np.array(s1.bbox().max), [2, 2, 2])


def test_include(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "top.obj").write_text("v 0 0 0\nv 5 0 0\nv 0 5 0\nf 1 2 3\n")
    write(tmp_path, "sub/mats.xml", scene_xml("""
    <bsdf type="diffuse" id="mat"/>
    <include filename="more.xml"/>
    <shape type="obj" id="m"><string name="filename" value="top.obj"/><ref id="mat"/></shape>
    """))
    write(tmp_path, "sub/more.xml", '<scene version="3.0.0"><shape type="sphere" id="inner">'
                                    '<float name="radius" value="$r"/></shape></scene>')
    path = write(tmp_path, "main.xml", scene_xml("""
    <default name="r" value="3"/>
    <shape type="sphere" id="first"/>
    <include filename="sub/mats.xml"/>
    <shape type="sphere" id="last"><ref id="mat"/></shape>"""))
    d = parse_file(path)
    assert list(d) == ["type", "first", "mat", "inner", "m", "last"]
    assert d["inner"]["radius"] == 3.0
    # relative filenames fall back to the main file's directory (as in Mitsuba)
    assert d["m"]["filename"] == str(tmp_path / "top.obj")
    s1, s2 = mi.load_dict(d), mi.load_file(path)
    assert len(s1.shapes()) == len(s2.shapes()) == 4
    assert np.allclose(np.array(s1.bbox().max), np.array(s2.bbox().max))
    assert np.allclose(np.array(s1.bbox().max), [5, 5, 3])
    # ... also when the included file's own directory has one: Mitsuba looks filenames
    # up in the main file's search path (it resolves them when it builds the plugins)
    (tmp_path / "sub" / "top.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert parse_file(path)["m"]["filename"] == str(tmp_path / "top.obj")
    assert np.allclose(np.array(mi.load_file(path).bbox().max), [5, 5, 3])
    # pbr's fallback where Mitsuba finds nothing: the directory of the file it is named in
    (tmp_path / "top.obj").unlink()
    assert parse_file(path)["m"]["filename"] == str(tmp_path / "sub" / "top.obj")


def test_search_path(tmp_path):
    """<path> and includes resolve like Mitsuba's file resolver (Mitsuba's test scenes
    use both: <path value="../../../common"/>, and an included file that includes
    "include/preamble.xml" relative to the main file's directory)."""
    tri = "v 0 0 0\nv {s} 0 0\nv 0 {s} 0\nf 1 2 3\n"
    (tmp_path / "common" / "meshes").mkdir(parents=True)
    (tmp_path / "common" / "meshes" / "m.obj").write_text(tri.format(s=2))
    (tmp_path / "scenes" / "inc").mkdir(parents=True)
    (tmp_path / "scenes" / "inc" / "pre.xml").write_text(
        scene_xml('<shape type="obj" id="pre"><string name="filename" value="meshes/m.obj"/></shape>'))
    (tmp_path / "scenes" / "inc" / "base.xml").write_text(scene_xml('<include filename="inc/pre.xml"/>'))
    # a <path> inside an included file only serves that file's own includes
    (tmp_path / "local").mkdir()
    (tmp_path / "local" / "meshes").mkdir()
    (tmp_path / "local" / "meshes" / "m.obj").write_text(tri.format(s=7))
    (tmp_path / "scenes" / "inc" / "local.xml").write_text(scene_xml('<path value="../../local"/>'))
    path = write(tmp_path / "scenes", "main.xml", scene_xml("""
    <path value="../common"/>
    <include filename="inc/base.xml"/>
    <include filename="inc/local.xml"/>
    <shape type="obj" id="main"><string name="filename" value="meshes/m.obj"/></shape>"""))
    d = parse_file(path)
    assert d["pre"]["filename"] == d["main"]["filename"] == str(tmp_path / "common" / "meshes" / "m.obj")
    ours, theirs = mi.load_dict(d), mi.load_file(path)
    assert len(ours.shapes()) == len(theirs.shapes()) == 2
    assert np.allclose(np.array(ours.bbox().max), np.array(theirs.bbox().max))
    assert np.allclose(np.array(ours.bbox().max), [2, 2, 0])
    with pytest.raises(XMLError, match=r'main.xml:2: <path>: folder "nowhere" not found'):
        parse_file(write(tmp_path, "main.xml", scene_xml('<path value="nowhere"/>')))
    with pytest.raises(XMLError, match=r"<path> is only allowed directly inside <scene>"):
        parse_file(write(tmp_path, "p.xml", scene_xml('<shape type="sphere"><path value="."/></shape>')))


# ---------------------------------------------------------------- transforms

def np_translate(v):
    m = np.eye(4)
    m[:3, 3] = v
    return m


def np_scale(v):
    return np.diag([*v, 1.0])


def np_rotate(axis, deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = np.radians(deg)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K
    return m


def np_lookat(origin, target, up):
    origin, target, up = (np.asarray(v, float) for v in (origin, target, up))
    z = (target - origin) / np.linalg.norm(target - origin)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    return m


def to_world(ops):
    d = parse_string(scene_xml(f'<shape type="sphere" id="s"><transform name="to_world">'
                               f'{ops}</transform></shape>'))
    t = d["s"]["to_world"]
    assert isinstance(t, mi.ScalarTransform4f)
    return mat(t)


@pytest.mark.parametrize("ops, expected", [
    ('<translate x="1" y="-2" z="3"/>', np_translate([1, -2, 3])),
    ('<translate value="1, -2, 3"/>', np_translate([1, -2, 3])),
    ('<translate y="5"/>', np_translate([0, 5, 0])),
    ('<scale value="2"/>', np_scale([2, 2, 2])),
    ('<scale value="2 3 4"/>', np_scale([2, 3, 4])),
    ('<scale y="3"/>', np_scale([1, 3, 1])),
    ('<rotate x="0.6" y="0.8" angle="30"/>', np_rotate([0.6, 0.8, 0], 30)),
    ('<rotate value="0, 0, 1" angle="-45"/>', np_rotate([0, 0, 1], -45)),
    ('<matrix value="1 2 3 4 5 6 7 8 9 10 11 12 0 0 0 1"/>',
     np.array([[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12], [0, 0, 0, 1]], float)),
    ('<matrix value="1 2 3 4 5 6 7 8 9"/>',
     np.array([[1, 2, 3, 0], [4, 5, 6, 0], [7, 8, 9, 0], [0, 0, 0, 1]], float)),
    ('<lookat origin="1, 2, 3" target="0, 0, 0" up="0, 1, 0"/>',
     np_lookat([1, 2, 3], [0, 0, 0], [0, 1, 0])),
    # composition: each operation is applied after (pre-multiplied onto) the previous
    ('<scale value="2"/><rotate z="1" angle="90"/><translate x="1"/>',
     np_translate([1, 0, 0]) @ np_rotate([0, 0, 1], 90) @ np_scale([2, 2, 2])),
    ('<lookat origin="0,0,5" target="0,0,0" up="0,1,0"/><translate value="1 2 3"/>',
     np_translate([1, 2, 3]) @ np_lookat([0, 0, 5], [0, 0, 0], [0, 1, 0])),
    ('', np.eye(4)),
])
def test_transform_ops(ops, expected):
    assert np.allclose(to_world(ops), expected, atol=1e-6)


@pytest.mark.parametrize("target", ["0,1,0", "0.3,-0.2,0.9", "-0.5,0.4,-0.7", "0,0,-1"])
def test_lookat_without_up_matches_mitsuba(target):
    ops = f'<lookat origin="0,0,0" target="{target}"/>'
    m = to_world(ops)
    d = np.array([float(v) for v in target.split(",")])
    assert np.allclose(m[:3, 2], d / np.linalg.norm(d), atol=1e-6)
    assert np.allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-6)
    xml = scene_xml(f'<sensor type="perspective"><transform name="to_world">{ops}'
                    '</transform></sensor>')
    ref = np.array(mi.load_string(xml).sensors()[0].world_transform().matrix).reshape(4, 4)
    assert np.allclose(m, ref, atol=1e-5)


def test_transforms_match_mitsuba(tmp_path):
    ops = ('<scale x="2" y="1" z="0.5"/><rotate value="1 1 1" angle="33"/>'
           '<matrix value="1 0 0 1  0 1 0 2  0 0 1 3  0 0 0 1"/>'
           '<lookat origin="1,1,1" target="0,0,2" up="0,0,1"/><translate x="-1"/>')
    path = write(tmp_path, "t.xml", scene_xml(
        f'<shape type="cube"><transform name="to_world">{ops}</transform></shape>'))
    b1 = mi.load_dict(parse_file(path)).bbox()
    b2 = mi.load_file(path).bbox()
    assert np.allclose(np.array(b1.min), np.array(b2.min), atol=1e-5)
    assert np.allclose(np.array(b1.max), np.array(b2.max), atol=1e-5)


# -------------------------------------------------------------------- errors

ERRORS = [
    # (body lines after the <scene> line, 1-based line of the culprit, message part)
    ('<shape type="sphere">\n<float name="radius" value="abc"/>\n</shape>', 3, "expected numbers"),
    ('<shape type="sphere">\n<integer name="n" value="1.5"/>\n</shape>', 3, "expected an integer"),
    ('<shape type="sphere">\n<boolean name="b" value="yes"/>\n</shape>', 3, '"true" or "false"'),
    ('\n\n<foo name="x"/>', 4, "unknown element"),
    ('<shape type="sphere">\n  <float value="1"/></shape>', 3, 'missing required attribute "name"'),
    ('<shape id="x"/>', 2, 'missing required attribute "type"'),
    ('<shape type="sphere" colour="red"/>', 2, 'unexpected attribute "colour"'),
    ('<shape type="sphere">\n\n<float name="radius" value="$nope"/></shape>', 4,
     "undefined parameter $nope"),
    ('<shape type="sphere" id="a"/>\n<bsdf type="diffuse" id="a"/>', 3, 'duplicate id "a"'),
    ('<shape type="sphere">\n<bsdf type="diffuse" id="a"/></shape>\n<shape type="sphere" id="a"/>',
     4, 'duplicate id "a"'),
    ('<shape type="sphere">\n<float name="r" value="1"/>\n<float name="r" value="2"/></shape>',
     4, 'duplicate name "r"'),
    ('<include filename="missing.xml"/>', 2, "cannot read included file"),
    ('<shape type="sphere">\n<ref id="nowhere"/></shape>', 3, 'unknown id "nowhere"'),
    ('<shape type="sphere"><transform name="to_world">\n<rotate x="1"/></transform></shape>',
     3, 'missing required attribute "angle"'),
    ('<shape type="sphere"><transform name="to_world">\n<matrix value="1 2 3"/>'
     '</transform></shape>', 3, "expected 9 or 16 numbers"),
    ('<shape type="sphere"><transform name="to_world">\n\n<shear value="1"/>'
     '</transform></shape>', 4, "unknown transform operation"),
    ('<shape type="sphere"><transform name="to_world">\n<lookat origin="0,0,0" '
     'target="0,0,0"/></transform></shape>', 3, "coincide"),
    ('<shape type="sphere">\n<point name="c" x="1" y="2"/></shape>', 3,
     'missing required attribute "z"'),
    ('<shape type="sphere">\n<spectrum name="s" value="400:1, 0.5"/></shape>', 3,
     "wavelength:value"),
    ('<shape type="sphere">\n<spectrum name="s" value="1" filename="a.spd"/></shape>', 3,
     "exactly one"),
    ('<shape type="sphere">\n<rgb name="c" value="1 2"/></shape>', 3, "expected 1 or 3 numbers"),
    ('<shape type="sphere">\n<default name="a" value="1"/></shape>', 3, "only allowed"),
    ('<shape type="sphere">\n<float name="r" value="1">\n<float name="q" value="2"/>'
     '</float></shape>', 3, "unexpected child <float>"),
    ('<shape type="sphere">\n<float name="r" value="1"></shape>', 3, "malformed XML"),
    ('<shape type="sphere"/>\n<translate x="1"/>', 3, "must be inside <transform>"),
]


@pytest.mark.parametrize("body, line, msg", ERRORS)
def test_errors_name_file_and_line(tmp_path, body, line, msg):
    path = write(tmp_path, "bad.xml", scene_xml(body))
    with pytest.raises(XMLError) as info:
        parse_file(path)
    text = str(info.value)
    assert text.startswith(f"{path}:{line}: "), text
    assert msg in text, text
    assert isinstance(info.value, ValueError)


def test_error_in_included_file_names_that_file(tmp_path):
    inc = write(tmp_path, "inc.xml", '<scene version="3.0.0">\n\n'
                '<shape type="sphere"><float name="radius" value="x"/></shape>\n</scene>')
    path = write(tmp_path, "main.xml", scene_xml('<include filename="inc.xml"/>'))
    with pytest.raises(XMLError, match=r"^" + re.escape(inc) + ":3: "):
        parse_file(path)


def test_root_and_parameter_errors(tmp_path):
    path = write(tmp_path, "a.xml", '<scene>\n</scene>')
    with pytest.raises(XMLError, match=r"a\.xml:1: .*version"):
        parse_file(path)
    path = write(tmp_path, "b.xml", '<scene version="0.6.0"/>')
    with pytest.raises(XMLError, match=r"b\.xml:1: .*not supported"):
        parse_file(path)
    path = write(tmp_path, "c.xml", scene_xml('<default name="a" value="1"/>'))
    with pytest.raises(XMLError, match=r"c\.xml:1: .*unused parameters: \$zzz=2"):
        parse_file(path, zzz=2)
    with pytest.raises(XMLError, match=r"^<string>:1: malformed XML"):
        parse_string("")
    with pytest.raises(XMLError, match=r"nothere\.xml:0: cannot read"):
        parse_file(tmp_path / "nothere.xml")
    write(tmp_path, "loop.xml", scene_xml('\n<include filename="loop.xml"/>'))
    with pytest.raises(XMLError, match=r"loop\.xml:3: .*recursive include"):
        parse_file(tmp_path / "loop.xml")


def test_to_xml_writes_volumes_as_volume_elements(tmp_path):
    """A gridvolume nested in a medium is a <volume> (it was written as a <shape>, which
    Mitsuba refuses: 'is of type "volume", which does not match the expected type "shape"')."""
    from pbr.media.grid import write_vol
    from pbr.scene.xml import to_xml
    vol = str(tmp_path / "g.vol")
    write_vol(vol, np.ones((2, 2, 2), np.float32))
    d = {"type": "scene",
         "cube": {"type": "cube", "bsdf": {"type": "null"},
                  "interior": {"type": "heterogeneous",
                               "sigma_t": {"type": "gridvolume", "filename": vol},
                               "albedo": {"type": "constvolume", "value": 0.5}}}}
    xml = to_xml(d)
    assert '<volume type="gridvolume" name="sigma_t">' in xml
    assert '<volume type="constvolume" name="albedo">' in xml
    from pbr import validate
    mi.set_variant(validate.mitsuba_variant())
    mi.load_string(xml)                  # Mitsuba reads it
    pbr.load_string(xml)                 # and so does pbr
