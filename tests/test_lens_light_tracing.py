"""Light tracing through a thin lens: ``ptracer``/``lightpath``, ``bdpt`` and ``mlt`` with a
``thinlens`` camera (or ``perspective`` with pbrt-v4's ``lensradius``) connect light
vertices to points of the lens (pbrt-v4's ``PerspectiveCamera::SampleWi``).

* The camera: ``sample_Wi`` through a lens sample inverts ``sample_ray`` with that
  aperture sample and agrees with ``We``/``pdf_We`` and ``lens_point``; it equals
  Mitsuba's ``thinlens`` ``sample_direction`` (lens point, solid-angle pdf, weight
  We / pdf, film position); the importance integrates to 1 over the lens and the film.
* Images: a depth-of-field scene (a sphere in focus, a nearer one out of focus, a floor
  crossing the focus plane, an area light) rendered by ``ptracer``, ``bdpt`` and ``mlt``
  matches ``path`` with the same camera (pbr.validate, per pixel; MLT per 2 x 2 block over
  independent runs), and ``ptracer`` matches Mitsuba's ``ptracer`` with its ``thinlens``.
* Must fail: light vertices splatted where a pinhole would see them (the focus plane
  ignored) are detected by the same comparison.
"""

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr import validate
from pbr.plugins.props import SceneError

RES, SPP, BATCHES = 24, 1024, 16


def T():
    return mi.ScalarTransform4f()


def dof_scene(integrator, res=RES, camera="thinlens", **kw):
    """Depth of field: the blue sphere lies in the plane in focus (4.1 from the lens), the
    red one 2 nearer (blurred), the floor crosses the focus plane; a box filter."""
    lens = {"aperture_radius": 0.25, "focus_distance": 4.1} if camera == "thinlens" else \
        {"lensradius": 0.25, "focaldistance": 4.1}
    return {
        "type": "scene",
        "integrator": {"type": integrator, **kw},
        "sensor": {"type": camera, "fov": 40.0, **lens,
                   "to_world": T().look_at([0, 1.0, 4.0], [0, 0.5, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": res, "height": res * 3 // 4, "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.5]}}},
        "near": {"type": "sphere", "center": [0.8, 0.4, 2.2], "radius": 0.4,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.2, 0.2]}}},
        "focus": {"type": "sphere", "center": [-0.6, 0.5, 0.0], "radius": 0.5,
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.3, 0.7]}}},
        "light": {"type": "rectangle", "to_world": T().translate([0, 3.0, 0.5]).rotate([1, 0, 0], 90).scale(0.7),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 6.0, 5.0]}}},
    }


def pbr_fn(d):
    scene = pbr.load_dict(d)
    return lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp, progress=False))


def compare(fa, fb, spp=SPP):
    res = validate.compare_renders(fa, fb, spp=spp, batches=BATCHES, seed_a=41, seed_b=42)
    print(res.summary())
    return res


# --------------------------------------------------------------------------- camera

def _camera(**kw):
    d = dof_scene("path", res=40)
    d["sensor"].update(kw)
    return pbr.load_dict(d).sensors[0]


@pytest.mark.parametrize("camera", ["thinlens", "perspective"])
def test_sample_Wi_inverts_lens_rays(camera):
    d = dof_scene("path", res=40, camera=camera)
    cam = pbr.load_dict(d).sensors[0]
    assert cam.connectable and not cam.pinhole
    rng = np.random.default_rng(1)
    n = 1000
    pos = mi.Point2f(*rng.random((2, n)).astype(np.float32))
    ap = mi.Point2f(*rng.random((2, n)).astype(np.float32))
    ray = cam.sample_ray(pos, ap)
    lens_p = cam.lens_point(ray)
    m = cam.to_world
    # The lens point lies on the aperture disk (camera z = 0, radius <= 0.25).
    q = np.array(lens_p) - m[:3, 3:]
    assert np.abs(m[:3, 2] @ q).max() < 1e-5 and np.linalg.norm(q, axis=0).max() <= 0.25 + 1e-5
    t = mi.Float(rng.uniform(0.5, 6.0, n).astype(np.float32))
    target = ray.o + ray.d * t
    cs = cam.sample_Wi(target, ap)
    assert np.all(np.array(cs.valid))
    np.testing.assert_allclose(np.array(cs.p), np.array(lens_p), atol=2e-5)
    np.testing.assert_allclose(np.array(cs.pos), np.array(pos), atol=5e-5)
    np.testing.assert_allclose(np.array(-cs.wi), np.array(ray.d), atol=2e-5)
    We, wpos = cam.We(ray)
    np.testing.assert_allclose(np.array(We), np.array(cs.We), rtol=1e-4)
    np.testing.assert_allclose(np.array(wpos), np.array(pos), atol=5e-5)
    area = math.pi * 0.25 ** 2
    pdf_pos, pdf_dir = cam.pdf_We(ray)
    cos = np.array(dr.dot(ray.d, mi.Vector3f(*m[:3, 2].tolist())))
    np.testing.assert_allclose(np.array(pdf_pos), 1.0 / area, rtol=1e-6)
    # pdf_dir = We cos lens_area: the density of sample_ray's directions from a lens point.
    np.testing.assert_allclose(np.array(pdf_dir), np.array(We) * cos * area, rtol=1e-4)
    dist = np.array(dr.norm(target - lens_p))
    np.testing.assert_allclose(np.array(cs.pdf), dist ** 2 / (cos * area), rtol=1e-3)
    # Behind the lens: invalid.
    assert not np.any(np.array(cam.sample_Wi(mi.Point3f(*(2 * m[:3, 3] - m[:3, 2]).tolist()), ap).valid))


def test_sample_Wi_equals_mitsuba_thinlens():
    """Mitsuba 3's ``thinlens`` ``sample_direction``: the same lens point, solid-angle pdf,
    weight (We / pdf) and film position (Mitsuba's in pixels)."""
    d = dof_scene("path", res=40)
    cam = pbr.load_dict(d).sensors[0]
    ms = mi.load_dict(d["sensor"])
    rng = np.random.default_rng(2)
    n = 4096
    p = mi.Point3f(*(rng.random((3, n)) * [[3.0], [1.5], [4.0]] - [[1.5], [0.0], [2.5]]).astype(np.float32))
    u = mi.Point2f(*rng.random((2, n)).astype(np.float32))
    it = dr.zeros(mi.Interaction3f, n)
    it.p = p
    ds, w = ms.sample_direction(it, u)
    cs = cam.sample_Wi(p, u)
    valid = np.array(cs.valid)
    w0 = np.array(w)[0]
    assert 0.3 < valid.mean() < 0.95
    np.testing.assert_array_equal(valid, w0 > 0)
    np.testing.assert_allclose(np.array(cs.p), np.array(ds.p), atol=2e-5)
    np.testing.assert_allclose(np.array(cs.pdf)[valid], np.array(ds.pdf)[valid], rtol=1e-4)
    np.testing.assert_allclose(np.array(cs.We / cs.pdf)[valid], w0[valid], rtol=1e-4)
    np.testing.assert_allclose((np.array(cs.pos) * [[40], [30]])[:, valid], np.array(ds.uv)[:, valid], atol=2e-3)


def test_lens_importance_integrates_to_one():
    """int int We cos d omega dA over the lens disk and all directions = 1."""
    cam = _camera()
    n = 1 << 20
    rng = mi.PCG32(n)
    m = cam.to_world
    disk = mi.warp.square_to_uniform_disk_concentric(mi.Point2f(rng.next_float32(), rng.next_float32())) * 0.25
    o = mi.Point3f(*[m[r, 3] + m[r, 0] * disk.x + m[r, 1] * disk.y for r in range(3)])
    d = mi.warp.square_to_uniform_sphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    We, _ = cam.We(mi.Ray3f(o, d))
    cos = dr.dot(d, mi.Vector3f(*m[:3, 2].tolist()))
    v = np.array(We * cos * 4 * math.pi * (math.pi * 0.25 ** 2), dtype=np.float64)
    assert abs(v.mean() - 1) < 4 * v.std() / math.sqrt(n)


# --------------------------------------------------------------------------- images

def test_ptracer_matches_path():
    res = compare(pbr_fn(dof_scene("ptracer", max_depth=3)), pbr_fn(dof_scene("path", max_depth=3)))
    assert res, res


def test_lightpath_perspective_lensradius_matches_path():
    """pbrt-v4's names: ``lightpath`` with ``perspective`` and ``lensradius``."""
    res = compare(pbr_fn(dof_scene("lightpath", camera="perspective", max_depth=3)),
                  pbr_fn(dof_scene("path", camera="perspective", max_depth=3)))
    assert res, res


def test_ptracer_matches_mitsuba_thinlens():
    d = dof_scene("ptracer", max_depth=3)
    res = compare(pbr_fn(d), validate.mitsuba_render_fn(d))
    assert res, res


def test_bdpt_matches_path():
    res = compare(pbr_fn(dof_scene("bdpt", max_depth=3)), pbr_fn(dof_scene("path", max_depth=3)), spp=512)
    assert res, res


def _blocks(img, b=2):
    h, w, c = img.shape
    return img.reshape(h // b, b, w // b, b, c).mean(axis=(1, 3))


def test_mlt_matches_path():
    """MLT's variance across 16 independent runs (its pixels are correlated: see
    tests/test_mlt.py), 2 x 2 blocks, Welch's t-test."""
    fa = pbr_fn(dof_scene("mlt", res=16, max_depth=3, bootstrapsamples=8192, chains=64))
    fb = pbr_fn(dof_scene("path", res=16, max_depth=3))
    ea = validate.estimate(lambda seed, spp: _blocks(fa(seed=seed, spp=spp)), 64 * 16, batches=16, seed=1)
    eb = validate.estimate(lambda seed, spp: _blocks(fb(seed=seed, spp=spp)), 2048, batches=16, seed=2)
    res = validate.compare(ea.mean, ea.var, eb.mean, eb.var, image_mean_var_a=ea.image_mean_var,
                           image_mean_var_b=eb.image_mean_var,
                           dof=validate.welch_dof(ea.var, ea.batches, eb.var, eb.batches))
    print(res.summary())
    assert res.passed, res.summary()


def test_focus_plane_ignored_fails(monkeypatch):
    """Must fail: splatting light vertices where a pinhole at the lens centre would see
    them (no blur of the near sphere: the image is too sharp)."""
    from pbr.cameras import PerspectiveCamera

    def pinhole_film(self, o_local, d_local):
        pos, inside = self.film_position(d_local)
        return pos, inside
    monkeypatch.setattr(PerspectiveCamera, "_lens_film", pinhole_film)
    res = compare(pbr_fn(dof_scene("ptracer", max_depth=3)), pbr_fn(dof_scene("path", max_depth=3)))
    assert not res, res


def test_moving_lens_camera_is_refused():
    d = dof_scene("bdpt", max_depth=3)
    d["sensor"]["to_world_end"] = T().look_at([0.2, 1.0, 4.0], [0, 0.5, 0], [0, 1, 0])
    with pytest.raises(SceneError, match=r"the 'bdpt' integrator connects paths to the camera.*moving 'thinlens'"):
        pbr.load_dict(d)


# ------------------------------------------------------------- pbrt-v4's rgb film sensor

def _sensor_scene(name, clamp=1e4):
    d = dof_scene(name, max_depth=3)
    d["sensor"]["film"] = {"type": "rgb", "xresolution": RES, "yresolution": RES * 3 // 4, "iso": 250.0,
                           "maxcomponentvalue": clamp, "rfilter": {"type": "box"}}
    return d


@pytest.mark.parametrize("integrator", ["ptracer", "bdpt"])
def test_sensor_film_matches_path(integrator):
    """pbrt-v4's ``rgb`` film with ``iso`` 250 (imaging ratio 2.5; pavilion-night's film):
    the splats go through the sensor as the camera film's samples do."""
    res = compare(pbr_fn(_sensor_scene(integrator)), pbr_fn(_sensor_scene("path")),
                  spp=512 if integrator == "bdpt" else SPP)
    assert res, res


def test_sensor_film_clamps_each_splat():
    """``maxcomponentvalue`` clamps each splat's sensor RGB (pbrt-v4's ``AddSplat``): a
    clamp below the brightest splats darkens the light-traced image (a different estimator
    than the camera film's clamp of whole camera samples, so no comparison with path)."""
    free = pbr_fn(_sensor_scene("ptracer"))(seed=1, spp=64)
    clamped = pbr_fn(_sensor_scene("ptracer", clamp=0.5))(seed=1, spp=64)
    assert clamped.mean() < 0.9 * free.mean() and np.all(clamped <= free + 1e-6)


def test_films_with_extra_channels_are_refused():
    for name in ("ptracer", "bdpt"):
        d = dof_scene(name, max_depth=3)
        d["sensor"]["film"] = {"type": "gbuffer", "xresolution": 8, "yresolution": 6}
        with pytest.raises(SceneError, match=rf"the '{name}' integrator develops RGB images only; sensor 0's film "
                                             r"\('gbuffer'\) has extra channels"):
            pbr.load_dict(d)
