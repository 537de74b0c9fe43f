"""Films: pbrt-v4's ``rgb`` (pixel sensor: imaging ratio, white balance, component
clamp, crop window), ``spectral`` and ``gbuffer``, Mitsuba's ``specfilm`` (against
Mitsuba and analytic integrals)."""

import math

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import validate
from pbr.films import _daylight_xy, white_balance
from pbr.plugins.props import SceneError


def _env_scene(film, radiance=None, sensor=None):
    """A camera seeing only a constant environment of spectrum ``radiance`` (a tiny far
    sphere makes it a scene)."""
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 1},
            "cam": {"type": "perspective", "fov": 40.0, "film": film, **(sensor or {})},
            "s": {"type": "sphere", "center": [0, 0, -50], "radius": 0.1},
            "env": {"type": "constant", "radiance": radiance or {"type": "spectrum",
                                                                 "value": [(360, 1.0), (830, 3.0)]}}}


def _ramp(lam):
    return 1.0 + 2.0 * (lam - 360.0) / 470.0


def test_rgb_film_is_hdrfilm_with_pbrts_sensor():
    d = pbr.cornell_box(16, 16)
    base = np.asarray(pbr.render(pbr.load_dict(d), spp=16, seed=3))
    def with_film(film, **cam):
        dd = pbr.cornell_box(16, 16)
        dd["sensor"]["film"] = {"type": "rgb", "xresolution": 16, "yresolution": 16, **film}
        dd["sensor"].update(cam)
        return np.asarray(pbr.render(pbr.load_dict(dd), spp=16, seed=3))
    assert np.array_equal(with_film({}), base)             # imaging ratio 1: the same image
    assert np.allclose(with_film({"iso": 400}, shutterclose=0.5), 2.0 * base, rtol=1e-5)
    crop = with_film({"cropwindow": [0.25, 0.75, 0.5, 1.0]})
    d["sensor"]["film"].update(crop_offset_x=4, crop_offset_y=8, crop_width=8, crop_height=8)
    assert np.array_equal(crop, np.asarray(pbr.render(pbr.load_dict(d), spp=16, seed=3)))   # Mitsuba's crop
    pix = with_film({"pixelbounds": [4, 12, 8, 16]})
    assert np.array_equal(pix, crop)
    # pbrt-v4 clamps each sample's sensor values (here XYZ times the imaging ratio 2), so
    # every pixel's XYZ is at most 0.3 / 2 (an sRGB clamp would leave white pixels' Z above).
    clamp = with_film({"maxcomponentvalue": 0.3, "iso": 200})
    from pbr import spectrum as spec
    xyz = clamp @ spec.SRGB_TO_XYZ.T
    assert xyz.max() <= 0.3 * (1 + 1e-5) and xyz.max() > 0.29 and clamp.mean() < 2 * base.mean()
    with pytest.raises(SceneError, match="film.sensor: expected one of 'cie1931', 'canon_eos_100d'"):
        with_film({"sensor": "leica_m"})
    with pytest.raises(SceneError, match="film.cropwindow: the rendered part of the image is empty"):
        with_film({"cropwindow": [0.5, 0.5, 0, 1]})


def test_white_balance_is_von_kries():
    """The white-balance matrix maps the source white to the destination white (Y kept)
    and is the identity for D65 daylight (6504 K) onto sRGB's white; balancing for a warm
    4000 K daylight makes that daylight's white neutral in sRGB."""
    d65 = (0.3127, 0.3290)
    assert np.allclose(white_balance(d65, d65), np.eye(3), atol=1e-12)
    x, y = _daylight_xy(6504.0)
    assert (x, y) == pytest.approx(d65, abs=2e-3)
    src = _daylight_xy(4000.0)
    m = white_balance(src, d65)
    xyz = np.array([src[0] / src[1], 1.0, (1 - src[0] - src[1]) / src[1]])
    out = m @ xyz
    assert out / out[1] == pytest.approx([d65[0] / d65[1], 1.0, (1 - sum(d65)) / d65[1]], rel=1e-6)
    from pbr import spectrum as spec
    rgb = spec.xyz_to_srgb(out)
    assert rgb == pytest.approx([rgb[1]] * 3, rel=2e-3)


def test_spectral_film_buckets_average_radiance():
    """Radiance rising linearly from 1 (360 nm) to 3 (830 nm): each bucket holds its
    mean over the bucket; the RGB channels are the rgb film's."""
    film = {"type": "spectral", "xresolution": 4, "yresolution": 4, "nbuckets": 5, "lambdamin": 400,
            "lambdamax": 700}
    img = np.asarray(pbr.render(pbr.load_dict(_env_scene(film)), spp=4096, seed=1))
    assert img.shape == (4, 4, 8)
    edges = np.linspace(400, 700, 6)
    expect = _ramp(0.5 * (edges[1:] + edges[:-1]))
    assert img[..., 3:].reshape(-1, 5).mean(0) == pytest.approx(expect, rel=0.02)
    rgb = np.asarray(pbr.render(pbr.load_dict(_env_scene({"type": "rgb", "xresolution": 4, "yresolution": 4})),
                                spp=4096, seed=1))
    assert np.allclose(img[..., :3], rgb, rtol=1e-5)


def test_specfilm_matches_mitsuba_and_the_integral():
    """Mitsuba's convention: a channel is the integral of srf(lambda) L(lambda) d lambda."""
    film = {"type": "specfilm", "width": 4, "height": 4,
            "box": {"type": "spectrum", "value": [(600, 1.0), (700, 1.0)]},
            "ramp": {"type": "irregular", "wavelengths": "400, 800", "values": "0, 2"}}
    img = np.asarray(pbr.render(pbr.load_dict(_env_scene(film)), spp=4096, seed=2))
    assert img.shape == (4, 4, 2)
    g = np.linspace(600, 700, 10001)
    box = np.trapezoid(_ramp(g), g)
    g = np.linspace(400, 800, 10001)
    ramp = np.trapezoid(_ramp(g) * (g - 400) / 200, g)
    got = img.reshape(-1, 2).mean(0)
    assert got == pytest.approx([box, ramp], rel=0.02)
    validate.mitsuba_variant()
    ref = np.asarray(mi.render(mi.load_dict(_env_scene({**film, "ramp": {"type": "spectrum", "value": [
        (400, 0.0), (800, 2.0)]}})), spp=4096, seed=5)).reshape(-1, 2).mean(0)
    assert got == pytest.approx(ref, rel=0.02)
    with pytest.raises(SceneError, match="needs at least one sensor response function"):
        pbr.load_dict(_env_scene({"type": "specfilm", "width": 4, "height": 4}))
    with pytest.raises(SceneError, match="integrator: the 'sppm' integrator develops plain RGB images only"):
        pbr.load_dict({**_env_scene(film), "integrator": {"type": "sppm"}})


def test_gbuffer_sees_the_first_surface():
    """A plane facing the camera at distance 3: camera-space P.z = 3, N = (0, 0, -1) in
    camera space (world: +z), albedo the plane's (luminance), u and v in [0, 1]."""
    film = {"type": "gbuffer", "xresolution": 8, "yresolution": 8}
    d = {"type": "scene", "integrator": {"type": "direct"},
         "cam": {"type": "perspective", "fov": 30.0, "film": film,
                 "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0])},
         "plane": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.4}}},
         "env": {"type": "constant"}}
    scene = pbr.load_dict(d)
    img = np.asarray(pbr.render(scene, spp=16, seed=0))
    names = scene.sensors[0].film.channel_names()
    assert img.shape == (8, 8, len(names)) and names[3:6] == ["Albedo.R", "Albedo.G", "Albedo.B"]
    ch = {n: img[2:6, 2:6, i] for i, n in enumerate(names)}
    assert np.allclose(ch["P.Z"], 3.0, atol=1e-3)
    assert np.allclose(ch["N.Z"], -1.0, atol=1e-4) and np.allclose(ch["Ns.Z"], -1.0, atol=1e-4)
    lum = 0.2126 * ch["Albedo.R"] + 0.7152 * ch["Albedo.G"] + 0.0722 * ch["Albedo.B"]
    assert np.allclose(lum, 0.4, atol=0.01)        # a flat 0.4 reflectance: Y = 0.4
    assert 0 < ch["u"].min() and ch["u"].max() < 1
    world = np.asarray(pbr.render(pbr.load_dict({**d, "cam": {**d["cam"], "film": {
        **film, "coordinatesystem": "world"}}}), spp=16, seed=0))
    assert np.allclose(world[2:6, 2:6, names.index("N.Z")], 1.0, atol=1e-4)
    assert np.allclose(world[2:6, 2:6, names.index("P.Z")], 0.0, atol=1e-4)
