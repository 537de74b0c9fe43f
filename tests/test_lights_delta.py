"""Delta lights: point, spot, projector / projection, goniometric, directional / distant.

* Mitsuba-equivalent lights (point, spot with and without a projected texture,
  projector with a constant and a bitmap irradiance, directional) against Mitsuba 3
  through the statistical image test, in the Cornell box with its area light removed;
  deliberately wrong variants (intensity x1.05, another falloff, mirrored textures)
  must fail the same test.
* goniometric (no Mitsuba equivalent): a uniform image is a point light (statistically,
  both mappings), a half-black image emits nothing into the matching half of space.
* ``power()`` equals the integral of the emitted intensity (evaluated through
  ``sample_Li`` on a sphere around the light), pbrt-v4's photometric ``power`` /
  ``illuminance`` reach their targets, and LightBounds dicts have pbrt-v4's fields.
* Extremes: 1e6 next to 1e-6, zero-intensity lights (never sampled by the power
  sampler), a light 1e5 away (equals a directional light), degenerate cones.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

import pbr
from pbr import validate
from pbr import spectrum as spec
from pbr.plugins.props import SceneError
from pbr.lights.goniometric import equal_area_sphere_to_square, equal_area_square_to_sphere
from pbr.lights.spot import spot_solid_angle

RES, SPP, BATCHES = 24, 1024, 16


def T():
    return mi.ScalarTransform4f()  # (a variant is set by conftest's fixture)


SPOT_FRAME = dict(origin=[0, 0.9, 0.3], target=[0.2, -1, -0.2], up=[0, 0, 1])
PROJ_FRAME = dict(origin=[0.3, 0.8, 0.9], target=[-0.2, -0.6, -0.5], up=[0, 1, 0])


def box(scale=1, max_depth=6, area_light=False, **emitters):
    """The Cornell box lit by ``emitters`` (its area light removed unless asked for);
    box filter, as in tests/mitsuba_scenes.py."""
    d = pbr.cornell_box(RES * scale, 16)
    if not area_light:
        del d["light"]
    d["integrator"] = {"type": "path", "max_depth": max_depth}
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d.update(emitters)
    return d


def pbr_fn(d):
    scene = pbr.load_dict(d)
    return lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))


def check(d_pbr, d_ref, scale, expect_pass=True, ref_is_pbr=False):
    ref = pbr_fn(d_ref) if ref_is_pbr else validate.mitsuba_render_fn(d_ref)
    res = validate.compare_renders(pbr_fn(d_pbr), ref, spp=SPP * scale, batches=BATCHES, seed_a=31, seed_b=32)
    print(res.summary())
    assert bool(res.passed) == expect_pass, res.summary()
    return res


def rgb(*v):
    return {"type": "rgb", "value": list(v)}


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    """Two small RGB images (values in [0, 1]) and their mirrored copies."""
    root = tmp_path_factory.mktemp("delta_lights")
    out = {}
    for name, (h, w) in {"sq": (8, 8), "wide": (6, 9)}.items():
        img = np.zeros((h, w, 3), np.float32)
        img[..., 0] = np.linspace(0.05, 0.9, w)[None, :]
        img[..., 1] = np.linspace(0.9, 0.1, h)[:, None]
        img[..., 2] = 0.3
        for tag, a in (("", img), ("_mirror_u", img[:, ::-1]), ("_mirror_v", img[::-1])):
            path = str(root / f"{name}{tag}.png")
            pbr.write_image(path, a)
            out[name + tag] = path
    return out


# ------------------------------------------------------------------ vs Mitsuba

def point(intensity=(3.0, 2.5, 2.0), **kw):
    return {"type": "point", "position": [0.2, 0.6, 0.2], "intensity": rgb(*intensity), **kw}


def spot(**kw):
    d = {"type": "spot", "to_world": T().look_at(**SPOT_FRAME), "cutoff_angle": 35.0, "beam_width": 15.0,
         "intensity": rgb(6.0, 5.0, 4.0)}
    d.update(kw)
    return d


def projector(**kw):
    d = {"type": "projector", "to_world": T().look_at(**PROJ_FRAME), "fov": 50.0, "scale": 1.5,
         "irradiance": rgb(1.0, 0.7, 0.5)}
    d.update(kw)
    return d


def test_point_matches_mitsuba(scale):
    check(box(scale, em=point()), box(scale, em=point()), scale)


def test_point_intensity_x105_fails(scale):
    res = check(box(scale, em=point((3.15, 2.625, 2.1))), box(scale, em=point()), scale, expect_pass=False)
    assert res.mean_ratio > 1.0


def test_point_to_world_matches_mitsuba(scale):
    em = {"type": "point", "to_world": T().translate([-0.3, 0.4, 0.1]).rotate([0, 1, 0], 30),
          "intensity": {"type": "blackbody", "temperature": 4000.0}}
    d = box(scale, em=em)
    check(d, box(scale, em=dict(em)), scale)


def test_spot_matches_mitsuba(scale):
    check(box(scale, em=spot()), box(scale, em=spot()), scale)


def test_spot_other_falloff_fails(scale):
    res = check(box(scale, em=spot(beam_width=10.0)), box(scale, em=spot()), scale, expect_pass=False)
    assert res.mean_ratio < 1.0


def test_textured_spot_matches_mitsuba(images, scale):
    em = spot(cutoff_angle=40.0, texture={"type": "bitmap", "filename": images["sq"]})
    del em["beam_width"]
    check(box(scale, em=em), box(scale, em=dict(em)), scale)


def test_textured_spot_mirrored_fails(images, scale):
    em = spot(cutoff_angle=40.0, texture={"type": "bitmap", "filename": images["sq"]})
    wrong = dict(em, texture={"type": "bitmap", "filename": images["sq_mirror_u"]})
    check(box(scale, em=wrong), box(scale, em=em), scale, expect_pass=False)


def test_projector_matches_mitsuba(scale):
    check(box(scale, em=projector()), box(scale, em=projector()), scale)


def test_textured_projector_matches_mitsuba(images, scale):
    # Non-square image (aspect 1.5) and Mitsuba's default field of view (50mm focal length).
    em = projector(scale=2.0, irradiance={"type": "bitmap", "filename": images["wide"]})
    del em["fov"]
    check(box(scale, em=em), box(scale, em=dict(em)), scale)


def test_textured_projector_mirrored_fails(images, scale):
    em = projector(scale=2.0, fov=60.0, irradiance={"type": "bitmap", "filename": images["wide"]})
    wrong = dict(em, irradiance={"type": "bitmap", "filename": images["wide_mirror_v"]})
    check(box(scale, em=wrong), box(scale, em=em), scale, expect_pass=False)


def test_directional_matches_mitsuba(scale):
    em = {"type": "directional", "direction": [0.3, -1.0, -0.4], "irradiance": rgb(2.0, 1.8, 1.5)}
    check(box(scale, em=em), box(scale, em=dict(em)), scale)


def test_directional_tilted_fails(scale):
    em = {"type": "directional", "direction": [0.3, -1.0, -0.4], "irradiance": rgb(2.0, 1.8, 1.5)}
    wrong = dict(em, direction=[0.36, -1.0, -0.4])
    check(box(scale, em=wrong), box(scale, em=em), scale, expect_pass=False)


def test_mixed_families_match_mitsuba(scale):
    """Area + point + spot + directional (to_world) + projector in one scene: dispatch over
    five families with the power light sampler (Mitsuba samples lights uniformly)."""
    ems = {"p": point((0.5, 0.4, 0.3)), "s": spot(), "pj": projector(scale=0.5),
           "dl": {"type": "directional", "irradiance": rgb(0.3, 0.3, 0.3),
                  "to_world": T().look_at(origin=[0, 0, 0], target=[-0.2, -0.5, -1.0], up=[0, 1, 0])}}
    d = box(scale, area_light=True, **ems)
    ems_m = {k: dict(v) for k, v in ems.items()}
    check(d, box(scale, area_light=True, **ems_m), scale)


# ----------------------------------------------------------------- goniometric

def test_equal_area_map_roundtrip_and_area():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(200000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    uv = equal_area_sphere_to_square(d)
    assert np.all((uv >= 0) & (uv <= 1))
    assert np.allclose(equal_area_square_to_sphere(uv), d, atol=2e-6)
    # Equal area: uniform directions fill the square uniformly (8x8 cells, 5 sigma).
    h, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], bins=8, range=[[0, 1], [0, 1]])
    e = len(d) / 64
    assert np.abs(h - e).max() < 5 * math.sqrt(e)
    # Halves: u < 1/2 <=> x < 0, v < 1/2 <=> y < 0; centre = +z, corners = -z.
    assert np.all((uv[:, 0] < 0.5) == (d[:, 0] < 0)) and np.all((uv[:, 1] < 0.5) == (d[:, 1] < 0))
    assert np.allclose(equal_area_sphere_to_square(np.array([0.0, 0, 1])), 0.5)
    # The Dr.Jit version agrees with numpy.
    v = mi.Vector3f(d[:1000, 0], d[:1000, 1], d[:1000, 2])
    assert np.allclose(np.array(equal_area_sphere_to_square(v)).T, uv[:1000], atol=1e-5)


def gonio(image, **kw):
    return {"type": "goniometric", "data": image, "I": rgb(3.0, 2.5, 2.0),
            "to_world": T().translate([0.2, 0.6, 0.2]).rotate([1, 1, 0], 40), **kw}


@pytest.mark.parametrize("shape", [(16, 16), (16, 32)], ids=["equalarea", "equirect"])
def test_uniform_goniometric_equals_point(shape, scale):
    d = box(scale, em=gonio(np.ones(shape)))
    check(d, box(scale, em=point()), scale, ref_is_pbr=True)


def test_brighter_goniometric_differs_from_point(scale):
    check(box(scale, em=gonio(np.full((16, 16), 1.05))), box(scale, em=point()), scale, expect_pass=False,
          ref_is_pbr=True)


def tiny_scene(**emitters):
    """A scene whose only geometry is a small far-away rectangle (lights under test are
    evaluated directly through sample_Li)."""
    d = {"type": "scene", "shape": {"type": "rectangle", "to_world": T().translate([0, 0, -40]).scale(0.1)}}
    d.update(emitters)
    return pbr.load_dict(d)


def sample_Li(scene, family, points, lam=(450.0, 520.0, 580.0, 650.0), local=0):
    fam = scene.lights.families[family]
    points = np.asarray(points, dtype=np.float64)
    n = len(points)
    ref = SimpleNamespace(p=mi.Point3f(points[:, 0], points[:, 1], points[:, 2]), n=mi.Normal3f(0, 0, 1))
    lam = [dr.opaque(mi.Float, float(x)) for x in lam]      # one kernel for every wavelength set
    wl = spec.SampledWavelengths(mi.Spectrum(*lam), mi.Spectrum(1.0))
    ls = fam.sample_Li(dr.full(mi.UInt32, local, n), ref, mi.Point2f(0.5), wl, dr.full(mi.Bool, True, n))
    return SimpleNamespace(L=np.array(ls.L).T, wi=np.array(ls.wi).T, pdf=np.array(ls.pdf), p=np.array(ls.p).T,
                           delta=np.array(ls.delta))


def emitted_Y(scene, family, points, local=0):
    """Luminance of the radiance arriving at ``points`` (integrated over wavelength)."""
    xyz, _ = spec.cie_tables_np()
    grid = spec.LAMBDA_MIN + 5.0 * np.arange(len(xyz))
    w = np.full(len(grid), 5.0)
    w[[0, -1]] = 2.5
    total = 0.0
    for k in range(0, len(grid), 4):
        lam = list(grid[k:k + 4]) + [grid[-1]] * (4 - len(grid[k:k + 4]))
        L = sample_Li(scene, family, points, lam, local).L
        m = min(4, len(grid) - k)
        total = total + (L[:, :m] * (xyz[k:k + m, 1] * w[k:k + m])[None, :]).sum(axis=1)
    return total / spec.CIE_Y_INTEGRAL


def fibonacci_sphere(n):
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = i * math.pi * (3 - math.sqrt(5))
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def test_half_black_goniometric_darkens_half_of_space():
    img = np.ones((16, 16))
    img[:, 8:] = 0.0            # u >= 1/2: local +x (equal-area map)
    eq = np.ones((8, 16))
    eq[:, 8:] = 0.0             # u >= 1/2: local -z half (latitude-longitude map)
    pos = np.array([0.3, -0.2, 0.5])
    scene = tiny_scene(g=gonio(img, to_world=T().translate(pos.tolist())),
                       g2=gonio(eq, to_world=T().translate(pos.tolist())),
                       p=point(position=pos.tolist()))
    dirs = fibonacci_sphere(4000)
    pts = pos + 2.0 * dirs
    ref = sample_Li(scene, "point", pts).L
    assert np.all(ref > 0)
    for local, side in ((0, dirs[:, 0]), (1, -dirs[:, 2])):
        ls = sample_Li(scene, "goniometric", pts, local=local)
        assert np.all(ls.delta) and np.allclose(ls.p, pos, atol=1e-6)
        dark, lit = side > 0.02, side < -0.02
        assert np.all(ls.L[dark] == 0) and np.all(ls.pdf[dark] == 0)
        assert np.allclose(ls.L[lit], ref[lit], rtol=1e-5)
        assert np.all(ls.pdf[lit] == 1)


def test_half_black_goniometric_image():
    """Direct light only: the right half of the image (world x > light x) is black, the
    left half equals the point light's."""
    img = np.ones((16, 16))
    img[:, 8:] = 0.0
    em = gonio(img, to_world=T().translate([0.0, 0.3, 0.0]))
    d = box(max_depth=2, em=em)
    a = validate.estimate(pbr_fn(d), 256, 8, seed=5)
    b = validate.estimate(pbr_fn(box(max_depth=2, em=point(position=[0.0, 0.3, 0.0]))), 256, 8, seed=6)
    assert np.all(a.mean[:, RES // 2:] == 0)
    assert b.mean[:, RES // 2:].mean() > 0.1
    res = validate.compare(a.mean[:, :RES // 2], a.var[:, :RES // 2], b.mean[:, :RES // 2], b.var[:, :RES // 2])
    assert res.passed, res.summary()


# ------------------------------------------------------------------- power

def integrated_power(scene, family, pos, n=200000, local=0):
    """4 pi times the mean luminous intensity over a Fibonacci sphere of radius 1."""
    pts = np.asarray(pos) + fibonacci_sphere(n)
    return 4 * math.pi * emitted_Y(scene, family, pts, local).mean()


def test_power_equals_integrated_intensity(tmp_path):
    grey = np.repeat(np.linspace(0.1, 0.9, 30).reshape(5, 6)[..., None], 3, axis=2).astype(np.float32)
    exr = str(tmp_path / "grey.exr")
    pbr.write_image(exr, grey)
    pos = [0.1, 0.2, 0.3]
    frame = T().look_at(origin=pos, target=[1.0, -0.5, 0.2], up=[0, 1, 0])
    ems = {
        "pt": {"type": "point", "position": pos, "intensity": rgb(2.0, 2.0, 2.0)},
        "pt2": {"type": "point", "position": pos, "intensity": {"type": "blackbody", "temperature": 3000.0},
                "scale": 1e-6},
        "sp": {"type": "spot", "to_world": frame, "cutoff_angle": 35.0, "beam_width": 10.0, "intensity": rgb(2, 2, 2)},
        "pj": {"type": "projector", "to_world": frame, "fov": 70.0, "irradiance": {"type": "bitmap", "filename": exr}},
        "pn": {"type": "projection", "to_world": frame, "fov": 60.0, "filename": exr, "scale": 0.7},
        "gn": {"type": "goniometric", "to_world": frame, "data": np.linspace(0, 2, 64).reshape(8, 8), "I": rgb(1, 1, 1)},
        "ge": {"type": "goniometric", "to_world": frame, "data": np.linspace(0, 2, 64).reshape(4, 16),
               "I": rgb(1, 1, 1)},
    }
    scene = tiny_scene(**ems)
    fams = {"pt": ("point", 0), "pt2": ("point", 1), "sp": ("spot", 0), "pj": ("projector", 0),
            "pn": ("projection", 0), "gn": ("goniometric", 0), "ge": ("goniometric", 1)}
    for key, (fam, local) in fams.items():
        expect = scene.lights.families[fam].power(local, scene)
        got = integrated_power(scene, fam, pos, local=local)
        assert expect == pytest.approx(got, rel=0.01), (key, expect, got)
    # Closed forms.
    assert scene.lights.families["point"].power(0, scene) == pytest.approx(4 * math.pi * 2.0, rel=1e-5)
    assert scene.lights.families["spot"].power(0, scene) == pytest.approx(
        2 * 2 * math.pi * (1 - (math.sin(math.radians(35)) - math.sin(math.radians(10))) / math.radians(25)), rel=1e-5)
    assert spot_solid_angle(math.pi, 0.0) == pytest.approx(2 * math.pi)
    assert spot_solid_angle(0.3, 0.3) == pytest.approx(2 * math.pi * (1 - math.cos(0.3)))
    t = math.tan(math.radians(35))
    lum = float(np.mean(spec.luminance_rgb(np.moveaxis(pbr.image.read_image(exr)[..., :3], -1, 0))))
    assert scene.lights.families["projector"].power(0, scene) == pytest.approx(
        math.pi * 4 * t * t / 1.2 * lum, rel=1e-4)


def test_photometric_power_and_scale():
    frame = T().look_at(origin=[0, 0, 0], target=[0, -1, 0], up=[0, 0, 1])
    data = np.linspace(0.2, 1, 64).reshape(8, 8)
    ems = {
        "pt": {"type": "point", "power": 100.0},
        "pt2": {"type": "point", "intensity": {"type": "blackbody", "temperature": 2500.0}, "power": 30.0},
        "sp": {"type": "spot", "to_world": frame, "power": 50.0, "scale": 3.0},
        "gn": {"type": "goniometric", "data": data, "power": 20.0},
        "pj": {"type": "projector", "to_world": frame, "fov": 40.0, "power": 10.0},
        "pj2": {"type": "projector", "to_world": frame, "fov": 40.0, "scale": 2.0},
        "dl": {"type": "distant", "L": rgb(1, 1, 1), "illuminance": 7.0},
    }
    scene = tiny_scene(**ems)
    F = scene.lights.families
    assert F["point"].power(0, scene) == pytest.approx(100.0, rel=1e-5)
    # A blackbody is normalised by its luminance: the emitted luminous power is 30.
    assert integrated_power(scene, "point", [0, 0, 0], n=2000, local=1) == pytest.approx(30.0, rel=1e-3)
    assert F["spot"].power(0, scene) == pytest.approx(150.0, rel=1e-5)   # scale multiplies the target power
    assert F["goniometric"].power(0, scene) == pytest.approx(20.0, rel=1e-5)
    assert F["projector"].power(0, scene) == pytest.approx(10.0, rel=1e-5)
    t = math.tan(math.radians(20))
    assert F["projector"].power(1, scene) == pytest.approx(2.0 * math.pi * 4 * t * t, rel=1e-5)
    assert emitted_Y(scene, "distant", [[0.0, 0.0, 0.0]])[0] == pytest.approx(7.0, rel=1e-3)
    r = scene.lights.scene_radius
    assert F["distant"].power(0, scene) == pytest.approx(math.pi * r * r * 7.0, rel=1e-4)


def test_light_bounds_dicts():
    frame = T().look_at(origin=[1, 2, 3], target=[1, 0, 3], up=[0, 0, 1])
    scene = tiny_scene(pt={"type": "point", "position": [1, 2, 3], "intensity": rgb(1, 2, 0.5)},
                       sp={"type": "spot", "to_world": frame, "cutoff_angle": 30, "beam_width": 20},
                       pj={"type": "projector", "to_world": frame, "fov": 90},
                       gn={"type": "goniometric", "data": np.ones((4, 4)), "to_world": frame},
                       dl={"type": "directional", "direction": [0, 0, 1]})
    F = scene.lights.families
    keys = {"p_min", "p_max", "phi", "w", "cos_theta_o", "cos_theta_e", "two_sided"}
    for fam in ("point", "spot", "projector", "goniometric"):
        b = F[fam].bounds(0, scene)
        assert set(b) == keys and b["two_sided"] is False
        assert np.allclose(b["p_min"], [1, 2, 3]) and np.allclose(b["p_max"], [1, 2, 3])
        assert b["phi"] > 0 and abs(np.linalg.norm(b["w"]) - 1) < 1e-9
    assert F["point"].bounds(0, scene)["phi"] == pytest.approx(4 * math.pi * 2.0)
    assert (F["point"].bounds(0, scene)["cos_theta_o"], F["point"].bounds(0, scene)["cos_theta_e"]) == (-1.0, 0.0)
    b = F["spot"].bounds(0, scene)
    assert np.allclose(b["w"], [0, -1, 0]) and b["cos_theta_o"] == pytest.approx(math.cos(math.radians(20)))
    assert b["cos_theta_e"] == pytest.approx(math.cos(math.radians(10)))
    b = F["projector"].bounds(0, scene)
    assert b["cos_theta_o"] == 1.0 and b["cos_theta_e"] == pytest.approx(1 / math.sqrt(3))
    assert F["directional"].bounds(0, scene) is None


def test_delta_samples_and_directional_shadow_point():
    scene = tiny_scene(dl={"type": "directional", "direction": [0, -1, 0], "irradiance": 2.0},
                       sp={"type": "spot", "to_world": T().look_at(origin=[0, 1, 0], target=[0, 0, 0], up=[0, 0, 1]),
                           "cutoff_angle": 20})
    pts = np.array([[0.0, 0, 0], [0.5, -0.3, 2.0], [30.0, 0, 0]])
    ls = sample_Li(scene, "directional", pts)
    assert np.all(ls.delta) and np.all(ls.pdf == 1) and np.allclose(ls.wi, [0, 1, 0])
    r = scene.lights.scene_radius
    c = scene.lights.scene_center
    # Shadow-ray targets lie beyond the scene's bounding sphere (and beyond the point).
    dist = np.linalg.norm(ls.p - pts, axis=1)
    assert np.all(dist >= 2 * r - 1e-4) and np.all(np.linalg.norm(ls.p - c, axis=1) > r)
    assert np.allclose((ls.p - pts) / dist[:, None], [0, 1, 0], atol=1e-6)
    # Outside a spot's cone: no radiance and pdf 0 (no shadow ray).
    ls = sample_Li(scene, "spot", [[0.0, 0, 0], [5.0, 0.9, 0]])
    assert ls.L[0].min() > 0 and ls.pdf[0] == 1
    assert np.all(ls.L[1] == 0) and ls.pdf[1] == 0
    # pdf_Li of a delta light is 0 (BSDF sampling never hits it).
    assert np.all(np.array(scene.lights.families["spot"].pdf_Li(mi.UInt32(0), mi.Point3f(0), None, True)) == 0)


def test_projection_pbrt_semantics(tmp_path):
    """pbrt-v4's ``projection``: I = scale E(uv) (nearest texel, no cos^3), fov along the
    shorter image axis."""
    # A grey 8x4 image (flat spectra times D65: compared with a unit D65 point light).
    img = np.repeat((np.arange(8)[None, :, None] / 8 + 0.05).repeat(4, axis=0), 3, axis=2).astype(np.float32)
    path = str(tmp_path / "p.exr")
    pbr.write_image(path, img)
    t = math.tan(math.radians(30))
    tx, ty = 2 * t, t          # aspect 2: the fov spans the shorter (vertical) axis
    rng = np.random.default_rng(3)
    u, v = rng.uniform(0.02, 0.98, 500), rng.uniform(0.02, 0.98, 500)
    x, y = (1 - 2 * u) * tx, (1 - 2 * v) * ty
    dirs = np.stack([x, y, np.ones_like(x)], 1)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    pts = 3.0 * dirs
    scene = tiny_scene(pn={"type": "projection", "filename": path, "fov": 60.0, "scale": 2.0},
                       pr={"type": "point", "intensity": 1.0})
    ls = sample_Li(scene, "projection", pts)
    ref = sample_Li(scene, "point", pts)       # D65 / d^2
    col = np.minimum((u * 8).astype(int), 7)   # nearest texel
    assert np.all(ls.pdf == 1)
    assert np.allclose(ls.L, 2.0 * img[0, col, 0:1] * ref.L, rtol=2e-3)
    # Behind the light or outside the frustum: nothing.
    ls = sample_Li(scene, "projection", [[0, 0, -1.0], [3.0, 0, 1.0], [0, 1.0, 1.0]])
    assert np.all(ls.L == 0) and np.all(ls.pdf == 0)


# ------------------------------------------------------------------ extremes

def test_huge_and_tiny_intensities():
    big = point((1e6, 1e6, 1e6), position=[0.2, 0.6, 0.2])
    tiny = point((1e-6, 1e-6, 1e-6), position=[-0.3, 0.5, 0.0])
    d = box(em=big, em2=tiny)
    d["integrator"]["light_sampler"] = "power"
    scene = pbr.load_dict(d)
    sampler = scene.integrator.light_sampler
    pmf = sampler.pmf_np if hasattr(sampler, "pmf_np") else None
    if pmf is not None:
        assert pmf[1] == pytest.approx(1e-12, rel=1e-3)
    img = np.asarray(pbr.render(scene, spp=32, seed=1))
    d1 = box(em=big)
    d1["integrator"]["light_sampler"] = "power"
    alone = np.asarray(pbr.render(pbr.load_dict(d1), spp=32, seed=1))
    assert np.all(np.isfinite(img)) and img.mean() > 1e4
    assert np.allclose(img, alone, rtol=1e-4, atol=1e-6 * alone.max())


def test_zero_intensity_light_is_never_sampled():
    d = box(em=point(), em0=point((0.0, 0.0, 0.0), position=[-0.3, 0.5, 0.0]),
            em1={"type": "spot", "to_world": T().look_at(**SPOT_FRAME), "intensity": 0.0})
    d["integrator"]["light_sampler"] = "power"
    scene = pbr.load_dict(d)
    s = scene.integrator.light_sampler
    u = mi.Float(np.linspace(0, 1, 100001, endpoint=False))
    idx, pmf = s.sample(u, mi.Point3f(0), mi.Normal3f(0, 0, 1), True)
    idx, pmf = np.array(idx), np.array(pmf)
    assert np.all(idx == 0) and np.allclose(pmf, 1.0)
    assert [scene.lights.families[t].power(i, scene) for t, i in scene.lights.entries][1:] == [0.0, 0.0]
    img = np.asarray(pbr.render(scene, spp=16, seed=2))
    alone = np.asarray(pbr.render(pbr.load_dict(box(em=point())), spp=16, seed=2))
    assert np.allclose(img, alone, rtol=1e-5, atol=1e-7)
    # Only black lights: a black, finite image.
    img = np.asarray(pbr.render(pbr.load_dict(box(em0=point((0.0, 0.0, 0.0)))), spp=4))
    assert np.all(img == 0)


def test_far_point_light_equals_directional(scale):
    """A point light 1e5 away with intensity E d^2 is a directional light of irradiance E."""
    d = np.array([0.25, -0.35, -1.0])
    d /= np.linalg.norm(d)
    far = 1e5
    pl = {"type": "point", "position": (-far * d).tolist(), "intensity": rgb(2e10, 1.6e10, 1.2e10)}
    dl = {"type": "directional", "direction": d.tolist(), "irradiance": rgb(2.0, 1.6, 1.2)}
    res = check(box(scale, em=pl), box(scale, em=dl), scale, ref_is_pbr=True)
    assert abs(res.mean_ratio - 1) < 0.01


def test_degenerate_cones_are_finite():
    d = box(s1=spot(cutoff_angle=25.0, beam_width=25.0),             # hard edge
            s2={"type": "spot", "to_world": T().translate([0, 0.5, 0]), "cutoff_angle": 180.0, "beam_width": 0.0,
                "intensity": 0.5},
            pj=projector(fov=175.0, scale=0.01))
    img = np.asarray(pbr.render(pbr.load_dict(d), spp=8))
    assert np.all(np.isfinite(img)) and img.mean() > 0


# ------------------------------------------------------------ parameters

def test_parameter_errors():
    def load(em):
        return pbr.load_dict(box(em=em))
    with pytest.raises(SceneError, match="em.position"):
        load({"type": "point", "position": [0, 0, 0], "to_world": T().translate([1, 0, 0])})
    with pytest.raises(SceneError, match="em.intensity"):
        load({"type": "point", "intensity": {"type": "checkerboard"}})
    with pytest.raises(SceneError, match="em.beam_width"):
        load({"type": "spot", "cutoff_angle": 10, "beam_width": 20})
    with pytest.raises(SceneError, match="em.texture"):
        load({"type": "spot", "texture": rgb(0.5, 0.5, 0.5)})
    with pytest.raises(SceneError, match="em.mapping"):
        load({"type": "goniometric", "data": np.ones((4, 8)), "mapping": "equalarea"})
    with pytest.raises(SceneError, match="em.direction"):
        load({"type": "directional", "direction": [0, 0, 1], "to_world": T()})
    with pytest.raises(SceneError, match="em.direction"):
        load({"type": "directional", "direction": [0, 0, 0]})
    with pytest.raises(SceneError, match="em.irradiance"):
        load({"type": "directional", "irradiance": {"type": "bitmap", "data": np.ones((2, 2, 3))}})
    with pytest.raises(SceneError, match="em.cutof_angle"):
        load({"type": "spot", "cutof_angle": 10})
    with pytest.raises(SceneError, match="em.filename"):
        load({"type": "projection"})
    with pytest.raises(SceneError, match="em.power"):
        load({"type": "point", "intensity": {"type": "spectrum", "value": 0.0}, "power": 5.0})


def test_distant_alias_and_traverse():
    dl = {"type": "directional", "direction": [0.3, -1.0, -0.4], "irradiance": rgb(2.0, 1.8, 1.5)}
    pb = {"type": "distant", "from": [0, 0, 0], "to": [0.3, -1.0, -0.4], "L": rgb(2.0, 1.8, 1.5)}
    a = np.asarray(pbr.render(pbr.load_dict(box(em=dl)), spp=16, seed=3))
    b = np.asarray(pbr.render(pbr.load_dict(box(em=pb)), spp=16, seed=3))
    assert np.allclose(a, b, rtol=1e-5, atol=1e-7)
    scene = pbr.load_dict(box(em=point()))
    params = pbr.traverse(scene)
    assert "em.intensity.value" in params
    img1 = np.asarray(pbr.render(scene, spp=16, seed=4))
    p0 = scene.lights.families["point"].power(0, scene)
    params["em.intensity.value"] = mi.Color3f(6.0, 5.0, 4.0)
    params.update()
    img2 = np.asarray(pbr.render(scene, spp=16, seed=4))
    assert np.allclose(img2, 2 * img1, rtol=1e-4, atol=1e-6)
    assert scene.lights.families["point"].power(0, scene) == pytest.approx(2 * p0)
