"""pbrt-v4's cameras and camera features, checked against analytic answers: the
``spherical`` camera's pixels integrate radiance over their solid angles (a sphere light
of known solid angle), a thin lens (``perspective`` with ``lensradius``) blurs a point
into its circle of confusion, and a moving camera (``to_world_end``) smears a point
along its path (motion blur)."""

import math

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr.cameras import SENSORS
from pbr.plugins.props import Props, SceneError


def _sensor(d):
    return SENSORS[d["type"]](Props(d, "scene.sensor"))


def _lit_spheres(sensor, spheres, radiance=1.0):
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 1}, "cam": sensor}
    for i, (c, r) in enumerate(spheres):
        d[f"s{i}"] = {"type": "sphere", "center": c, "radius": r,
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": radiance}}}
    return d


def _pixel_solid_angles(mapping, w, h):
    if mapping == "equalarea":
        return np.full((h, w), 4.0 * math.pi / (w * h))
    th = np.linspace(0.0, math.pi, h + 1)
    return np.repeat(((2.0 * math.pi / w) * (np.cos(th[:-1]) - np.cos(th[1:])))[:, None], w, axis=1)


@pytest.mark.parametrize("mapping, size", [("equalarea", (48, 48)), ("equirectangular", (64, 32))])
@pytest.mark.parametrize("where", ["ahead", "near the pole", "on the seam"])
def test_spherical_pixels_integrate_solid_angle(mapping, size, where):
    """sum over pixels of L_pixel * (pixel solid angle) = L * 2 pi (1 - cos alpha) for a
    sphere light of angular radius alpha, wherever it is: the mapping's pixel solid
    angles (4 pi / N for equal-area; (2 pi / W)(cos theta0 - cos theta1) for
    equirectangular) are right and no direction is seen twice or missed.
    Equirectangular pixels average over their (u, v) rectangle, not over solid angle, so
    near the poles the sum is compared with the same sum over a fine (u, v) grid of the
    mapping evaluated here (NumPy); equal-area pixels are exact."""
    w, h = size
    centre = {"ahead": [0.0, 0.0, 2.0], "near the pole": [0.3, 1.9, 0.4], "on the seam": [-2.0, 0.1, 0.05]}[where]
    cam = {"type": "spherical", "mapping": mapping,
           "to_world": mi.ScalarTransform4f().look_at([0, 0, 0], [0, 0, 1], [0, 1, 0]),
           "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}}}
    r = 0.5
    img = np.asarray(pbr.render(pbr.load_dict(_lit_spheres(cam, [(centre, r)])), spp=512, seed=1), np.float64)
    got = float((img.mean(axis=2) * _pixel_solid_angles(mapping, w, h)).sum())
    cos_alpha = math.sqrt(1.0 - (r / np.linalg.norm(centre)) ** 2)
    expect = 2.0 * math.pi * (1.0 - cos_alpha)
    if mapping == "equirectangular":
        k = 32                                          # sub-samples per pixel and axis
        u, v = np.meshgrid((np.arange(w * k) + 0.5) / (w * k), (np.arange(h * k) + 0.5) / (h * k))
        t, p = math.pi * v, 2 * math.pi * u
        dirs = np.stack([-np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], axis=-1)
        inside = (dirs @ (np.asarray(centre) / np.linalg.norm(centre)) > cos_alpha).astype(np.float64)
        frac = inside.reshape(h, k, w, k).mean(axis=(1, 3))
        approx = float((frac * _pixel_solid_angles(mapping, w, h)).sum())
        assert approx == pytest.approx(expect, rel=0.02 if where == "near the pole" else 0.005)
        expect = approx
    assert got == pytest.approx(expect, rel=0.01)


def test_spherical_directions_follow_pbrt():
    """Equirectangular: film (u, v) sees pbrt-v4's direction (sin t cos p, cos t, sin t sin p)
    (y and z swapped) with t = pi v, p = 2 pi u, and x negated into pbr's camera space
    (image x toward -x, as the other cameras); equal-area: unit directions, the film's
    centre looks along pbrt-v4's +y (pbr's +z)... i.e. straight ahead."""
    cam = _sensor({"type": "spherical", "mapping": "equirectangular",
                   "film": {"type": "hdrfilm", "width": 8, "height": 4}})
    u, v = np.array([0.25, 0.5, 0.1, 0.7]), np.array([0.5, 0.5, 0.2, 0.9])
    d = np.array(cam.sample_ray(mi.Point2f(u, v)).d)
    t, p = math.pi * v, 2 * math.pi * u
    assert np.allclose(d, [-np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], atol=1e-6)
    ea = _sensor({"type": "spherical", "film": {"type": "hdrfilm", "width": 8, "height": 8}})
    rng = np.random.default_rng(0)
    q = rng.random((2, 1000))
    d = np.array(ea.sample_ray(mi.Point2f(*q)).d)
    assert np.allclose(np.linalg.norm(d, axis=0), 1.0, atol=1e-6)
    assert np.allclose(np.array(ea.sample_ray(mi.Point2f([0.5], [0.5])).d).ravel(), [0, 1, 0], atol=1e-6)
    # Equal area: the four quadrants of the square each see a quarter of the sphere's
    # directions with z > 0 or < 0 in equal shares.
    assert abs(np.mean(d[2] > 0) - 0.5) < 0.05


def test_thin_lens_circle_of_confusion():
    """A small light at depth z out of focus (focus distance f, lens radius R) images to a
    uniform disk of radius R |1 - f / z| / f on the plane z = 1: the image's second moment
    about its centroid is r^2 / 2 (plus the light's own image and the box filter's 1/12
    per axis), in pixels."""
    w, lens, focus, z, rho, fov = 96, 0.3, 2.0, 4.0, 0.01, 30.0
    d = _lit_spheres({"type": "perspective", "fov": fov, "lensradius": lens, "focaldistance": focus,
                      "to_world": mi.ScalarTransform4f().look_at([0, 0, 0], [0, 0, 1], [0, 1, 0]),
                      "film": {"type": "hdrfilm", "width": w, "height": w, "rfilter": {"type": "box"}}},
                     [([0.0, 0.0, z], rho)])
    img = np.asarray(pbr.render(pbr.load_dict(d), spp=1024, seed=0), np.float64).mean(axis=2)
    y, x = np.mgrid[0:w, 0:w] + 0.5
    m0 = img.sum()
    cx, cy = (img * x).sum() / m0, (img * y).sum() / m0
    m2 = (img * ((x - cx) ** 2 + (y - cy) ** 2)).sum() / m0
    px = w / (2 * math.tan(math.radians(fov) / 2))
    r_coc, r_light = lens * abs(1 - focus / z) / focus * px, rho / z * px
    assert r_coc > 13
    assert (cx, cy) == pytest.approx((w / 2, w / 2), abs=0.5)
    assert m2 == pytest.approx(r_coc ** 2 / 2 + r_light ** 2 / 2 + 2 / 12, rel=0.03)


def test_perspective_lensradius_is_mitsubas_thin_lens():
    """pbrt-v4's ``lensradius``/``focaldistance`` on ``perspective`` give the rays of
    Mitsuba's ``thinlens`` with ``aperture_radius``/``focus_distance``."""
    look = mi.ScalarTransform4f().look_at([1, 2, -4], [0, 0.5, 0], [0, 1, 0])
    film = {"type": "hdrfilm", "width": 40, "height": 30}
    ref_d = {"type": "thinlens", "fov": 35.0, "to_world": look, "aperture_radius": 0.2, "focus_distance": 3.0,
             "film": film}
    rng = np.random.default_rng(3)
    pos, ap = rng.random((2, 2, 64))
    ref, _ = mi.load_dict(ref_d).sample_ray(0.0, 0.5, mi.Point2f(*pos), mi.Point2f(*ap))
    cam = _sensor({"type": "perspective", "fov": 35.0, "to_world": look, "lensradius": 0.2, "focaldistance": 3.0,
                   "film": film})
    assert cam.needs_aperture_sample and not cam.pinhole
    ours = cam.sample_ray(mi.Point2f(*pos), mi.Point2f(*ap))
    assert np.allclose(np.array(ours.o), np.array(ref.o), atol=2e-5)
    assert np.allclose(np.array(ours.d), np.array(ref.d), atol=2e-6)
    # Light tracing connects to the lens (tests/test_lens_light_tracing.py), not to a moving camera.
    pbr.load_dict({"type": "scene", "integrator": {"type": "ptracer"}, "l": {"type": "constant"},
                   "s": {"type": "sphere"}, "cam": {"type": "perspective", "lensradius": 0.1, "film": film}})
    with pytest.raises(SceneError, match=r"the 'ptracer' integrator .* a moving 'perspective' camera"):
        pbr.load_dict({"type": "scene", "integrator": {"type": "ptracer"}, "l": {"type": "constant"},
                       "s": {"type": "sphere"}, "cam": {"type": "perspective", "lensradius": 0.1, "film": film,
                                                        "to_world_end": mi.ScalarTransform4f().translate([0.1, 0, 0])}})


def test_camera_motion_blur_smears_along_the_path():
    """A camera translating by dx during the shutter [0, 1] (``to_world_end``) images a
    small light as a streak: its pixels' x spread uniformly over the projected shift
    (variance shift^2 / 12, plus the light's own disk r^2 / 4 and the box filter's 1/12),
    y unchanged; rays carry their time. A shutter [0, 0.5]
    halves the streak; a camera whose end transform equals its start is static."""
    w, fov, z, rho = 64, 40.0, 5.0, 0.1
    def render(shutter_close, dx):
        cam = {"type": "perspective", "fov": fov, "shutteropen": 0.0, "shutterclose": shutter_close,
               "to_world": mi.ScalarTransform4f().look_at([0, 0, 0], [0, 0, 1], [0, 1, 0]),
               "to_world_end": mi.ScalarTransform4f().look_at([dx, 0, 0], [dx, 0, 1], [0, 1, 0]),
               "film": {"type": "hdrfilm", "width": w, "height": w, "rfilter": {"type": "box"}}}
        img = np.asarray(pbr.render(pbr.load_dict(_lit_spheres(cam, [([0, 0, z], rho)])), spp=4096, seed=2),
                         np.float64).mean(axis=2)
        y, x = np.mgrid[0:w, 0:w] + 0.5
        m0 = img.sum()
        cx, cy = (img * x).sum() / m0, (img * y).sum() / m0
        return cx, cy, (img * (x - cx) ** 2).sum() / m0, (img * (y - cy) ** 2).sum() / m0
    px = w / (2 * math.tan(math.radians(fov) / 2))
    dx = 1.5
    shift = dx / z * px                       # pixels the light moves across the image
    cx, cy, vx, vy = render(1.0, dx)
    assert 20 < shift < w / 2 - 4
    # The camera moves toward +x (its left, looking down +z): the light drifts to the right.
    assert cx == pytest.approx(w / 2 + shift / 2, abs=0.5) and cy == pytest.approx(w / 2, abs=0.3)
    own = (rho / z * px) ** 2 / 4 + 1 / 12
    assert vx == pytest.approx(shift ** 2 / 12 + own, rel=0.03)
    assert vy == pytest.approx(own, rel=0.1)
    _, _, vx_half, _ = render(0.5, dx)
    assert vx_half == pytest.approx((shift / 2) ** 2 / 12 + own, rel=0.03)
    static = _sensor({"type": "perspective", "to_world_end": np.eye(4), "film": {"type": "hdrfilm"}})
    assert static.motion is None
    cam = _sensor({"type": "perspective", "shutter_open": 0.2, "shutter_close": 0.6, "film": {"type": "hdrfilm"},
                   "to_world_end": mi.ScalarTransform4f().translate([1, 0, 0])})
    t = cam.sample_time(mi.Float([0.0, 0.5, 1.0]))
    assert np.allclose(np.array(cam.sample_ray(mi.Point2f([0.5] * 3, [0.5] * 3), None, t).time), [0.2, 0.4, 0.6])
    with pytest.raises(SceneError, match="scene.sensor.shutterclose: the shutter closes"):
        _sensor({"type": "perspective", "shutteropen": 1.0, "shutterclose": 0.5, "film": {"type": "hdrfilm"}})
    with pytest.raises(SceneError, match="scene.sensor.transform_times"):
        _sensor({"type": "perspective", "transform_times": [1.0, 1.0], "film": {"type": "hdrfilm"}})


def test_rotating_camera_interpolates_by_slerp():
    """Half-way through a 90 degree turn the camera looks at 45 degrees (slerp, not a
    linear blend of matrices, which would shrink the frame)."""
    look = lambda t: mi.ScalarTransform4f().look_at([0, 0, 0], t, [0, 1, 0])  # noqa: E731
    cam = _sensor({"type": "perspective", "fov": 10.0, "to_world": look([0, 0, 1]), "to_world_end": look([1, 0, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8}})
    ray = cam.sample_ray(mi.Point2f([0.5], [0.5]), None, mi.Float([0.5]))
    assert np.allclose(np.array(ray.d).ravel(), [math.sqrt(0.5), 0, math.sqrt(0.5)], atol=1e-5)


SINGLET = "# a biconvex singlet (R 50 mm, 5 mm thick, n 1.5), the stop 2 mm behind it\n50 5 1.5 20\n-50 2 1 20\n0 45 0 10\n"


def _realistic(tmp_path, film, **kw):
    lens = tmp_path / "singlet.dat"
    lens.write_text(SINGLET)
    return {"type": "realistic", "lensfile": str(lens), "aperturediameter": 10.0,
            "to_world": mi.ScalarTransform4f().look_at([0, 0, 0], [0, 0, 1], [0, 1, 0]), "film": film, **kw}


def test_realistic_camera_focal_length_and_image_position(tmp_path):
    """The singlet's focal length is the thick-lens formula's, 1/f = (n-1)(1/R1 - 1/R2 +
    (n-1) d / (n R1 R2)) = 1 / 50.85 mm; a distant light 8 degrees to the camera's left
    (+x) images left of the centre at f tan(theta) on the film (within 3%: the lens's
    distortion)."""
    w, h, dist, th = 64, 48, 100.0, math.radians(8.0)
    d = _lit_spheres(_realistic(tmp_path, {"type": "rgb", "xresolution": w, "yresolution": h,
                                           "rfilter": {"type": "box"}}, focusdistance=dist),
                     [([dist * math.sin(th), 0.0, dist * math.cos(th)], 0.5)])
    scene = pbr.load_dict(d)
    cam = scene.sensors[0]
    n, r1, r2, t = 1.5, 0.05, -0.05, 0.005
    f = 1.0 / ((n - 1) * (1 / r1 - 1 / r2 + (n - 1) * t / (n * r1 * r2)))
    assert cam.lens.focal_length == pytest.approx(f, rel=1e-4)
    img = np.asarray(pbr.render(scene, spp=256, seed=0), np.float64).mean(axis=2)
    y, x = np.mgrid[0:h, 0:w] + 0.5
    m0 = img.sum()
    cx, cy = (img * x).sum() / m0, (img * y).sum() / m0
    shift = f * math.tan(th) / cam.extent[0] * w
    assert w / 2 - cx == pytest.approx(shift, rel=0.03) and cy == pytest.approx(h / 2, abs=0.2)


def test_realistic_camera_irradiance_on_axis(tmp_path):
    """Under a uniform sky of radiance 1 (a flat spectrum: Y = 1), the centre pixel holds
    pbrt-v4's weighted estimate of the integral of cos^4 / z^2 over the exit pupil (the
    stop, radius a at distance z from the film): pi a^2 / (z^2 + a^2)."""
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 1},
         "cam": _realistic(tmp_path, {"type": "hdrfilm", "width": 9, "height": 9, "rfilter": {"type": "box"}},
                           focusdistance=5.0),
         "s": {"type": "sphere", "center": [0, 0, -50], "radius": 0.1},
         "sky": {"type": "constant", "radiance": {"type": "spectrum", "value": 1.0}}}
    scene = pbr.load_dict(d)
    img = np.asarray(pbr.render(scene, spp=16384, seed=1), np.float64)
    y = 0.2126 * img[4, 4, 0] + 0.7152 * img[4, 4, 1] + 0.0722 * img[4, 4, 2]
    a, z = 0.005, scene.sensors[0].lens.rear_z
    assert y == pytest.approx(math.pi * a * a / (z * z + a * a), rel=0.025)   # ~0.7% noise
    # at the film's centre exactly, the weights' mean is the integral (1M lens samples)
    u = np.random.default_rng(0).random((2, 1 << 20))
    _, wt = scene.sensors[0].sample_ray_weighted(mi.Point2f(0.5, 0.5), mi.Point2f(*u))
    assert float(np.mean(np.array(wt))) == pytest.approx(math.pi * a * a / (z * z + a * a), rel=2e-3)
    assert img[0, 0].mean() < img[4, 4].mean()              # vignetting and cos^4 toward the corners
    with pytest.raises(SceneError, match="scene.cam.focusdistance: the focus distance .* too short"):
        pbr.load_dict({**d, "cam": _realistic(tmp_path, {"type": "hdrfilm"}, focusdistance=0.01)})
    with pytest.raises(SceneError, match="scene.cam.lensfile: file not found"):
        pbr.load_dict({**d, "cam": {**d["cam"], "lensfile": str(tmp_path / "missing.dat")}})
    bad = tmp_path / "bad.dat"
    bad.write_text("50 5 1.5\n")
    with pytest.raises(SceneError, match="scene.cam.lensfile: cannot read lens file .* rows of 4 numbers"):
        pbr.load_dict({**d, "cam": {**d["cam"], "lensfile": str(bad)}})
    with pytest.raises(SceneError, match="the 'ptracer' integrator"):
        pbr.load_dict({**d, "integrator": {"type": "ptracer"}})


XML = """<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="spherical">
        <string name="mapping" value="equirectangular"/>
        <film type="specfilm">
            <integer name="width" value="16"/><integer name="height" value="8"/>
            <spectrum name="band" value="500:1, 600:1"/>
            <rfilter type="mitchell"><float name="B" value="0.5"/></rfilter>
        </film>
    </sensor>
    <shape type="sphere">
        <bsdf type="diffuse">
            <texture name="reflectance" type="imagemap">
                <string name="filter" value="ewa"/><string name="filename" value="tex.png"/>
            </texture>
        </bsdf>
        <transform name="to_world"><translate value="0 0 3"/></transform>
    </shape>
    <shape type="rectangle">
        <bsdf type="diffuse">
            <texture name="reflectance" type="wrinkled"><integer name="octaves" value="4"/></texture>
        </bsdf>
        <transform name="to_world"><translate value="0 -1 0"/><rotate x="1" angle="-90"/></transform>
    </shape>
    <emitter type="constant"/>
</scene>
"""


def test_xml_scene_with_the_new_plugins(tmp_path):
    """Mitsuba XML reaches the new plugins: a spherical camera with a specfilm and a
    Mitchell filter looking at an EWA imagemap and a wrinkled texture (the spherical
    camera's footprint: its ray origins are one point)."""
    pbr.write_image(str(tmp_path / "tex.png"), np.random.default_rng(0).random((32, 32, 3)).astype(np.float32))
    (tmp_path / "scene.xml").write_text(XML)
    scene = pbr.load_file(str(tmp_path / "scene.xml"))
    img = np.asarray(pbr.render(scene, spp=16))
    assert img.shape == (8, 16, 1) and np.isfinite(img).all() and img.mean() > 0
    assert scene.sensors[0].film.channel_names() == ["band"]
