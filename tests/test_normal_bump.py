"""normalmap and bumpmap: perturbed shading frames, compared with Mitsuba; bump maps of
any texture (forward differences, pbrt-v4's BumpMap) against the analytic tilt of a
linear height field and against the same texture baked to a bitmap."""

import math

import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr import backend
from mitsuba_scenes import material_box, compare_with_mitsuba


def _normal_map(path, n=32):
    """A tangent-space normal map of sinusoidal ripples, stored as 8-bit RGB."""
    y, x = np.mgrid[0:n, 0:n] / n
    nx = 0.5 * np.sin(4 * np.pi * x)
    ny = 0.3 * np.cos(6 * np.pi * y)
    nn = np.stack([nx, ny, np.ones_like(nx)], -1)
    nn /= np.linalg.norm(nn, axis=-1, keepdims=True)
    rgb = (nn * 0.5 + 0.5).astype(np.float32)
    # write_image sRGB-encodes: store the sRGB-decoded values so the file holds rgb exactly.
    from pbr.image import srgb_to_linear
    pbr.write_image(path, srgb_to_linear(rgb))
    return path


def _height_map(path, n=32):
    y, x = np.mgrid[0:n, 0:n] / n
    h = 0.5 + 0.5 * np.sin(6 * np.pi * x) * np.sin(4 * np.pi * y)
    from pbr.image import srgb_to_linear
    pbr.write_image(path, srgb_to_linear(np.repeat(h[..., None], 3, -1).astype(np.float32)))
    return path


def test_normalmap_matches_mitsuba(tmp_path, scale):
    nm = _normal_map(str(tmp_path / "n.png"))
    small = {"type": "normalmap", "normalmap": {"type": "bitmap", "raw": True, "filename": nm},
             "b": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.2]}}}
    large = {"type": "normalmap", "normalmap": {"type": "bitmap", "raw": True, "filename": nm},
             "b": {"type": "roughconductor", "alpha": 0.3}}
    res = compare_with_mitsuba(material_box(small, large, scale), scale)
    print(res.summary())
    assert res.passed, res.summary()


def test_bumpmap_matches_mitsuba(tmp_path, scale):
    hm = _height_map(str(tmp_path / "h.png"))
    small = {"type": "bumpmap", "height": {"type": "bitmap", "raw": True, "filename": hm}, "scale": 0.05,
             "b": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.6, 0.8]}}}
    res = compare_with_mitsuba(material_box(small, None, scale), scale)
    print(res.summary())
    assert res.passed, res.summary()


def test_flat_normal_map_changes_nothing(tmp_path):
    flat = np.zeros((4, 4, 3), np.float32) + np.array([0.5, 0.5, 1.0], np.float32)
    d1 = material_box({"type": "normalmap", "normalmap": {"type": "bitmap", "raw": True, "data": flat},
                       "b": {"type": "diffuse", "reflectance": 0.5}})
    d2 = material_box({"type": "diffuse", "reflectance": 0.5})
    a = np.asarray(pbr.render(pbr.load_dict(d1), spp=16, seed=3))
    b = np.asarray(pbr.render(pbr.load_dict(d2), spp=16, seed=3))
    assert np.allclose(a, b, atol=1e-4)


def test_errors_name_the_key():
    d = material_box({"type": "normalmap", "b": {"type": "diffuse"}})
    with pytest.raises(pbr.SceneError, match="small-box.bsdf.normalmap: missing"):
        pbr.load_dict(d)
    d = material_box({"type": "normalmap", "normalmap": {"type": "rgb", "value": [0.5, 0.5, 1.0]},
                      "b": {"type": "diffuse"}})
    with pytest.raises(pbr.SceneError, match="small-box.bsdf.normalmap: normalmap needs a bitmap"):
        pbr.load_dict(d)
    d = material_box({"type": "bumpmap", "h": {"type": "fbm"}, "g": {"type": "fbm"}, "b": {"type": "diffuse"}})
    with pytest.raises(pbr.SceneError, match="bumpmap takes exactly one nested .height. texture, got 2"):
        pbr.load_dict(d)


def test_wrong_maps_fail_the_comparison(tmp_path):
    """The comparisons can fail: the normal-mapped box against Mitsuba's box without the
    map (so the map's effect is measurable), and a bump map with twice the height."""
    from pbr import validate
    nm = _normal_map(str(tmp_path / "n.png"))
    mapped = {"type": "normalmap", "normalmap": {"type": "bitmap", "raw": True, "filename": nm},
              "b": {"type": "roughconductor", "alpha": 0.3}}
    scene = pbr.load_dict(material_box(mapped))
    res = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp)),
                                   validate.mitsuba_render_fn(material_box({"type": "roughconductor", "alpha": 0.3})),
                                   spp=1024, batches=16, seed_a=1, seed_b=2)
    assert not res.passed
    hm = _height_map(str(tmp_path / "h.png"))
    mk = lambda s: material_box({"type": "bumpmap", "height": {"type": "bitmap", "raw": True, "filename": hm},  # noqa: E731
                                 "scale": s, "b": {"type": "diffuse", "reflectance": 0.6}})
    scene = pbr.load_dict(mk(0.1))
    res = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp)),
                                   validate.mitsuba_render_fn(mk(0.05)), spp=1024, batches=16, seed_a=1, seed_b=2)
    assert not res.passed


# -- bump maps of any texture ------------------------------------------------------------------

def _normals_scene(bsdf, res=64, spp=64):
    """The shading normals (AOV) of a unit rectangle (uv in [0, 1]^2, p = (2u - 1, 2v - 1, 0))
    seen head-on."""
    return {"type": "scene", "integrator": {"type": "aov", "aovs": "nn:sh_normal"},
            "cam": {"type": "perspective", "fov": 40.0,
                    "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": spp}},
            "plane": {"type": "rectangle", "bsdf": bsdf}}


def _bump(height, scale=1.0):
    return {"type": "bumpmap", "h": height, "scale": scale, "b": {"type": "diffuse"}}


def _unit(n):
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


@pytest.mark.parametrize("a", [0.5, 2.0])
def test_linear_height_tilts_the_normal_analytically(a):
    """h(u, v) = a u (a ``bilerp``): dp/du' = dp/du + a n with |dp/du| = 2, so the normal
    tilts by atan(a du/dp) = atan(a / 2) toward -x, everywhere."""
    h = {"type": "bilerp", "v00": 0.0, "v10": a, "v01": 0.0, "v11": a}
    img = np.asarray(pbr.render(pbr.load_dict(_normals_scene(_bump(h), res=16, spp=4)), seed=1))[2:-2, 2:-2]
    n = _unit(img)
    tilt = np.degrees(np.arccos(np.clip(n[..., 2], -1, 1)))
    assert np.abs(tilt - math.degrees(math.atan(a / 2))).max() < 0.01
    assert (n[..., 0] < 0).all() and np.abs(n[..., 1]).max() < 1e-5
    # scale multiplies the gradient
    img = np.asarray(pbr.render(pbr.load_dict(_normals_scene(_bump(h, 0.5), res=16, spp=4)), seed=1))[2:-2, 2:-2]
    tilt = np.degrees(np.arccos(np.clip(_unit(img)[..., 2], -1, 1)))
    assert np.abs(tilt - math.degrees(math.atan(a / 4))).max() < 0.01


def test_procedural_bump_matches_its_baked_bitmap():
    """A 2-octave fbm height field, differenced (pbrt-v4's steps from the pixel footprint),
    against the same field baked into a 512^2 raw bitmap (Mitsuba's exact gradient of the
    bilinear interpolation): same normals to 0.3 degrees (mean 0.1) where the normals tilt
    by 7 degrees on average; the bitmap with 1.2 times the height differs by > 1 degree."""
    fbm = {"type": "fbm", "octaves": 2, "to_world": mi.ScalarTransform4f().scale(0.5)}
    scene = pbr.load_dict(_normals_scene(_bump(fbm, 0.05)))
    n = 512
    with backend.pbr_variant():
        T = scene.textures
        slot = next(i for i, t in enumerate(T.items) if t.path == "plane.bsdf.nested_texture")
        j, i = np.meshgrid(np.arange(n), np.arange(n))
        u, v = ((j + 0.5) / n).ravel(), ((i + 0.5) / n).ravel()     # texel centres, row 0 at v = 0
        si = mi.SurfaceInteraction3f()
        si.p, si.uv, si.n = mi.Point3f(2 * u - 1, 2 * v - 1, 0.0), mi.Point2f(u, v), mi.Normal3f(0, 0, 1)
        h = np.array(T.eval(slot, si, mi.Spectrum(550.0), True, illuminant=False)[0], np.float32).reshape(n, n, 1)
    proc = np.asarray(pbr.render(scene, seed=1))

    def baked(scale):
        s = pbr.load_dict(_normals_scene(_bump({"type": "bitmap", "raw": True, "data": h}, scale)))
        return np.asarray(pbr.render(s, seed=1))

    def angle(x, y):     # inside the border (the bitmap wraps around there)
        x, y = _unit(x[8:-8, 8:-8]), _unit(y[8:-8, 8:-8])
        return np.degrees(np.arccos(np.clip((x * y).sum(-1), -1, 1)))

    tilt = np.degrees(np.arccos(_unit(proc[8:-8, 8:-8])[..., 2]))
    assert tilt.mean() > 5
    d = angle(proc, baked(0.05))
    assert d.mean() < 0.15 and d.max() < 0.5, (d.mean(), d.max())
    d = angle(proc, baked(0.06))
    assert d.mean() > 1.0


def test_constant_height_changes_nothing():
    """A constant height field has no gradient: the plain BSDF's image, bit for bit."""
    a = np.asarray(pbr.render(pbr.load_dict(material_box(_bump({"type": "uniform", "value": 0.3}))), spp=16, seed=3))
    b = np.asarray(pbr.render(pbr.load_dict(material_box({"type": "diffuse"})), spp=16, seed=3))
    assert np.allclose(a, b, atol=1e-6)
