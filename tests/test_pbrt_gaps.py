"""pbrt-v4 features the reader maps to pbr plugins added for them: the infinite light's
``portal``, named camera sensors, the ``cloud`` medium, two-sided and image area lights.
Each is checked against an independent value (NumPy or a closed form)."""
import math

import numpy as np
import pytest

import pbr
from pbr.scene.pbrt import convert, to_dict
from pbr.scene.xml import XMLError
from test_pbrt import write


def render(path, **kw):
    return np.asarray(pbr.render(pbr.load_file(path, **kw), seed=1), dtype=np.float64)


# -- infinite light with a portal ------------------------------------------------------------

PORTAL = """
LookAt 0 0 0  1 0 0  0 0 1
Camera "perspective" "float fov" 90
Film "rgb" "integer xresolution" 40 "integer yresolution" 40
Sampler "independent" "integer pixelsamples" 32
Integrator "path" "integer maxdepth" 1
WorldBegin
Translate 0 0 3
Rotate 30 0 0 1
LightSource "infinite" {L}
    "point3 portal" [5 -1 -1  5 -1 1  5 1 1  5 1 -1]
Translate -20 0 0
Shape "sphere" "float radius" 0.1
"""


def _planck(lam_nm, t):
    lam = lam_nm * 1e-9
    c, h, k = 299792458.0, 6.62606957e-34, 1.3806488e-23
    return 2 * h * c * c / lam ** 5 / np.expm1(h * c / (lam * k * t))


def test_portal_light_window_and_radiance(tmp_path):
    """The portal's points are in world space (pbrt-v4 ignores the CTM for them) and light
    comes through toward the side cross(p3 - p0, p1 - p0) faces away from: a camera at the
    origin looking at the 2x2 portal at x = 5 (fov 90) sees the radiance in the central
    fifth of the image and black around it; an RGB L keeps its value times scale."""
    path = write(tmp_path, PORTAL.format(L='"rgb L" [0.3 0.5 0.7] "float scale" 2'))
    d = to_dict(path)
    light = [v for v in d.values() if isinstance(v, dict) and v.get("type") == "portalenvmap"]
    assert len(light) == 1 and light[0]["portal"][0] == [5.0, -1.0, -1.0]
    img = render(path)
    n = img.shape[0]
    inside = img[n // 2 - 3:n // 2 + 3, n // 2 - 3:n // 2 + 3].reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(inside, [0.6, 1.0, 1.4], rtol=0.03)
    outside = np.concatenate([img[:n // 2 - 5].ravel(), img[n // 2 + 5:].ravel(),
                              img[:, :n // 2 - 5].ravel(), img[:, n // 2 + 5:].ravel()])
    assert outside.max() == 0.0
    # pbrt-v4 converts L to sRGB for a portal light without normalising its luminance: a
    # blackbody (peak 1) keeps its own luminance (NumPy: Planck's law against CIE ybar).
    from pbr.spectrum import CIE_Y_INTEGRAL, cie_tables_np
    xyz, _ = cie_tables_np()
    lam = 360.0 + 5.0 * np.arange(len(xyz))
    b = _planck(lam, 6500.0) / _planck(np.array([2.8977721e6 / 6500.0]), 6500.0)
    Y = np.trapezoid(b * xyz[:, 1], lam) / CIE_Y_INTEGRAL
    d = to_dict(write(tmp_path, PORTAL.format(L='"blackbody L" 6500 "float scale" 7.5'), "bb.pbrt"))
    light = [v for v in d.values() if isinstance(v, dict) and v.get("type") == "portalenvmap"][0]
    rgb = np.asarray(light["data"])[0, 0]
    assert light["scale"] == 7.5
    assert rgb @ [0.2126, 0.7152, 0.0722] == pytest.approx(Y, rel=2e-3)
    assert rgb.max() / rgb.min() < 1.1     # 6500 K is nearly sRGB's white


def test_portal_light_errors_and_mitsuba(tmp_path):
    bad = write(tmp_path, PORTAL.format(L='"rgb L" [1 1 1]').replace("5 1 1  5 1 -1]", "5 1 1]"), "bad.pbrt")
    with pytest.raises(XMLError, match=r"bad.pbrt:11: LightSource: parameter 'portal': expected 4 points"):
        to_dict(bad)
    path = write(tmp_path, PORTAL.format(L='"rgb L" [1 1 1]'))
    with pytest.raises(XMLError, match="portal.*not supported"):
        to_dict(path, mitsuba=True)
    d, notes, _ = convert(path, mitsuba=True, approximate=True)
    assert any(v.get("type") == "envmap" for v in d.values() if isinstance(v, dict))


# -- named camera sensors ----------------------------------------------------------------------

def _table(name):
    import os
    rows = [ln.split() for ln in open(os.path.join(os.path.dirname(pbr.__file__), "data", name))
            if ln.strip() and not ln.startswith("#")]
    return rows


def _canon_curves(lam):
    rows, out, on = _table("camera_sensors.txt"), [], False
    for r in rows:
        if r[0] == "camera":
            on = r[1] == "canon_eos_100d"
        elif on:
            out.append([float(x) for x in r])
    c = np.array(out)
    return [np.interp(lam, c[:, 0], c[:, k], left=0, right=0) for k in (1, 2, 3)]


def test_sensor_matrix_matches_pbrt_formula():
    """pbrt-v4's XYZFromSensorRGB for canon_eos_100d balanced for 6500 K, recomputed here
    with the normal equations (pbrt-v4's LinearLeastSquares: M = (A^T B)^T (A^T A)^-1) and
    the tabulated CIE D65 (pbrt-v4's D(6500) is D65 within 1e-3): within 2e-3."""
    from pbr.films import sensor_xyz_matrix
    from pbr.spectrum import cie_tables_np
    lam = np.arange(360.0, 831.0)
    r, g, b = _canon_curves(lam)
    xyz_tab, d65_tab = cie_tables_np()
    grid = 360.0 + 5.0 * np.arange(len(d65_tab))
    X, Y, Z = (np.interp(lam, grid, xyz_tab[:, k]) for k in range(3))
    d65 = np.interp(lam, grid, d65_tab)
    sw = np.array([[float(x) for x in row] for row in _table("colorchecker_swatches.spd")])
    A, B = np.zeros((24, 3)), np.zeros((24, 3))
    for i in range(24):
        s = np.interp(lam, sw[:, 0], sw[:, i + 1], left=0, right=0)
        A[i] = [np.sum(c * s * d65) / np.sum(g * d65) for c in (r, g, b)]
        B[i] = [np.sum(c * s * d65) / np.sum(Y * d65) for c in (X, Y, Z)]
    B *= np.sum(d65 * Y) / np.sum(d65 * g)
    M = (A.T @ B).T @ np.linalg.inv(A.T @ A)
    np.testing.assert_allclose(sensor_xyz_matrix("canon_eos_100d", 6500.0), M, rtol=2e-3, atol=2e-3)


def _env(sensor, wb, T, iso=100.0):
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 1},
            "cam": {"type": "perspective", "fov": 40.0, "film": {"type": "rgb", "xresolution": 4, "yresolution": 4,
                                                                 "sensor": sensor, "whitebalance": wb, "iso": iso}},
            "s": {"type": "sphere", "center": [0, 0, -50], "radius": 0.1},
            "env": {"type": "constant", "radiance": {"type": "scale", "scale": 0.5,
                                                     "tex": {"type": "blackbody", "temperature": T}}}}


def test_camera_sensor_white_balance_keeps_grey(tmp_path):
    """A grey (0.5) surface under a 3000 K light seen by canon_eos_100d balanced for 3000 K
    (pbrt-v4's D(t) is a blackbody below 4000 K) stays grey (channels within 4%: the
    least-squares fit is not exact for white), and equals the NumPy value
    sRGB(M (iso/100) int rbar L) within 1.5%; balanced for 6500 K (the default) it is orange.
    The reader passes pbrt-v4's sensor names through."""
    from pbr.films import sensor_xyz_matrix
    from pbr.spectrum import CIE_Y_INTEGRAL, XYZ_TO_SRGB, blackbody
    img = np.asarray(pbr.render(pbr.load_dict(_env("canon_eos_100d", 3000.0, 3000.0, iso=200)), spp=512, seed=1))
    rgb = img.reshape(-1, 3).mean(axis=0)
    assert rgb.max() / rgb.min() < 1.04
    lam = np.arange(360.0, 831.0)
    L = 0.5 * blackbody(lam, 3000.0)
    cam = np.array([np.trapezoid(c * L, lam) for c in _canon_curves(lam)]) / CIE_Y_INTEGRAL
    expect = XYZ_TO_SRGB @ sensor_xyz_matrix("canon_eos_100d", 3000.0) @ cam * 2.0
    np.testing.assert_allclose(rgb, expect, rtol=0.015)
    warm = np.asarray(pbr.render(pbr.load_dict(_env("canon_eos_100d", 0.0, 3000.0)), spp=64, seed=1))
    w = warm.reshape(-1, 3).mean(axis=0)
    assert w[0] > 1.5 * w[2]
    head = PORTAL.split("WorldBegin")[0]
    ok = write(tmp_path, head.replace('Film "rgb"', 'Film "rgb" "string sensor" "nikon_d810"')
               + 'WorldBegin\nShape "sphere"\n', "n.pbrt")
    assert to_dict(ok)["sensor"]["film"]["sensor"] == "nikon_d810"
    pbr.load_file(ok)
    bad = write(tmp_path, head.replace('Film "rgb"', 'Film "rgb" "string sensor" "leica"')
                + 'WorldBegin\nShape "sphere"\n', "b.pbrt")
    with pytest.raises(XMLError, match=r"b.pbrt:4: Film: parameter 'sensor': unknown sensor 'leica'"):
        to_dict(bad)


# -- the cloud medium ---------------------------------------------------------------------------

def np_cloud(p, density, wispiness, frequency):
    """pbrt-v4's CloudMedium::Density in NumPy (float64), from its formulas."""
    from test_textures_pbrt import np_noise
    pp = frequency * p
    vo, vl = 0.05 * wispiness, 10.0
    for _ in range(2):
        q = vl * pp
        n = np_noise(*q)
        g = np.stack([(np_noise(*(q + 0.01 * e[:, None])) - n) / 0.01 for e in np.eye(3)])
        pp = pp + vo * g
        vo, vl = vo * 0.5, vl * 1.99
    d, o, lam = 0.0, 0.5, 1.0
    for _ in range(5):
        d = d + o * np_noise(*(lam * pp))
        o, lam = o * 0.5, lam * 1.99
    d = np.clip((1 - p[1]) * 4.5 * density * d, 0, 1)
    return np.clip(d + 2 * np.maximum(0, 0.5 - p[1]), 0, 1)


@pytest.mark.parametrize("wisp", [0.0, 1.0])
def test_cloud_density_matches_numpy(wisp):
    import mitsuba as mi
    from pbr.media.cloud import cloud_density
    from pbr.textures.procedural import NOISE_PERM
    rng = np.random.default_rng(4)
    p = rng.uniform(0, 1, (3, 2000))
    got = np.asarray(cloud_density(mi.UInt32(NOISE_PERM), mi.Point3f(*p), 2.0, wisp, 5.0))
    want = np_cloud(p, 2.0, wisp, 5.0)
    assert 0.05 < want.mean() < 0.95 and want.std() > 0.1
    # float32 noise differences of step 0.01 amplify rounding: a few points differ more.
    assert np.mean(np.abs(got - want) < 1e-3) > 0.99 and np.abs(got - want).mean() < 2e-4


CLOUD = """
LookAt 0.5 0.5 -2  0.5 0.5 0  0 1 0
Camera "orthographic" "float screenwindow" [-0.5 0.5 -0.5 0.5]
Film "rgb" "integer xresolution" 8 "integer yresolution" 8
PixelFilter "box"
Sampler "independent" "integer pixelsamples" 4096
Integrator "volpath" "integer maxdepth" 1
WorldBegin
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Shape "trianglemesh" "point3 P" [-1 -1 1.8  -1 2 1.8  2 2 1.8  2 -1 1.8] "integer indices" [0 1 2 0 2 3]
AttributeEnd
MakeNamedMedium "c" "string type" "cloud" "spectrum sigma_s" [200 0 900 0] "spectrum sigma_a" [200 2 900 2]
   "float density" 2 "float wispiness" 0
MediumInterface "c" ""
Material ""
Translate .5 .5 .5
Shape "sphere" "float radius" 1
"""


def test_cloud_medium_transmittance(tmp_path):
    """Through a purely absorbing cloud (sigma_a 2) each pixel of an orthographic view of a
    unit emitter is the mean over the pixel of exp(-2 int_0^1 d(x, y, z) dz) (NumPy: 8x8
    rays per pixel, 200 steps; 4096 spp): the reader's mapping (box, transform), pbr's density and
    its majorant (the density's bound 1) together."""
    d = to_dict(write(tmp_path, CLOUD))
    med = [v for v in d.values() if isinstance(v, dict) and v.get("type") == "cloud"][0]
    assert med["type"] == "cloud" and med["density"] == 2.0 and med["wispiness"] == 0.0
    img = render(str(tmp_path / "scene.pbrt"))
    lum = img.mean(axis=2)
    s = (np.arange(8)[:, None] + (np.arange(8) + 0.5)[None, :] / 8).ravel() / 8     # 64 x positions per 8 pixels
    z = (np.arange(200) + 0.5) / 200
    X, Y, Z = np.meshgrid(s, 1 - s, z, indexing="xy")
    dens = np_cloud(np.stack([X.ravel(), Y.ravel(), Z.ravel()]), 2.0, 0.0, 5.0).reshape(X.shape)
    T = np.exp(-2.0 * dens.mean(axis=2))
    want = T.reshape(8, 8, 8, 8).mean(axis=(1, 3))
    assert want.std() > 0.05
    # Each sample sees the emitter or not (delta tracking): binomial noise, 4.5 sigma per pixel.
    sigma = np.sqrt(want * (1 - want) / 4096) + 1e-3
    assert np.all(np.abs(lum - want) < 4.5 * sigma), np.abs(lum - want) / sigma
    assert abs((lum - want).mean()) < 3 * np.sqrt((sigma ** 2).sum()) / 64


# -- two-sided and image area lights ----------------------------------------------------------

AREA = """
LookAt 0 0 {z}  0 0 0  0 1 0
Camera "perspective" "float fov" 30
Film "rgb" "integer xresolution" 16 "integer yresolution" 16
PixelFilter "box"
Sampler "independent" "integer pixelsamples" 256
Integrator "path" "integer maxdepth" 1
WorldBegin
AreaLightSource "diffuse" {light}
Shape "trianglemesh" "point3 P" [-1 -1 0  1 -1 0  1 1 0  -1 1 0] "integer indices" [0 1 2 0 2 3]
    "point2 uv" [0 0  1 0  1 1  0 1]
"""


def test_two_sided_area_light(tmp_path):
    """The quad's normal is +z: seen from -z a one-sided light is black, a two-sided one
    shows L on both sides; with 'power' P each of the quad's two triangles (area 2) gets P
    (pbrt-v4: one light per triangle), radiance P / (2 pi 2) when two-sided (k_e doubles)."""
    def centre(z, light, name):
        img = render(write(tmp_path, AREA.format(z=z, light=light), name))
        return img[6:10, 6:10].mean(axis=(0, 1))
    one_front = centre(5, '"rgb L" [1 2 3]', "a.pbrt")
    one_back = centre(-5, '"rgb L" [1 2 3]', "b.pbrt")
    two_back = centre(-5, '"rgb L" [1 2 3] "bool twosided" true', "c.pbrt")
    np.testing.assert_allclose(one_front, [1, 2, 3], rtol=0.03)
    assert one_back.max() == 0.0
    np.testing.assert_allclose(two_back, [1, 2, 3], rtol=0.03)
    p = centre(-5, '"bool twosided" true "float power" 100', "d.pbrt")
    np.testing.assert_allclose(p, 100 / (2 * math.pi * 2), rtol=0.02)
    d = to_dict(str(tmp_path / "c.pbrt"))
    assert [v["emitter"]["twosided"] for v in d.values() if isinstance(v, dict) and "emitter" in v] == [True]


@pytest.mark.parametrize("integrator", ["path", "lightpath", "bdpt"])
def test_two_sided_area_light_illuminates_both_sides(tmp_path, integrator):
    """A small disk light above a diffuse floor, its normal pointing up (away from the
    floor): one-sided it leaves the floor black, two-sided it lights the floor as a
    one-sided disk facing down does (next-event estimation and the light BVH take both
    sides; pixels away from the disk); also for the light tracers (sample_Le: half the
    rays leave the back)."""
    scene = """
LookAt 0 0 6  0 0 0  0 1 0
Camera "perspective" "float fov" 20
Film "rgb" "integer xresolution" 8 "integer yresolution" 8
PixelFilter "box"
Sampler "independent" "integer pixelsamples" {spp}
Integrator "{integ}" "integer maxdepth" 1
WorldBegin
AttributeBegin
  Translate 0 0 1
  {rev}
  AreaLightSource "diffuse" "rgb L" [1 1 1] {two}
  Shape "disk" "float radius" 0.3
AttributeEnd
Shape "trianglemesh" "point3 P" [-3 -3 0  3 -3 0  3 3 0  -3 3 0] "integer indices" [0 1 2 0 2 3]
"""
    c = np.arange(8) - 3.5
    far = np.hypot(*np.meshgrid(c, c)) > 2.6
    spp = 256 if integrator == "path" else 2048
    two = render(write(tmp_path, scene.format(rev="", two='"bool twosided" true', integ=integrator, spp=spp), "t.pbrt"))[far]
    down = render(write(tmp_path, scene.format(rev="ReverseOrientation", two="", integ=integrator, spp=spp), "d.pbrt"))[far]
    up = render(write(tmp_path, scene.format(rev="", two="", integ=integrator, spp=spp), "u.pbrt"))[far]
    assert down.mean() > 0.01 and up.max() == 0.0
    assert two.mean() == pytest.approx(down.mean(), rel=0.03)


def test_image_area_light(tmp_path):
    """pbrt-v4 looks an area light's image up at (u, 1 - v): on a quad whose v grows upward,
    the image's first rows show at the top; 'scale' multiplies it."""
    import mitsuba as mi
    img = np.zeros((8, 8, 3), np.float32)
    img[:4] = [1.0, 0.0, 0.0]
    img[4:] = [0.0, 0.5, 0.0]
    mi.Bitmap(img).write(str(tmp_path / "e.exr"))
    path = write(tmp_path, AREA.format(z=5, light='"string filename" "e.exr" "float scale" 2'))
    out = render(path)
    top, bottom = out[4:7, 6:10].mean(axis=(0, 1)), out[9:12, 6:10].mean(axis=(0, 1))
    np.testing.assert_allclose(top, [2, 0, 0], atol=0.08)
    np.testing.assert_allclose(bottom, [0, 1, 0], atol=0.05)
    # 'power' P: pbrt-v4's k_e = pi A (per triangle, area 2) times the image's mean luminance.
    mean_lum = 0.5 * 0.2126 + 0.5 * 0.5 * 0.7152
    out = render(write(tmp_path, AREA.format(z=5, light='"string filename" "e.exr" "float power" 10'), "p.pbrt"))
    k = 10 / (math.pi * 2 * mean_lum)
    np.testing.assert_allclose(out[4:7, 6:10].mean(axis=(0, 1)), [k, 0, 0], atol=0.04 * k)
    with pytest.raises(XMLError, match="give either"):
        to_dict(write(tmp_path, AREA.format(z=5, light='"string filename" "e.exr" "rgb L" [1 1 1]'), "x.pbrt"))


# -- material displacement (bump mapping), textures bilerp and directionmix --------------------

def perspective_head(z: float) -> str:
    """A 16 x 16, 4 spp perspective view (fov 40) from (0, 0, z) at the origin, up to
    WorldBegin."""
    return f"""
LookAt 0 0 {z}  0 0 0  0 1 0
Camera "perspective" "float fov" 40
Film "rgb" "integer xresolution" 16 "integer yresolution" 16
Sampler "independent" "integer pixelsamples" 4
WorldBegin
"""


QUAD = perspective_head(3) + """{world}
Shape "trianglemesh" "point3 P" [-1 -1 0  1 -1 0  1 1 0  -1 1 0] "integer indices" [0 1 2  0 2 3]
    "point2 uv" [0 0  1 0  1 1  0 1]
"""


@pytest.mark.parametrize("a", [0.4, 1.5])
def test_displacement_tilts_the_shading_normal(tmp_path, a):
    """pbrt-v4's BumpMap on a 2 x 2 quad with uv in [0, 1]^2 and d(u, v) = a u (a
    ``bilerp`` float texture): dp/du' = dp/du + a n, so the shading normal tilts by
    atan(a du/dp) = atan(a / 2) toward -x."""
    world = (f'Texture "d" "float" "bilerp" "float v00" 0 "float v10" {a} "float v01" 0 "float v11" {a}\n'
             'Material "diffuse" "texture displacement" "d"')
    d = to_dict(write(tmp_path, QUAD.format(world=world)))
    bsdf = next(v for v in d.values() if isinstance(v, dict) and v.get("type") == "bumpmap")
    assert bsdf["displacement"]["type"] == "bilerp"
    d["integrator"] = {"type": "aov", "aovs": "nn:sh_normal"}
    n = np.asarray(pbr.render(pbr.load_dict(d), seed=1), np.float64)[3:-3, 3:-3]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    assert np.abs(np.degrees(np.arccos(n[..., 2])) - math.degrees(math.atan(a / 2))).max() < 0.01
    assert (n[..., 0] < 0).all()


def test_displacement_notes(tmp_path):
    """A constant displacement displaces nothing (no wrapper); with a normal map pbrt-v4
    ignores the displacement (noted); Mitsuba's bumpmap takes bitmaps only."""
    d = to_dict(write(tmp_path, QUAD.format(world='Material "diffuse" "float displacement" 0.3')))
    assert all(v.get("type") != "bumpmap" for v in d.values() if isinstance(v, dict))
    world = 'Texture "d" "float" "checkerboard"\nMaterial "diffuse" "texture displacement" "d"'
    with pytest.raises(XMLError, match="displacement' of a non-image texture"):
        convert(write(tmp_path, QUAD.format(world=world)), mitsuba=True)
    flat = np.zeros((2, 2, 3), np.float32) + np.array([0.5, 0.5, 1.0], np.float32)
    pbr.write_image(str(tmp_path / "n.exr"), flat)
    world = 'Texture "d" "float" "fbm"\nMaterial "diffuse" "texture displacement" "d" "string normalmap" "n.exr"'
    _, notes, _ = convert(write(tmp_path, QUAD.format(world=world)))
    assert any("'displacement' is ignored with a 'normalmap'" in n for n in notes)


def test_directionmix_and_bilerp_read_from_pbrt(tmp_path):
    """``directionmix`` takes the CTM at its Texture directive for ``dir``: (0, 1, 0)
    rotated to +z faces the quad's normal, so tex1 is seen (as a constant reflectance);
    a ``bilerp`` of four equal values is that value."""
    def img(world):
        return render(write(tmp_path, QUAD.format(world=world)))
    light = 'LightSource "infinite" "rgb L" [1 1 1]\n'
    ref = img(light + 'Material "diffuse" "rgb reflectance" [0.8 0.3 0.1]')
    mixed = img(light + 'AttributeBegin\nRotate 90 1 0 0\nTexture "m" "spectrum" "directionmix" "rgb tex1" [0.8 0.3 0.1]'
                ' "rgb tex2" [0 0 1] "vector3 dir" [0 1 0]\nAttributeEnd\nMaterial "diffuse" "texture reflectance" "m"')
    assert np.abs(mixed - ref).max() < 1e-4 * ref.max()
    unrotated = img(light + 'Texture "m" "spectrum" "directionmix" "rgb tex1" [0.8 0.3 0.1] "rgb tex2" [0 0 1]'
                    '\nMaterial "diffuse" "texture reflectance" "m"')
    assert unrotated[..., 2].mean() > 2 * ref[..., 2].mean()
    flat = img(light + 'Texture "b" "spectrum" "bilerp" "rgb v00" [0.8 0.3 0.1] "rgb v01" [0.8 0.3 0.1]'
               ' "rgb v10" [0.8 0.3 0.1] "rgb v11" [0.8 0.3 0.1]\nMaterial "diffuse" "texture reflectance" "b"')
    assert np.abs(flat - ref).max() < 1e-3 * ref.max()


# -- medium presets ----------------------------------------------------------------------------

MEDIUM = """
LookAt 0 0 3  0 0 0  0 1 0
Camera "perspective" "float fov" 40
Film "rgb" "integer xresolution" 8 "integer yresolution" 8
WorldBegin
MakeNamedMedium "m" "string type" "{type}" {params}
AttributeBegin
MediumInterface "m" ""
Material "interface"
Shape "sphere" "float radius" 1
AttributeEnd
"""

# (sigma'_s, sigma_a) in mm^-1 as printed in Jensen et al. 2001 (table 2) and Narasimhan
# et al. 2006 (table 1), typed here from the papers' values.
PUBLISHED = {"Apple": ((2.29, 2.39, 1.97), (0.0030, 0.0034, 0.046)),
             "Skimmilk": ((0.70, 1.22, 1.90), (0.0014, 0.0025, 0.0142)),
             "Ketchup": ((0.18, 0.07, 0.03), (0.061, 0.97, 1.45)),
             "Espresso": ((0.72378, 0.84557, 1.0247), (4.7984, 6.5751, 8.8493)),
             "Regular Milk": ((4.5513, 5.8294, 7.136), (0.0015333, 0.0046, 0.019933))}


def _medium(tmp_path, typ, params, **kw):
    d, notes, _ = convert(write(tmp_path, MEDIUM.format(type=typ, params=params)), **kw)
    return d["medium_m"], notes


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_medium_preset_is_the_published_table(tmp_path, name):
    """pbrt-v4's preset: sigma_s = the measured reduced scattering sigma'_s, sigma_a, both
    in mm^-1 and times ``scale``; explicit sigma_a/sigma_s are replaced (noted)."""
    m, notes = _medium(tmp_path, "homogeneous", f'"string preset" "{name}" "float scale" 10 "rgb sigma_a" [1 1 1]')
    sps, sa = PUBLISHED[name]
    assert m["sigma_s"] == {"type": "rgb", "value": list(sps)}
    assert m["sigma_a"] == {"type": "rgb", "value": list(sa)}
    assert m["scale"] == 10.0
    assert any("replaces sigma_a and sigma_s" in n for n in notes)


def test_medium_preset_errors_and_grids(tmp_path):
    with pytest.raises(XMLError, match="unknown preset 'Skim milk' .did you mean 'Skimmilk'"):
        _medium(tmp_path, "homogeneous", '"string preset" "Skim milk"')
    with pytest.raises(XMLError, match="an rgbgrid takes its coefficients from its grids"):
        _medium(tmp_path, "rgbgrid", '"string preset" "Apple" "rgb sigma_a" [1 1 1]')
    m, notes = _medium(tmp_path, "uniformgrid", '"string preset" "Cream" "float density" [1]')
    assert m["sigma_a"]["value"] == [0.0002, 0.0028, 0.0163] and m["sigma_s"]["value"] == [7.38, 5.47, 3.15]
    assert any("reads 'preset' for homogeneous media only" in n for n in notes)


# -- forms of pbrt-v4's syntax found in pbrt-v4-scenes (benchmarks/pbrt_scenes.py) ---------------

GAP_HEAD = perspective_head(5)


def test_repeated_parameter_last_one_wins(tmp_path):
    """pbrt-v4 looks parameters up from the last given, so a repeated parameter overrides
    the earlier one (watercolor/camera-2.pbrt gives "focaldistance" and "lensradius" twice)."""
    path = write(tmp_path, GAP_HEAD + 'Shape "sphere" "float radius" 1 "float radius" 2.5\n')
    d, notes, _ = convert(path)
    sphere = [v for k, v in d.items() if k.startswith("shape_")]
    assert len(sphere) == 1 and sphere[0]["radius"] == 2.5
    assert not any("radius" in n for n in notes)       # the shadowed one is not "unused"


def test_named_material_defined_after_its_use(tmp_path):
    """pbrt-v4 resolves named materials after parsing: contemporary-bathroom uses
    NamedMaterial "light" before it includes materials.pbrt, which defines it."""
    write(tmp_path, 'MakeNamedMaterial "late" "string type" "diffuse" "rgb reflectance" [0.1 0.2 0.3]\n',
          "materials.pbrt")
    path = write(tmp_path, GAP_HEAD + 'NamedMaterial "late"\nShape "sphere"\nInclude "materials.pbrt"\n')
    d, _, _ = convert(path)
    shape = [v for k, v in d.items() if k.startswith("shape_")][0]
    assert shape["bsdf"] == {"type": "ref", "id": "mat_late"}
    assert d["mat_late"]["bsdf"]["reflectance"]["value"] == [0.1, 0.2, 0.3]
    assert list(d).index("mat_late") < list(d).index("shape_0001")    # defined before it is referenced
    pbr.load_dict(d)
    # A name never defined is still an error at the NamedMaterial's line.
    path = write(tmp_path, GAP_HEAD + 'NamedMaterial "never"\nShape "sphere"\n', "bad.pbrt")
    with pytest.raises(XMLError, match=r"bad.pbrt:7: NamedMaterial: unknown material 'never'"):
        convert(path)


def test_parameters_after_include_continue_its_last_directive(tmp_path):
    """pbrt-v4 splices an included file's tokens into the including file, so parameters
    after ``Include`` belong to the included file's last directive (smoke-plume/plume.pbrt
    gives the smoke's sigma_a and sigma_s after including its density grid)."""
    write(tmp_path, '# the grid\nMakeNamedMedium "smoke" "string type" "homogeneous" "float scale" 2\n', "grid.pbrt")
    path = write(tmp_path, GAP_HEAD + 'Include "grid.pbrt"\n  "rgb sigma_a" [0.5 0.25 0.125] "float scale" 3\n'
                 'MediumInterface "smoke" ""\nMaterial "interface"\nShape "sphere"\n')
    d, _, _ = convert(path)
    m = d["medium_smoke"]
    assert m["sigma_a"]["value"] == [0.5, 0.25, 0.125] and m["scale"] == 3.0   # the later "scale" wins
    pbr.load_dict(d)
    # Import parses its file on its own (pbrt-v4): no parameters follow it.
    path = write(tmp_path, GAP_HEAD + 'Import "grid.pbrt" "float scale" 3\n', "imp.pbrt")
    with pytest.raises(XMLError, match=r"imp.pbrt:7: Import: takes no parameters"):
        convert(path)


def test_light_tracing_integrator_with_a_lens_stays(tmp_path):
    """pbr's bdpt connects paths to a static camera, pinhole or thin lens
    (barcelona-pavilion's night view is bdpt with a thin lens): the lens keeps bdpt. A
    moving camera does not: a clear reader error, or volpath under approximate=True,
    instead of a dict that the loader rejects."""
    text = GAP_HEAD.replace('Camera "perspective" "float fov" 40',
                            'Camera "perspective" "float fov" 40 "float lensradius" 0.1 "float focaldistance" 5\n'
                            'Integrator "bdpt" "integer maxdepth" 4') + 'Shape "sphere"\n'
    path = write(tmp_path, text)
    d, notes, _ = convert(path)
    assert d["integrator"] == {"type": "bdpt", "maxdepth": 4}
    assert d["sensor"]["type"] == "thinlens" and d["sensor"]["aperture_radius"] == 0.1
    assert not any("'volpath' is used" in n for n in notes)
    pbr.load_dict(d)
    moving = write(tmp_path, GAP_HEAD.replace(
        'Camera "perspective" "float fov" 40',
        'TransformTimes 0 1\nActiveTransform EndTime\nTranslate 0.1 0 0\nActiveTransform All\n'
        'Camera "perspective" "float fov" 40 "float lensradius" 0.1 "float focaldistance" 5\n'
        'Integrator "bdpt" "integer maxdepth" 4') + 'Shape "sphere"\n', "moving.pbrt")
    with pytest.raises(XMLError, match=r"moving.pbrt:\d+: Integrator: 'bdpt' with a moving 'thinlens' camera.* "
                                       r"not supported"):
        convert(moving)
    d, notes, _ = convert(moving, approximate=True)
    assert d["integrator"] == {"type": "volpath", "max_depth": 5}
    assert any("'volpath' is used" in n for n in notes)
    pbr.load_dict(d)


def test_hair_color_is_its_reflectance(tmp_path):
    """pbrt-v4's hair reads "color" when "reflectance" is not given (bunny-fur.pbrt gives
    "rgb color"): it sets the fibre's colour, not the default eumelanin 1.3."""
    path = write(tmp_path, GAP_HEAD + 'Material "hair" "rgb color" [0.5 0.4 0.3]\n'
                 'Shape "curve" "point3 P" [0 0 0  0 0.3 0  0 0.6 0  0 1 0] "float width" 0.1 "string type" "cylinder"\n')
    d, notes, _ = convert(path)
    m = [v for k, v in d.items() if k.startswith("material_")][0]
    assert m["reflectance"]["value"] == [0.5, 0.4, 0.3] and "eumelanin" not in m
    assert not any("'color'" in n for n in notes)
    path = write(tmp_path, GAP_HEAD + 'Material "hair" "rgb color" [0.5 0.4 0.3] "rgb reflectance" [0.1 0.1 0.1]\n'
                 'Shape "sphere"\n', "both.pbrt")
    m = [v for k, v in convert(path)[0].items() if k.startswith("material_")][0]
    assert m["reflectance"]["value"] == [0.1, 0.1, 0.1]      # "reflectance" wins


def test_skip_missing_leaves_out_a_medium_of_a_missing_file(tmp_path):
    """With skip_missing=True, a medium named after a file was left out (smoke-plume's
    density grid file defines "smoke") is left out with a note; without a missing file,
    an unknown medium is still an error."""
    body = 'Include "grid.pbrt" "rgb sigma_a" [1 1 1]\nMediumInterface "smoke" ""\nMaterial "interface"\nShape "sphere"\n'
    path = write(tmp_path, GAP_HEAD + body)
    d, notes, _ = convert(path, skip_missing=True)
    assert any("unknown medium 'smoke'" in n and "left out" in n for n in notes)
    assert all("interior" not in v for v in d.values() if isinstance(v, dict))
    pbr.load_dict(d)
    with pytest.raises(XMLError, match=r"scene.pbrt:7: Include: file not found"):
        convert(path)
    path = write(tmp_path, GAP_HEAD + 'MediumInterface "smoke" ""\nShape "sphere"\n', "nofile.pbrt")
    with pytest.raises(XMLError, match=r"nofile.pbrt:7: MediumInterface: unknown medium 'smoke'"):
        convert(path, skip_missing=True)
