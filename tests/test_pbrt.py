"""pbrt-v4 scene files (pbr.scene.pbrt): directives, parameter types, errors with
file:line, pbrt-v4's defaults and units against independent values, and a converted
scene against Mitsuba 3."""
import gzip
import math
import os

import numpy as np
import pytest

import pbr
from pbr import validate
from pbr.scene.pbrt import convert, equal_area_to_latlong, to_dict
from pbr.scene.xml import XMLError


def write(tmp_path, text, name="scene.pbrt"):
    p = tmp_path / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return str(p)


HEAD = """
LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" 40
Film "rgb" "integer xresolution" 32 "integer yresolution" 24
Sampler "independent" "integer pixelsamples" 8
"""


def shapes(d):
    return {k: v for k, v in d.items() if k.startswith("shape_")}


# -- every directive and parameter type -------------------------------------------------------

def test_every_directive(tmp_path):
    write(tmp_path, 'Shape "sphere" "float radius" 0.25\n', "inc/included.pbrt")
    write(tmp_path, 'MakeNamedMaterial "imported" "string type" "diffuse" "rgb reflectance" [0.1 0.2 0.3]\n',
          "inc/imported.pbrt")
    path = write(tmp_path, HEAD.replace('Sampler "independent"', 'Option "bool wavefront" true\nColorSpace "srgb"\n'
                                        'PixelFilter "box"\nAccelerator "bvh"\nIntegrator "path" "integer maxdepth" 3\n'
                                        'Sampler "independent"') + """
TransformTimes 0 1
WorldBegin
Attribute "shape" "float radius" 0.5
AttributeBegin
  CoordSysTransform "camera"
  Translate 0 0 1
  Shape "sphere"
AttributeEnd
Identity
CoordinateSystem "origin"
Translate 5 0 0
CoordSysTransform "origin"
Transform [1 0 0 0  0 1 0 0  0 0 1 0  0 2 0 1]
ConcatTransform [1 0 0 0  0 1 0 0  0 0 1 0  1 0 0 1]
Rotate 90 0 0 1
Scale 2 2 2
Shape "sphere"
Identity
TransformBegin
  Translate 9 9 9
TransformEnd
Import "inc/imported.pbrt"
NamedMaterial "imported"
Include "inc/included.pbrt"
Texture "checks" "spectrum" "checkerboard" "float uscale" 4 "rgb tex1" [1 0 0] "rgb tex2" [0 0 1]
Texture "half" "float" "constant" "float value" 0.5
Material "coateddiffuse" "texture reflectance" "checks" "texture roughness" "half" "bool remaproughness" false
MakeNamedMedium "fog" "string type" "homogeneous" "rgb sigma_a" [0.1 0.1 0.1] "spectrum sigma_s" [400 0.5 700 0.5]
MediumInterface "fog" ""
ReverseOrientation
Shape "disk"
MediumInterface ""
ObjectBegin "pair"
  Shape "sphere" "float radius" 0.1
  Translate 1 0 0
  Shape "sphere" "float radius" 0.1
ObjectEnd
Translate 0 3 0
ObjectInstance "pair"
AttributeBegin
  AreaLightSource "diffuse" "blackbody L" 4000 "float scale" 2
  Shape "trianglemesh" "point3 P" [0 0 0 1 0 0 0 1 0] "normal N" [0 0 1 0 0 1 0 0 1] "point2 uv" [0 0 1 0 0 1]
AttributeEnd
LightSource "point" "rgb I" [1 2 3] "point3 from" [0 1 0]
""")
    d, notes, lines = convert(path)
    s = shapes(d)
    # Attribute "shape" radius, CoordSysTransform "camera": the camera sits at (0, 0, 5)
    # looking down -z, so camera-space z = 1 is world (0, 0, 4).
    first = s["shape_0001"]
    assert first["radius"] == 0.5
    np.testing.assert_allclose(first["center"], [0, 0, 4], atol=1e-6)
    # Transform then ConcatTransform, Rotate, Scale: translation (1, 2, 0) from the two
    # matrices, radius 0.5 scaled by 2.
    np.testing.assert_allclose(s["shape_0002"]["center"], [1, 2, 0], atol=1e-6)
    assert s["shape_0002"]["radius"] == pytest.approx(1.0)
    # Include and Import: the included sphere with the imported named material.
    assert s["shape_0003"]["radius"] == 0.25 and s["shape_0003"]["bsdf"]["id"] == "mat_imported"
    np.testing.assert_allclose(s["shape_0003"]["center"], [0, 0, 0], atol=1e-12)
    # The textured coated diffuse material; the disk inside the fog, ReverseOrientation.
    disk = s["shape_0004"]
    assert disk["type"] == "disk" and disk["flip_normals"] is True
    assert disk["interior"] == {"type": "ref", "id": "medium_fog"} and "exterior" not in disk
    mat = d[disk["bsdf"]["id"]]["bsdf"]
    assert mat["type"] == "coateddiffuse" and mat["reflectance"]["type"] == "checkerboard"
    assert mat["roughness"] == 0.5 and mat["remaproughness"] is False
    assert d["medium_fog"]["sigma_s"]["type"] == "spectrum"
    # The object and its instance.
    assert d["object_pair"]["type"] == "shapegroup" and len(d["object_pair"]) == 3
    inst = [v for k, v in d.items() if k.startswith("instance_")]
    assert len(inst) == 1 and np.allclose(np.array(inst[0]["to_world"].matrix)[:3, 3], [0, 3, 0])
    light = s["shape_0005"]
    assert light["type"] == "ply" and light["emitter"]["radiance"]["type"] == "scale"
    assert d["light_0001"]["intensity"] == {"type": "rgb", "value": [1.0, 2.0, 3.0]}
    assert d["integrator"] == {"type": "path", "max_depth": 4}
    assert d["sensor"]["film"]["rfilter"] == {"type": "box"}
    assert d["sensor"]["sampler"]["sample_count"] == 8
    assert any("Accelerator ignored" in n for n in notes) and any("wavefront" in n for n in notes)
    line = open(path).read().splitlines().index("  Shape \"sphere\"") + 1
    assert lines["scene.shape_0001"] == f"{path}:{line}"
    pbr.load_dict(d)


def test_active_transform_end_time_moves_shapes(tmp_path):
    """ActiveTransform EndTime around a Shape: the shape moves (pbr's to_world_end, built
    in object space; tests/test_motion_blur.py renders it); for Mitsuba 3 (mitsuba=True)
    refused, or the start transform under approximate."""
    path = write(tmp_path, HEAD + """WorldBegin
ActiveTransform EndTime
Translate 0 1 0
ActiveTransform All
Shape "sphere"
""")
    s = to_dict(path)["shape_0001"]
    np.testing.assert_allclose(s["center"], [0, 0, 0])
    np.testing.assert_allclose(np.array(s["to_world"].matrix), np.eye(4))
    np.testing.assert_allclose(np.array(s["to_world_end"].matrix)[:3, 3], [0, 1, 0])
    assert s["transform_times"] == [0.0, 1.0]
    with pytest.raises(XMLError, match=r"scene.pbrt:10: Shape: animated transforms .* Mitsuba 3"):
        to_dict(path, mitsuba=True)
    d, notes, _ = convert(path, approximate=True, mitsuba=True)
    assert any("animated transforms" in n for n in notes)
    np.testing.assert_allclose(d["shape_0001"]["center"], [0, 0, 0])
    assert "to_world_end" not in d["shape_0001"]


def test_parameter_types(tmp_path):
    (tmp_path / "refl.spd").write_text("# comment\n400 0.2\n700 0.8\n")
    path = write(tmp_path, HEAD + """WorldBegin
MakeNamedMaterial "a" "string type" "diffuse" "spectrum reflectance" "refl.spd"
MakeNamedMaterial "b" "string type" "diffuse" "spectrum reflectance" [400 0.1 700 0.9]
MakeNamedMaterial "c" "string type" "diffuse" "color reflectance" [0.1 0.2 0.3]
MakeNamedMaterial "d" "string type" "diffuse" "blackbody reflectance" 3000
MakeNamedMaterial "e" "string type" "dielectric" "spectrum eta" "glass-BK7"
MakeNamedMaterial "f" "string type" "conductor" "spectrum eta" "metal-Ag-eta" "spectrum k" "metal-Ag-k"
Shape "bilinearmesh" "point P" [0 0 0 1 0 0 0 1 0 1 1 0] "vector2 uv" [0 0 1 0 0 1 1 1]
Shape "cylinder" "float phimax" 180 "bool dummy" false
""")
    d, notes, _ = convert(path)
    assert d["mat_a"]["bsdf"]["reflectance"] == {"type": "spectrum", "value": [(400.0, 0.2), (700.0, 0.8)]}
    assert d["mat_b"]["bsdf"]["reflectance"]["value"] == [(400.0, 0.1), (700.0, 0.9)]
    assert d["mat_c"]["bsdf"]["reflectance"] == {"type": "rgb", "value": [0.1, 0.2, 0.3]}
    bb = d["mat_d"]["bsdf"]["reflectance"]
    # pbrt-v4's BlackbodySpectrum peaks at 1: Wien's peak of 3000 K is 965.9 nm.
    lam = 2.8977721e-3 / 3000 * 1e9
    planck = 2 * 6.62607004e-34 * 2.99792458e8 ** 2 / ((lam * 1e-9) ** 5 * (np.exp(
        6.62607004e-34 * 2.99792458e8 / (1.38064852e-23 * lam * 1e-9 * 3000)) - 1)) * 1e-9
    assert bb["type"] == "spectrum" and max(v for _, v in bb["value"]) <= 1.0
    at = dict(bb["value"])[830.0]
    lam2 = 830.0
    planck2 = 2 * 6.62607004e-34 * 2.99792458e8 ** 2 / ((lam2 * 1e-9) ** 5 * (np.exp(
        6.62607004e-34 * 2.99792458e8 / (1.38064852e-23 * lam2 * 1e-9 * 3000)) - 1)) * 1e-9
    assert at == pytest.approx(planck2 / planck, rel=1e-6)
    assert d["mat_e"] == {"type": "dielectric", "int_ior": "glass-BK7", "ext_ior": 1.0}
    assert d["mat_f"]["bsdf"] == {"type": "conductor", "material": "Ag"}
    assert any("'dummy'" in n and "not used" in n for n in notes)
    # The bilinear patch and the half cylinder became PLY meshes.
    assert [v["type"] for v in shapes(d).values()] == ["ply", "ply"]
    pbr.load_dict(d)


def test_gzip_ply_and_gz_scene(tmp_path):
    from pbr.scene.pbrt import write_ply
    ply = tmp_path / "tri.ply"
    write_ply(str(ply), np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]]), np.array([[0, 1, 2]]))
    with open(ply, "rb") as f, gzip.open(tmp_path / "tri.ply.gz", "wb") as g:
        g.write(f.read())
    text = HEAD + 'WorldBegin\nShape "plymesh" "string filename" "tri.ply.gz"\n'
    with gzip.open(tmp_path / "scene.pbrt.gz", "wt") as g:
        g.write(text)
    scene = pbr.load_file(str(tmp_path / "scene.pbrt.gz"))
    assert len(scene.shapes()) == 1


# -- errors name file:line and the directive ------------------------------------------------------

@pytest.mark.parametrize("body, pattern", [
    ('Shape "sphere" "float radius" [1 2]', r"scene.pbrt:7: Shape: parameter 'radius': expected one value"),
    ('Shape "sphere" "flaot radius" 1', r"scene.pbrt:7: Shape: unknown parameter type 'flaot'"),
    ('Shape "teapot"', r"scene.pbrt:7: Shape: unknown shape 'teapot'"),
    ('Material "plastic"', r"scene.pbrt:7: Material: unknown material 'plastic'"),
    ('NamedMaterial "nope"', r"scene.pbrt:7: NamedMaterial: unknown material 'nope'"),
    ('Translate 1 2', r"scene.pbrt:7: Translate: expected 3 numbers"),
    ('AttributeEnd', r"scene.pbrt:7: AttributeEnd: no matching AttributeBegin"),
    ('Frobnicate 1', r"scene.pbrt:7: unknown directive 'Frobnicate'"),
    ('Shape "sphere" "string radius" 1', r"scene.pbrt:7: Shape: parameter 'radius' \(string\) expects quoted"),
    ('Shape "trianglemesh" "point3 P" [0 0 0 1 0 0 0 1 0] "integer indices" [0 1 5]',
     r"scene.pbrt:7: Shape: parameter 'indices': vertex indices must be in \[0, 2\]"),
    ('Include "missing.pbrt"', r"scene.pbrt:7: Include: file not found: 'missing.pbrt'"),
    ('Camera "perspective"', r"scene.pbrt:7: Camera: must come before WorldBegin"),
    ('LightSource "point" "rgb I" [1 1]', r"scene.pbrt:7: LightSource: parameter 'I' \(rgb\) needs a multiple of 3"),
    ('Material "subsurface" "string name" "Skin9"',
     r"scene.pbrt:7: Material: parameter 'name': unknown measured medium 'Skin9' \(did you mean 'Skin[12]'"),
    ('Shape "sphere" "float radius" "one"', r"scene.pbrt:7: Shape: parameter 'radius' \(float\) expects numbers"),
])
def test_errors_name_file_line_and_directive(tmp_path, body, pattern):
    path = write(tmp_path, HEAD + "WorldBegin\n" + body + "\n")
    with pytest.raises(XMLError, match=pattern):
        to_dict(path)


def test_error_in_included_file_names_it(tmp_path):
    write(tmp_path, '\n\nShape "sphere" "float radius" [1 2]\n', "geo.pbrt")
    path = write(tmp_path, HEAD + 'WorldBegin\nInclude "geo.pbrt"\n')
    with pytest.raises(XMLError, match=r"geo.pbrt:3: Shape: parameter 'radius'"):
        to_dict(path)


def test_loader_errors_get_file_line(tmp_path):
    # A value pbr's loader rejects (a negative IOR) is located at the Material's line.
    path = write(tmp_path, HEAD + 'WorldBegin\nMaterial "dielectric" "float eta" -2\nShape "sphere"\n')
    with pytest.raises(ValueError, match=r"scene.pbrt:7: scene.material_0001"):
        pbr.load_file(path)


def test_approximate_notes_instead_of_errors(tmp_path):
    # Mitsuba 3 has no BSSRDF: for Mitsuba, pbrt-v4's subsurface becomes a coated diffuse
    # surface (pbr's own subsurface: tests/test_subsurface.py).
    path = write(tmp_path, HEAD + 'WorldBegin\nMaterial "subsurface" "rgb reflectance" [0.5 0.4 0.3]\nShape "sphere"\n')
    with pytest.raises(XMLError, match=r"scene.pbrt:7: Material: material 'subsurface' \(Mitsuba 3 has no BSSRDF\)"):
        convert(path, mitsuba=True)
    d, notes, _ = convert(path, approximate=True, mitsuba=True)
    assert d["material_0001"]["bsdf"]["type"] == "coateddiffuse"
    assert any("scene.pbrt:7" in n and "subsurface" in n for n in notes)


# -- conventions, defaults and units against independent values ------------------------------------


def flat_view(res: int, spp: int, look: str = "0 0 1  0 0 0  0 1 0", camera: str = "") -> str:
    """The head of the small orthographic test scenes, up to WorldBegin: a res x res image,
    spp samples, box filter, direct light only. pbrt's LookAt from +z shows world +x on the
    image's left (its camera space is left-handed); "Scale -1 1 1" first, as exported
    scenes do, puts it on the right."""
    return f"""
Scale -1 1 1
LookAt {look}
Camera "orthographic"{camera}
Film "rgb" "integer xresolution" {res} "integer yresolution" {res}
Sampler "independent" "integer pixelsamples" {spp}
Integrator "path" "integer maxdepth" 1
PixelFilter "box"
WorldBegin
"""

def render_mean(path, **kw):
    scene = pbr.load_file(path, **kw)
    return np.asarray(pbr.render(scene, seed=3), dtype=np.float64)


def luminance(img):
    return img[..., 0] * 0.2126 + img[..., 1] * 0.7152 + img[..., 2] * 0.0722


def test_camera_handedness_and_fov(tmp_path):
    """pbrt's camera space has x to the right of the image: an emitter at camera-space
    x > 0 shows in the right half. fov is the shorter axis's: for a 2:1 film with fov 90,
    Mitsuba's x_fov is 2 atan(2) (computed by Mitsuba from the converted dict)."""
    import mitsuba as mi
    path = write(tmp_path, """
LookAt 0 0 0  0 0 1  0 1 0
Camera "perspective" "float fov" 90
Film "rgb" "integer xresolution" 32 "integer yresolution" 16
Sampler "independent" "integer pixelsamples" 4
Integrator "path" "integer maxdepth" 1
WorldBegin
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Translate 1.2 0.5 3
  Shape "sphere" "float radius" 0.3
AttributeEnd
""")
    img = luminance(render_mean(path))
    h, w = img.shape
    assert img[:, w // 2:].sum() > 50 * img[:, :w // 2].sum()       # right half
    assert img[:h // 2].sum() > 50 * img[h // 2:].sum()             # top half (+y is up)
    d = to_dict(path, mitsuba=True)
    sensor = mi.load_dict(d["sensor"])
    assert mi.traverse(sensor)["x_fov"][0] == pytest.approx(math.degrees(2 * math.atan(2.0)), rel=1e-5)


def test_point_light_power(tmp_path):
    """A point light of power P 1 unit above a diffuse plane (albedo 0.5): the radiance
    under it is 0.5 / pi * I / d^2, with pbrt-v4's photometric I = P / 4 pi for the
    illuminant alone: the RGB multiplier's luminance multiplies it."""
    path = write(tmp_path, """
LookAt 0 0 3  0 0 0  0 1 0
Camera "perspective" "float fov" 2
Film "rgb" "integer xresolution" 4 "integer yresolution" 4
Sampler "independent" "integer pixelsamples" 16
Integrator "path" "integer maxdepth" 1
WorldBegin
LightSource "point" "rgb I" [0.3 0.6 0.9] "float power" 100 "point3 from" [0 0 1]
Material "diffuse" "rgb reflectance" [0.5 0.5 0.5]
Shape "trianglemesh" "point3 P" [-10 -10 0 10 -10 0 10 10 0 -10 10 0] "integer indices" [0 1 2 0 2 3]
""")
    y = luminance(render_mean(path)).mean()
    lum_rgb = 0.2126 * 0.3 + 0.7152 * 0.6 + 0.0722 * 0.9
    assert y == pytest.approx(0.5 / math.pi * 100 / (4 * math.pi) * lum_rgb, rel=0.02)
    # Without 'power', 'scale' multiplies the RGB illuminant (luminance of rgb (1, 1, 1) is 1).
    path2 = path.replace("scene.pbrt", "scene2.pbrt")
    open(path2, "w").write(open(path).read().replace('"rgb I" [0.3 0.6 0.9] "float power" 100',
                                                     '"rgb I" [1 1 1] "float scale" 7'))
    assert luminance(render_mean(path2)).mean() == pytest.approx(0.5 / math.pi * 7, rel=0.02)


def test_area_light_power_and_blackbody(tmp_path):
    """A disk light of power P seen head-on has radiance P / (pi A); a blackbody L is
    normalised to luminance 1 (pbrt-v4's SpectrumToPhotometric), so with 'scale' s the
    pixels' luminance is s."""
    tmpl = """
LookAt 0 0 3  0 0 0  0 1 0
Camera "perspective" "float fov" 3
Film "rgb" "integer xresolution" 4 "integer yresolution" 4
Sampler "independent" "integer pixelsamples" 4
Integrator "path" "integer maxdepth" 1
WorldBegin
AreaLightSource "diffuse" {L}
Shape "disk" "float radius" 2
"""
    p1 = write(tmp_path, tmpl.format(L='"rgb L" [1 1 1] "float power" 50'), "a.pbrt")
    assert luminance(render_mean(p1)).mean() == pytest.approx(50 / (math.pi * math.pi * 4), rel=0.01)
    # A mesh: pbrt-v4 gives every triangle the whole power (one light per triangle), so a
    # square of two triangles of area A/2 each has radiance P / (pi A / 2).
    p4 = write(tmp_path, tmpl.format(L='"rgb L" [1 1 1] "float power" 50').replace(
        'Shape "disk" "float radius" 2', 'Shape "trianglemesh" "point3 P" [-2 -2 0 2 -2 0 2 2 0 -2 2 0] '
                                         '"integer indices" [0 1 2 0 2 3]'), "d.pbrt")
    assert luminance(render_mean(p4)).mean() == pytest.approx(50 / (math.pi * 8), rel=0.01)
    # A scaled sphere: pbrt-v4 divides by its object-space area (4 pi r^2, the scale ignored).
    p5 = write(tmp_path, tmpl.format(L='"rgb L" [1 1 1] "float power" 50').replace(
        'Shape "disk" "float radius" 2', 'Scale 2 2 2\nShape "sphere" "float radius" 1'), "e.pbrt")
    assert luminance(render_mean(p5)).mean() == pytest.approx(50 / (math.pi * 4 * math.pi), rel=0.01)
    p2 = write(tmp_path, tmpl.format(L='"blackbody L" 3500 "float scale" 3'), "b.pbrt")
    img = render_mean(p2)
    assert luminance(img).mean() == pytest.approx(3.0, rel=0.02)
    assert img[..., 0].mean() > img[..., 2].mean() * 1.5           # 3500 K is reddish
    # ReverseOrientation turns the disk's emitting side away from the camera.
    p3 = write(tmp_path, tmpl.format(L='"rgb L" [1 1 1]').replace("Shape", "ReverseOrientation\nShape"), "c.pbrt")
    assert luminance(render_mean(p3)).max() < 1e-6


@pytest.mark.parametrize("prefix, N, lit", [
    ("", "", True),
    ("ReverseOrientation", "", False),
    ("Scale -1 1 1", "", True),                      # a handedness swap keeps pbrt's normal
    ("Scale -1 1 1\nReverseOrientation", "", False),
    ("", '"normal N" [0 0 -1 0 0 -1 0 0 -1]', False),   # the normal follows N, not the winding
    ("ReverseOrientation", '"normal N" [0 0 1 0 0 1 0 0 1]', True),
])
def test_triangle_orientation(tmp_path, prefix, N, lit):
    """pbrt-v4's triangle normal: cross(p1 - p0, p2 - p0), flipped by ReverseOrientation
    and by transforms that swap handedness, or the side of the vertex normals if given.
    An area light emits on its normal's side only; the camera looks down -z at it."""
    path = write(tmp_path, f"""
LookAt 0 0 3  0 0 0  0 1 0
Camera "perspective" "float fov" 3
Film "rgb" "integer xresolution" 4 "integer yresolution" 4
Sampler "independent" "integer pixelsamples" 4
Integrator "path" "integer maxdepth" 1
WorldBegin
AreaLightSource "diffuse" "rgb L" [1 1 1]
{prefix}
Shape "trianglemesh" "point3 P" [-1 -1 0 1 -1 0 0 1 0] "integer indices" [0 1 2] {N}
""")
    y = luminance(render_mean(path)).mean()
    assert (y == pytest.approx(1.0, rel=0.01)) if lit else (y < 1e-6)


def test_default_material_and_maxdepth(tmp_path):
    """pbrt-v4's default material is diffuse 0.5 (two-sided) and maxdepth 5; a plane lit
    by a distant light of L = 1 straight on reflects 0.5 / pi."""
    path = write(tmp_path, """
LookAt 0 0 3  0 0 0  0 1 0
Camera "perspective" "float fov" 5
Film "rgb" "integer xresolution" 4 "integer yresolution" 4
Sampler "independent" "integer pixelsamples" 4
WorldBegin
LightSource "distant" "point3 from" [0 0 1] "point3 to" [0 0 0]
Shape "trianglemesh" "point3 P" [-10 -10 0 10 -10 0 10 10 0 -10 10 0] "integer indices" [0 2 1 0 3 2]
""")
    d = to_dict(path)
    assert d["integrator"] == {"type": "volpath", "max_depth": 6}
    assert luminance(render_mean(path)).mean() == pytest.approx(0.5 / math.pi, rel=0.02)


def test_equal_area_mapping_round_trip():
    """The equal-area -> lat-long resampling puts pbrt's +z (light space) at the top row,
    which the converter rotates onto Mitsuba's +y."""
    n = 64
    img = np.zeros((n, n, 3), dtype=np.float32)
    img[n // 2 - 2:n // 2 + 2, n // 2 - 2:n // 2 + 2] = 1.0   # the square's centre is +z
    env = equal_area_to_latlong(img, height=32)
    assert env[0].mean() > 0.9 and env[-1].mean() == 0.0


# -- a converted scene matches Mitsuba 3 -------------------------------------------------------------

SCENE = """
Scale -1 1 1
LookAt 0 1.5 6  0 0.5 0  0 1 0
Camera "perspective" "float fov" 35
Film "rgb" "integer xresolution" {res} "integer yresolution" {res2}
Sampler "independent" "integer pixelsamples" 16
Integrator "volpath" "integer maxdepth" 4
PixelFilter "box"
WorldBegin
LightSource "point" "rgb I" [4 4 4] "point3 from" [2 4 3]
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [6 5 4]
  Translate 0 3 0
  Rotate 90 1 0 0
  Shape "disk" "float radius" 0.6
AttributeEnd
Texture "checks" "spectrum" "checkerboard" "float uscale" 8 "float vscale" 8 "rgb tex1" [0.8 0.8 0.8] "rgb tex2" [0.2 0.3 0.6]
Material "diffuse" "texture reflectance" "checks"
Shape "trianglemesh" "point3 P" [-4 0 -4 4 0 -4 4 0 4 -4 0 4] "integer indices" [0 1 2 0 2 3] "point2 uv" [0 0 1 0 1 1 0 1]
AttributeBegin
  Translate -1 0.6 0
  Material "conductor" "spectrum eta" "metal-Au-eta" "spectrum k" "metal-Au-k" "float roughness" 0.1
  Shape "sphere" "float radius" 0.6
AttributeEnd
AttributeBegin
  Translate 1 0.6 0
  Material "dielectric" "float eta" 1.5
  Shape "sphere" "float radius" 0.6
AttributeEnd
AttributeBegin
  Translate 0 0.4 1.5
  Material "diffuse" "rgb reflectance" [0.7 0.2 0.2]
  Shape "sphere" "float radius" 0.4 "float zmax" 0.2 "float phimax" 270
AttributeEnd
"""


@pytest.mark.parametrize("camera", ["", '"float lensradius" 0.15 "float focaldistance" 5',
                                    '"float screenwindow" [-0.5 1.5 -1 0.5]'])
def test_converted_scene_matches_mitsuba(tmp_path, scale, camera):
    """The dict of a pbrt-v4 scene (textured diffuse floor, gold and glass spheres, a
    partial sphere, point and area lights; a pinhole, a thin lens, an off-centre screen
    window: Mitsuba's fov and principal point) renders the same in pbr and in Mitsuba 3
    (``mitsuba=True``). The box filter: with a Gaussian the per-pixel test cannot pass
    near edges although the means agree (pbr importance-samples the filter, Mitsuba
    splats; docs/integrators.md), measured here: 1273/1296 pixel-channels with pbrt-v4's
    default Gaussian."""
    res = 24 * scale
    path = write(tmp_path, SCENE.format(res=res, res2=res * 3 // 4).replace(
        'Camera "perspective" "float fov" 35', 'Camera "perspective" "float fov" 35 ' + camera))
    d = to_dict(path, mitsuba=True)
    assert d["sensor"]["type"] == ("thinlens" if "lens" in camera else "perspective")
    s = pbr.load_dict(d)
    r = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(s, seed=seed, spp=spp)),
                                 validate.mitsuba_render_fn(d), spp=256 * scale, batches=16, seed_a=5, seed_b=6)
    print(r.summary())
    assert r


def test_to_xml_round_trip(tmp_path):
    """A converted scene saves as Mitsuba XML and loads again to the same image."""
    from pbr.scene.xml import to_xml
    path = write(tmp_path, SCENE.format(res=16, res2=12))
    d = to_dict(path)
    xml = tmp_path / "scene.xml"
    xml.write_text(to_xml(d, str(tmp_path)))
    a = np.asarray(pbr.render(pbr.load_dict(d), seed=1, spp=4))
    b = np.asarray(pbr.render(pbr.load_file(str(xml)), seed=1, spp=4))
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_cli_renders_pbrt(tmp_path):
    from pbr.cli import main
    path = write(tmp_path, HEAD + 'WorldBegin\nLightSource "point" "point3 from" [0 0 3]\nShape "sphere"\n')
    out = tmp_path / "out.exr"
    assert main(["render", path, "-o", str(out), "--res", "16", "--backend", pbr.get_backend()]) == 0
    assert out.exists()


def test_curves_subdivision_instances_media_render(tmp_path):
    """Curves (Bezier -> Mitsuba's B-spline: the curve still starts at P0), Loop
    subdivision, object instances and a medium behind an interface load and render."""
    path = write(tmp_path, HEAD + """WorldBegin
LightSource "infinite" "rgb L" [0.5 0.5 0.5]
Material "hair"
Shape "curve" "point3 P" [0 0 0  0.3 0.3 0  0.6 -0.3 0  1 0 0] "float width0" 0.1 "float width1" 0.05 "string type" "cylinder"
Material "diffuse"
Shape "loopsubdiv" "integer levels" 2 "point3 P" [0 0 1  1 0 -1  -1 0 -1  0 1 0] "integer indices" [0 1 2  0 3 1  1 3 2  2 3 0]
ObjectBegin "ball"
  Shape "sphere" "float radius" 0.2
ObjectEnd
Translate -1 -1 0
ObjectInstance "ball"
Translate 2 0 0
ObjectInstance "ball"
MakeNamedMedium "smoke" "string type" "homogeneous" "rgb sigma_a" [0.5 0.5 0.5] "rgb sigma_s" [1 1 1] "float g" 0.3
MediumInterface "smoke" ""
Material "interface"
Shape "sphere" "float radius" 0.5
""")
    d, notes, _ = convert(path)
    curve = next(v for v in d.values() if isinstance(v, dict) and v.get("type") == "bsplinecurve")
    first = [float(x) for x in open(curve["filename"]).read().splitlines()[:4][0].split()]
    q = np.array([[float(x) for x in line.split()] for line in open(curve["filename"]).read().splitlines()[:4]])
    start = (q[0, :3] + 4 * q[1, :3] + q[2, :3]) / 6           # a uniform cubic B-spline at t = 0
    np.testing.assert_allclose(start, [0, 0, 0], atol=1e-6)
    assert first[3] == pytest.approx(0.05)                       # radius = width0 / 2
    assert any("loopsubdiv" in n for n in notes)
    assert sum(1 for k in d if k.startswith("instance_")) == 2
    img = np.asarray(pbr.render(pbr.load_dict(d), spp=4))
    assert np.isfinite(img).all() and img.mean() > 0


@pytest.mark.parametrize("region, normal", [
    ("diamond", (0, 0, 1)),      # the octahedral map's inner diamond is the upper hemisphere (+z)
    ("right", (1, 0, 0)),        # u > 0: x > 0
    ("bottom", (0, 1, 0)),       # image rows below the middle: v > 0, y > 0
])
def test_infinite_light_equal_area_image(tmp_path, region, normal):
    """pbrt-v4's image infinite light: an equal-area square image in light space. An image
    that is 1 over one hemisphere and 0 elsewhere gives a diffuse plane (albedo 0.5) facing
    that hemisphere's pole the radiance 0.5 (irradiance pi), and the opposite plane 0."""
    import mitsuba as mi
    n = 64
    c = (np.arange(n) + 0.5) / n * 2 - 1
    u, v = np.meshgrid(c, c)          # u along columns, v along rows
    mask = {"diamond": np.abs(u) + np.abs(v) < 1, "right": u > 0, "bottom": v > 0}[region]
    img = np.repeat(mask[..., None].astype(np.float32), 3, axis=2)
    mi.Bitmap(img).write(str(tmp_path / "env.exr"))
    results = []
    for sign in (1, -1):
        nx, ny, nz = (sign * x for x in normal)
        up = "0 1 0" if ny == 0 else "1 0 0"
        path = write(tmp_path, f"""
LookAt {3 * nx} {3 * ny} {3 * nz}  0 0 0  {up}
Camera "perspective" "float fov" 5
Film "rgb" "integer xresolution" 4 "integer yresolution" 4
Sampler "independent" "integer pixelsamples" 64
Integrator "path" "integer maxdepth" 1
WorldBegin
LightSource "infinite" "string filename" "env.exr"
Material "diffuse" "rgb reflectance" [0.5 0.5 0.5]
Shape "disk" "float radius" 10
""".replace('Shape "disk"', _orient(nx, ny, nz) + '\nShape "disk"'), f"s{sign}.pbrt")
        results.append(luminance(render_mean(path)).mean())
    assert results[0] == pytest.approx(0.5, rel=0.05)
    assert results[1] < 0.01


def _orient(nx, ny, nz):
    """pbrt directives turning the disk's +z normal to (nx, ny, nz)."""
    if nz:
        return "" if nz > 0 else "Rotate 180 1 0 0"
    if nx:
        return f"Rotate {90 * nx} 0 1 0"
    return f"Rotate {-90 * ny} 1 0 0"


def test_imagemap_conventions(tmp_path):
    """pbrt-v4 looks image maps up at (s, 1 - t) with s = uscale u + udelta: a 2x2 image
    whose bottom-left texel is white, on a quad with uv (0, 0) at its lower left, shows
    white in the lower left; 'invert' gives 1 - value."""
    import mitsuba as mi
    img = np.zeros((2, 2, 3), dtype=np.float32)
    img[1, 0] = 1.0                   # row 1 is the bottom row of the image
    mi.Bitmap(img).write(str(tmp_path / "tex.exr"))
    # The texture is read through a quad lit by a distant light (radiance = albedo).
    scene = flat_view(8, 4) + """LightSource "distant" "point3 from" [0 0 1] "point3 to" [0 0 0] "rgb L" [3.14159265 3.14159265 3.14159265]
Texture "t" "spectrum" "imagemap" "string filename" "tex.exr" "string filter" "point" {extra}
Material "diffuse" "texture reflectance" "t"
Shape "trianglemesh" "point3 P" [-1 -1 0 1 -1 0 1 1 0 -1 1 0] "integer indices" [0 1 2 0 2 3] "point2 uv" [0 0 1 0 1 1 0 1]
"""
    out = []
    for extra in ("", '"bool invert" true'):
        path = write(tmp_path, scene.format(extra=extra), f"img{len(out)}.pbrt")
        out.append(luminance(render_mean(path)))
        # pbr's imagemap (pbrt-v4's MIP map and filters); Mitsuba's bitmap for Mitsuba.
        assert to_dict(path)["material_0001"]["bsdf"]["reflectance"]["type"] == "imagemap"
        if not extra:
            assert to_dict(path, mitsuba=True)["material_0001"]["bsdf"]["reflectance"]["type"] == "bitmap"
    a, b = out
    # Orthographic view of [-1, 1]^2: the lower-left quarter (image rows 4..7, columns 0..3).
    assert a[4:, :4].mean() == pytest.approx(1.0, rel=0.02) and a[:4].max() < 1e-3 and a[4:, 4:].max() < 1e-3
    assert b[4:, :4].max() < 1e-3 and b[:4, 4:].mean() == pytest.approx(1.0, rel=0.02)


def test_checkerboard_conventions(tmp_path):
    """pbrt-v4's 2D checkerboard: tex1 where floor(s) + floor(t) is even, squares of size
    1 in (s, t) = (uscale u, vscale v): with scale 2 on a quad with uv (0, 0) at its lower
    left, tex1 fills the lower-left and upper-right quarters. pbr's checkerboard (pbrt-v4's)
    is box-filtered over the pixel footprint: pixels next to a square's edge are blurred,
    so the quarters' inner pixels are compared; with mitsuba=True (Mitsuba's unfiltered
    checkerboard, to_uv scaled by 1/2) the whole quarters."""
    text = flat_view(8, 4) + """LightSource "distant" "point3 from" [0 0 1] "point3 to" [0 0 0] "rgb L" [3.14159265 3.14159265 3.14159265]
Texture "c" "spectrum" "checkerboard" "float uscale" 2 "float vscale" 2 "rgb tex1" [1 1 1] "rgb tex2" [0.2 0.2 0.2]
Material "diffuse" "texture reflectance" "c"
Shape "trianglemesh" "point3 P" [-1 -1 0 1 -1 0 1 1 0 -1 1 0] "integer indices" [0 1 2 0 2 3] "point2 uv" [0 0 1 0 1 1 0 1]
"""
    path = write(tmp_path, text.replace('"integer xresolution" 8 "integer yresolution" 8',
                                        '"integer xresolution" 16 "integer yresolution" 16'))
    y = luminance(render_mean(path))
    q = [y[10:14, 2:6].mean(), y[2:6, 10:14].mean(), y[2:6, 2:6].mean(), y[10:14, 10:14].mean()]
    np.testing.assert_allclose(q, [1.0, 1.0, 0.2, 0.2], rtol=0.03)
    path = write(tmp_path, text, "mi.pbrt")
    s = pbr.load_dict(to_dict(path, mitsuba=True))
    y = luminance(np.asarray(pbr.render(s, seed=3), dtype=np.float64))
    q = [y[4:, :4].mean(), y[:4, 4:].mean(), y[:4, :4].mean(), y[4:, 4:].mean()]
    np.testing.assert_allclose(q, [1.0, 1.0, 0.2, 0.2], rtol=0.03)


def test_spot_light_axis_and_intensity(tmp_path):
    """A spot light from (0, 0, 2) to the origin: on its axis the intensity is I scale
    (RGB of unit luminance), so the diffuse plane (albedo 0.5) at distance 2 shows
    0.5 / pi * I / 4; outside the cone (a point 2 units aside: 45 degrees) it is dark."""
    path = write(tmp_path, flat_view(9, 16, look="0 0 6  0 0 0  0 1 0") + """LightSource "spot" "rgb I" [1 1 1] "float scale" 8 "point3 from" [0 0 2] "point3 to" [0 0 0] "float coneangle" 20
Material "diffuse" "rgb reflectance" [0.5 0.5 0.5]
Shape "trianglemesh" "point3 P" [-10 -10 0 10 -10 0 10 10 0 -10 10 0] "integer indices" [0 1 2 0 2 3]
""")
    y = luminance(render_mean(path))
    # The centre pixel spans 2/9 units: cos^3 falloff across it is < 1%.
    assert y[4, 4] == pytest.approx(0.5 / math.pi * 8 / 4, rel=0.02)
    assert y[0, 0] == 0.0 and y[4, 0] == 0.0


# -- pbrt-v4's cameras, films, filters and textures: pbr's plugins of pbrt-v4's names ------------------

def test_filters_map_to_pbrt_plugins(tmp_path):
    """Each PixelFilter gets pbrt-v4's parameters and defaults (the Gaussian's radius 1.5,
    not Mitsuba's 4 sigma); the loaded filters have those radii. mitsuba=True gives
    Mitsuba's filters."""
    want = {"": {"type": "gaussian", "xradius": 1.5, "yradius": 1.5, "sigma": 0.5},
            'PixelFilter "gaussian" "float sigma" 0.3': {"type": "gaussian", "xradius": 1.5, "yradius": 1.5,
                                                         "sigma": 0.3},
            'PixelFilter "mitchell" "float xradius" 1.5': {"type": "mitchell", "xradius": 1.5, "yradius": 2.0,
                                                           "B": 1 / 3, "C": 1 / 3},
            'PixelFilter "sinc" "float tau" 2': {"type": "sinc", "xradius": 4.0, "yradius": 4.0, "tau": 2.0},
            'PixelFilter "triangle"': {"type": "triangle", "xradius": 2.0, "yradius": 2.0},
            'PixelFilter "box" "float xradius" 1': {"type": "box", "xradius": 1.0, "yradius": 0.5},
            'PixelFilter "box"': {"type": "box"}}
    for i, (line, f) in enumerate(want.items()):
        path = write(tmp_path, HEAD + line + '\nWorldBegin\nShape "sphere"\n', f"f{i}.pbrt")
        d = to_dict(path)
        assert d["sensor"]["film"]["rfilter"] == pytest.approx(f) if f["type"] != "box" or len(f) == 1 else True
        assert d["sensor"]["film"]["rfilter"] == f
        rf = pbr.load_dict(d).sensors[0].film.rfilter
        assert rf.radius == pytest.approx(f.get("xradius", 0.5))
    path = write(tmp_path, HEAD + 'WorldBegin\nShape "sphere"\n', "m.pbrt")
    assert to_dict(path, mitsuba=True)["sensor"]["film"]["rfilter"] == {"type": "gaussian", "stddev": 0.5}


def test_film_sensor_iso_and_white_balance(tmp_path):
    """pbrt-v4's imaging ratio (shutterclose - shutteropen) x iso / 100 scales the image:
    iso 400 with a 0.5 s shutter gives 2x the plain film's image (pbr's rgb film; the
    plain one is Mitsuba's hdrfilm); a named camera sensor is passed to pbr's rgb film;
    the CLI's --res sets the rgb film's size."""
    body = 'WorldBegin\nLightSource "point" "point3 from" [0 0 3] "rgb I" [5 5 5]\nShape "sphere"\n'
    plain = write(tmp_path, HEAD + body, "a.pbrt")
    iso = write(tmp_path, HEAD.replace('Film "rgb"', 'Film "rgb" "float iso" 400').replace(
        '"float fov" 40', '"float fov" 40 "float shutteropen" 0.25 "float shutterclose" 0.75') + body, "b.pbrt")
    da, db = to_dict(plain), to_dict(iso)
    assert da["sensor"]["film"]["type"] == "hdrfilm"
    assert db["sensor"]["film"]["type"] == "rgb" and db["sensor"]["film"]["iso"] == 400.0
    assert (db["sensor"]["shutter_open"], db["sensor"]["shutter_close"]) == (0.25, 0.75)
    a, b = render_mean(plain), render_mean(iso)
    assert a.mean() > 0.01
    np.testing.assert_allclose(b, 2.0 * a, rtol=1e-4, atol=1e-6)
    named = write(tmp_path, HEAD.replace('Film "rgb"', 'Film "rgb" "string sensor" "canon_eos_100d"') + body, "c.pbrt")
    d = to_dict(named)      # pbrt-v4's camera sensors: pbr's rgb film (tests/test_pbrt_gaps.py)
    assert d["sensor"]["film"]["sensor"] == "canon_eos_100d" and "whitebalance" not in d["sensor"]["film"]
    pbr.load_dict(d)
    from pbr.cli import main
    out = tmp_path / "out.exr"
    assert main(["render", iso, "-o", str(out), "--res", "16", "--backend", pbr.get_backend()]) == 0
    import mitsuba as mi
    assert np.asarray(mi.Bitmap(str(out))).shape[:2] == (12, 16)


def test_camera_motion_blur(tmp_path):
    """ActiveTransform EndTime on the camera's transform: to_world_end and
    transform_times; the camera turns during the shutter, so a small light is smeared
    across the image (rows of light wider than the static image's)."""
    text = """
LookAt 0 0 0  0 0 1  0 1 0
{motion}
Camera "perspective" "float fov" 30
Film "rgb" "integer xresolution" 32 "integer yresolution" 8
Sampler "independent" "integer pixelsamples" 64
Integrator "path" "integer maxdepth" 1
PixelFilter "box"
WorldBegin
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Translate 0 0 5
  Shape "sphere" "float radius" 0.1
AttributeEnd
"""
    still = write(tmp_path, text.format(motion=""), "still.pbrt")
    moving = write(tmp_path, text.format(motion="TransformTimes 0 1\nActiveTransform EndTime\nRotate 8 0 1 0\n"
                                                "ActiveTransform All"), "moving.pbrt")
    d = to_dict(moving)
    assert d["sensor"]["transform_times"] == [0.0, 1.0] and "to_world_end" in d["sensor"]
    lit = [int((luminance(render_mean(p)).max(axis=0) > 1e-3).sum()) for p in (still, moving)]
    assert lit[0] <= 3 and lit[1] >= 8, lit
    with pytest.raises(XMLError, match="moving camera"):
        to_dict(moving, mitsuba=True)


@pytest.mark.parametrize("camera", ["perspective", "orthographic"])
def test_screen_window(tmp_path, camera):
    """pbrt-v4's screenwindow picks a part of the screen: a light at screen (0.5, 0.5)
    (fov 90 perspective: direction (0.5, 0.5, 1); orthographic: camera-space x, y =
    0.5) shows at the image's centre with the window [0, 1] x [0, 1], in the upper right
    quarter without it."""
    pos = "2.5 2.5 5" if camera == "perspective" else "0.5 0.5 5"
    text = f"""
LookAt 0 0 0  0 0 1  0 1 0
Camera "{camera}" "float fov" 90 {{window}}
Film "rgb" "integer xresolution" 16 "integer yresolution" 16
Sampler "independent" "integer pixelsamples" 16
Integrator "path" "integer maxdepth" 1
PixelFilter "box"
WorldBegin
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Translate {pos}
  Shape "sphere" "float radius" 0.05
AttributeEnd
"""
    if camera == "orthographic":
        text = text.replace('"float fov" 90 ', "")
    peaks = []
    for i, window in enumerate(("", '"float screenwindow" [0 1 0 1]')):
        img = luminance(render_mean(write(tmp_path, text.format(window=window), f"w{i}.pbrt")))
        peaks.append(np.unravel_index(np.argmax(img), img.shape))
    # pbrt's camera x points right (LookAt from the origin down +z, its image is mirrored
    # by the left-handed camera space): (0.5, 0.5) is the upper right quarter's centre.
    assert peaks[0] in [(r, c) for r in (3, 4) for c in (11, 12)], peaks
    assert peaks[1] in [(r, c) for r in (7, 8) for c in (7, 8)], peaks


@pytest.mark.parametrize("kind", ['"integer dimension" 3',
                                  '"string mapping" "planar" "vector3 v1" [1 0 0] "vector3 v2" [0 1 0]'])
def test_texture_space_and_3d_checkerboard(tmp_path, kind):
    """3D textures and non-UV mappings take to_world = the CTM at the Texture directive:
    a 3D checkerboard, or a 2D one over a planar mapping (s = x, t = y in texture
    space), translated by one unit swaps its colours at a point."""
    text = flat_view(4, 256, look="0.5 0.5 5  0.5 0.5 0  0 1 0", camera=' "float screenwindow" [-0.4 0.4 -0.4 0.4]') + """LightSource "distant" "point3 from" [0 0 1] "point3 to" [0 0 0] "rgb L" [3.14159265 3.14159265 3.14159265]
AttributeBegin
{xf}
Texture "c" "spectrum" "checkerboard" {kind} "rgb tex1" [1 1 1] "rgb tex2" [0.2 0.2 0.2]
AttributeEnd
Material "diffuse" "texture reflectance" "c"
Shape "trianglemesh" "point3 P" [0 0 0.5 1 0 0.5 1 1 0.5 0 1 0.5] "integer indices" [0 1 2 0 2 3]
"""
    vals = []
    for i, xf in enumerate(("", "Translate 1 0 0")):
        path = write(tmp_path, text.format(xf=xf, kind=kind), f"t{i}.pbrt")
        d = to_dict(path)
        assert d["material_0001"]["bsdf"]["reflectance"]["type"] == "checkerboard"
        assert ("to_world" in d["material_0001"]["bsdf"]["reflectance"]) == bool(xf)
        vals.append(luminance(render_mean(path)).mean())
    # The visible [0.1, 0.9]^2 x {0.5} lies in cell (0, 0, 0): tex1; moved by one cell: tex2.
    np.testing.assert_allclose(vals, [1.0, 0.2], rtol=0.03)


@pytest.mark.parametrize("pos, column", [("0 0 5", 0.25), ("-5 0 0", 0.5), ("5 0 0", 0.0)])
def test_spherical_camera_directions(tmp_path, pos, column):
    """pbrt-v4's equirectangular spherical camera: u = phi / 2 pi of the camera-space
    direction (x, z, y) in spherical coordinates (pbrt-v4 swaps y and z), v = theta / pi:
    camera +z at u = 1/4, -x at u = 1/2, +x at u = 0 (the seam), all at v = 1/2. The
    reader's to_world (the CTM's inverse times Scale(-1, 1, 1), as for every camera) gives
    these positions; without the mirror, -x and +x swap."""
    path = write(tmp_path, f"""
LookAt 0 0 0  0 0 1  0 1 0
Camera "spherical" "string mapping" "equirectangular"
Film "rgb" "integer xresolution" 32 "integer yresolution" 16
Sampler "independent" "integer pixelsamples" 16
Integrator "path" "integer maxdepth" 1
PixelFilter "box"
WorldBegin
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Translate {pos}
  Shape "sphere" "float radius" 0.4
AttributeEnd
""")
    assert to_dict(path)["sensor"]["type"] == "spherical"
    img = luminance(render_mean(path))
    cols = img.sum(axis=0)
    c = np.arange(32) + 0.5
    # circular mean of the lit columns (the seam wraps around)
    ang = np.angle(np.sum(cols * np.exp(2j * np.pi * c / 32))) / (2 * np.pi) % 1.0
    assert min(abs(ang - column), 1 - abs(ang - column)) < 0.02, ang
    rows = img.sum(axis=1)
    assert rows[7:9].sum() > 0.9 * rows.sum()


def test_realistic_camera_from_pbrt(tmp_path):
    """A realistic camera: its lens file is found relative to the scene, the film's
    'diagonal' reaches it (so the film is pbr's rgb, not hdrfilm), and a light at
    camera-space +x (pbrt-v4's: the image's right) shows in the right half."""
    (tmp_path / "lenses").mkdir()
    (tmp_path / "lenses" / "singlet.dat").write_text(
        "# a biconvex singlet (R 50 mm, 5 mm thick, n 1.5), the stop 2 mm behind it\n"
        "50 5 1.5 20\n-50 2 1 20\n0 45 0 10\n")
    path = write(tmp_path, """
LookAt 0 0 0  0 0 1  0 1 0
Camera "realistic" "string lensfile" "lenses/singlet.dat" "float aperturediameter" 10 "float focusdistance" 100
Film "rgb" "integer xresolution" 32 "integer yresolution" 24 "float diagonal" 20
Sampler "independent" "integer pixelsamples" 64
Integrator "path" "integer maxdepth" 1
PixelFilter "box"
WorldBegin
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Translate 8 0 100
  Shape "sphere" "float radius" 2
AttributeEnd
""")
    d = to_dict(path)
    assert d["sensor"]["lensfile"] == str(tmp_path / "lenses" / "singlet.dat")
    assert d["sensor"]["film"]["type"] == "rgb" and d["sensor"]["film"]["diagonal"] == 20.0
    img = luminance(render_mean(path))
    w = img.shape[1]
    assert img[:, w // 2:].sum() > 20 * img[:, :w // 2].sum()


def test_gbuffer_and_spectral_films(tmp_path):
    """Film "gbuffer" and "spectral" become pbr's films of those names with pbrt-v4's
    parameters (the image has their extra channels); 'exposuretime', which pbrt-v4's
    films do not take, is noted."""
    body = 'WorldBegin\nLightSource "point" "point3 from" [0 0 3]\nShape "sphere"\n'
    g = write(tmp_path, HEAD.replace('Film "rgb"', 'Film "gbuffer" "string coordinatesystem" "world" '
                                     '"float exposuretime" 2') + body, "g.pbrt")
    d, notes, _ = convert(g)
    assert d["sensor"]["film"]["type"] == "gbuffer" and d["sensor"]["film"]["coordinatesystem"] == "world"
    assert "exposuretime" not in d["sensor"]["film"] and any("exposuretime" in n for n in notes)
    assert np.asarray(pbr.render(pbr.load_dict(d), spp=1)).shape == (24, 32, 3 + 14)
    s = write(tmp_path, HEAD.replace('Film "rgb"', 'Film "spectral" "integer nbuckets" 4') + body, "s.pbrt")
    d = to_dict(s)
    assert d["sensor"]["film"]["type"] == "spectral" and d["sensor"]["film"]["nbuckets"] == 4
    assert np.asarray(pbr.render(pbr.load_dict(d), spp=1)).shape == (24, 32, 3 + 4)


def test_imagemap_encoding_as_pbrt(tmp_path):
    """pbrt-v4 decodes 8-bit PNG files with 'encoding' (default sRGB) and every other
    8-bit format (JPEG, ...) as sRGB whatever 'encoding' says: a grey JPEG texel of 128
    with "encoding" "linear" reads as sRGB 128 (0.216), a PNG one as 128/255 (0.502)."""
    import mitsuba as mi
    img = np.full((4, 4, 3), 128, dtype=np.uint8)
    for ext in ("png", "jpg"):
        mi.Bitmap(img).write(str(tmp_path / f"grey.{ext}"))
    vals = []
    for ext in ("png", "jpg"):
        path = write(tmp_path, flat_view(4, 64) + f"""LightSource "distant" "point3 from" [0 0 1] "point3 to" [0 0 0] "rgb L" [3.14159265 3.14159265 3.14159265]
Texture "t" "float" "imagemap" "string filename" "grey.{ext}" "string encoding" "linear"
Material "diffuse" "texture reflectance" "t"
Shape "trianglemesh" "point3 P" [-1 -1 0 1 -1 0 1 1 0 -1 1 0] "integer indices" [0 1 2 0 2 3] "point2 uv" [0 0 1 0 1 1 0 1]
""", f"{ext}.pbrt")
        vals.append(luminance(render_mean(path)).mean())
    srgb = ((128 / 255 + 0.055) / 1.055) ** 2.4
    np.testing.assert_allclose(vals, [128 / 255, srgb], rtol=0.03)


def test_subsurface_named_coefficients(tmp_path):
    """pbrt-v4's subsurface "name": the measured coefficients (pbr.media.presets, mm^-1)
    replace sigma_a/sigma_s and g (noted); scale stays."""
    path = write(tmp_path, HEAD + 'WorldBegin\nMaterial "subsurface" "string name" "Skin1" "float scale" 10 '
                                  '"float g" 0.5\nShape "sphere"\n')
    d, notes, _ = convert(path)
    b = next(v for v in d.values() if isinstance(v, dict) and v.get("type") == "subsurface")
    assert b["type"] == "subsurface" and b["scale"] == 10.0 and "g" not in b
    assert b["sigma_a"]["value"] == [0.032, 0.17, 0.48] and b["sigma_s"]["value"] == [0.74, 0.88, 1.01]
    assert any("replaces 'g'" in n for n in notes)
    assert np.isfinite(np.asarray(pbr.render(pbr.load_dict(d), spp=1))).all()
