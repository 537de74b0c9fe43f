"""normalmap and bumpmap: perturbed shading frames, compared with Mitsuba."""

import numpy as np
import pytest

import pbr
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
    d = material_box({"type": "bumpmap", "h": {"type": "rgb", "value": [0.5, 0.5, 0.5]}, "b": {"type": "diffuse"}})
    with pytest.raises(pbr.SceneError, match="small-box.bsdf.h: bumpmap needs a bitmap"):
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
