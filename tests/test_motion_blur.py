"""Moving shapes and instances (motion blur: ``to_world_end`` / ``transform_times`` on a
shape or an instance; pbrt-v4's ``ActiveTransform`` around a ``Shape`` or an
``ObjectInstance``), checked against values computed here without the renderer:

* a black sphere moving in a straight line across a constant sky, seen by an
  orthographic camera with a box filter: a pixel's value is the sky times the fraction
  of (shutter time x pixel area) its rays miss the sphere; per point of the pixel the
  blocked time is an interval in closed form (a quadratic in t), the pixel area is
  integrated on a fine grid;
* a black rectangle turning 120 degrees about the view axis (slerp: a constant angular
  velocity): the same fraction on a fine grid of times;
* a lit cube moving and turning above a floor under a point light: its shading and its
  shadow equal the time average of static renders of the cube at stratified times
  (pbr's static path, poses built here, not by pbr's interpolation);
* a pbrt-v4 file with ``ActiveTransform EndTime`` around the sphere of the first case.

Images are compared per pixel with :func:`pbr.validate.compare` (tests with a Sidak
correction, Student's t for variances measured over 16 batches, and the whole image's
mean)."""

import math
import os

import mitsuba as mi
import numpy as np
import pytest

import pbr
import pbr.scene.pbrt
from pbr.scene.pbrt import write_ply
from pbr.scene.xml import XMLError, to_xml
from pbr.plugins.props import SceneError
from pbr.validate import compare, estimate, welch_dof

# Moving shapes are refused on CUDA (pbr.geometry._traces_with_optix: one Mitsuba scene per
# OptiX kernel); these tests render them.
movers = pytest.mark.skipif(os.environ.get("PBR_TEST_BACKEND", "llvm") == "cuda",
                            reason="moving shapes are not supported on CUDA (one OptiX scene per kernel)")

T = mi.ScalarTransform4f
W, H, S = 32, 16, 2.0          # image size; the view spans x in [-S, S], y in [-S H / W, S H / W]


def _view(objects: dict, spp: int = 64, max_depth: int = 2, sky: bool = True) -> dict:
    """An orthographic camera at z = -5 looking toward +z (world x grows to the image's
    left, y upward), a box filter, a constant sky of radiance 1."""
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": max_depth},
         "cam": {"type": "orthographic", "to_world": T().look_at([0, 0, -5], [0, 0, 0], [0, 1, 0]) @ T().scale([S, S, 1]),
                 "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}},
                 "sampler": {"type": "independent", "sample_count": spp}}}
    if sky:
        d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}
    return {**d, **objects}


def _pixel_points(k: int, mirror_x: bool = False):
    """World (x, y) of k x k points per pixel (midpoints of a sub-grid): (H, W, k*k) arrays."""
    u = (np.arange(W * k) + 0.5) / (W * k)
    v = (np.arange(H * k) + 0.5) / (H * k)
    x = S * (2 * u - 1) if mirror_x else S * (1 - 2 * u)
    y = S * H / W * (1 - 2 * v)
    X, Y = np.meshgrid(x, y)
    to_px = lambda a: a.reshape(H, k, W, k).transpose(0, 2, 1, 3).reshape(H, W, k * k)  # noqa: E731
    return to_px(X), to_px(Y)


def _sphere_miss_fraction(c0, c1, r, k=24, mirror_x=False):
    """Per pixel, the fraction of (time in [0, 1] x pixel area) in which a ray along z
    misses a sphere of radius r whose centre moves from c0 to c1: |p - c0 - t v|^2 < r^2
    is a quadratic a t^2 + b t + c < 0, the blocked time its interval clipped to [0, 1]."""
    x, y = _pixel_points(k, mirror_x)
    v = np.subtract(c1[:2], c0[:2])
    px, py = x - c0[0], y - c0[1]
    a = float(v @ v)
    b = -2 * (px * v[0] + py * v[1])
    c = px * px + py * py - r * r
    disc = np.maximum(b * b - 4 * a * c, 0.0)
    t1, t2 = (-b - np.sqrt(disc)) / (2 * a), (-b + np.sqrt(disc)) / (2 * a)
    blocked = np.clip(np.minimum(t2, 1.0) - np.maximum(t1, 0.0), 0.0, 1.0)
    return 1.0 - blocked.mean(axis=-1)


def _rectangle_miss_fraction(a, b, turn_deg, k=12, steps=512, still=None):
    """Per pixel, the fraction of (time x pixel area) in which a ray along z misses the
    rectangle [-a, a] x [-b, b] turned by turn_deg * t about z at time t (times on a
    midpoint grid of ``steps``), and the still rectangle ``still`` (x0, x1, y0, y1)."""
    x, y = _pixel_points(k)
    miss = np.zeros(x.shape)
    for t in (np.arange(steps) + 0.5) / steps:
        th = math.radians(turn_deg * t)
        u = x * math.cos(th) + y * math.sin(th)          # the point in the rectangle's frame
        w = -x * math.sin(th) + y * math.cos(th)
        miss += (np.abs(u) >= a) | (np.abs(w) >= b)
    if still is not None:
        x0, x1, y0, y1 = still
        miss[(x > x0) & (x < x1) & (y > y0) & (y < y1)] = 0.0
    return miss.mean(axis=-1) / steps


def _sky_level(spp=1024):
    """The sky's image value per channel (a render without shapes but a far-away speck)
    and the variance of that mean."""
    d = _view({"speck": {"type": "sphere", "radius": 1e-3, "center": [0, 0, 50]}})
    est = estimate(lambda seed, spp: pbr.render(pbr.load_dict(d), seed=seed, spp=spp), spp, batches=8, seed=7)
    return est.mean.mean(axis=(0, 1)), est.image_mean_var


def _check_against(d: dict, frac: np.ndarray, spp: int = 1024):
    scene = pbr.load_dict(d)
    est = estimate(lambda seed, spp: pbr.render(scene, seed=seed, spp=spp), spp, batches=16, seed=3)
    sky, sky_var = _sky_level()
    expect = frac[..., None] * sky
    result = compare(est.mean, est.var, expect, frac[..., None] ** 2 * sky_var * np.ones(3),
                     image_mean_var_a=est.image_mean_var, dof=est.batches - 1)
    assert result, result
    return est.mean


BLACK = {"type": "diffuse", "reflectance": 0.0}


@movers
def test_moving_sphere_blocks_the_sky_for_its_time_fraction():
    """A black sphere (radius 0.4) translating from (-1, 0.2) to (1, -0.2) during the
    shutter [0, 1] darkens each pixel by the closed-form fraction of time it covers it."""
    c0, c1, r = (-1.0, 0.2, 0.0), (1.0, -0.2, 0.0), 0.4
    d = _view({"ball": {"type": "sphere", "radius": r, "to_world": T().translate(list(c0)),
                        "to_world_end": T().translate(list(c1)), "bsdf": BLACK}})
    _check_against(d, _sphere_miss_fraction(c0, c1, r))


@movers
def test_rotating_rectangle_sweeps_its_turn():
    """A black 2.4 x 0.6 rectangle turning 120 degrees about the view axis: the sweep
    follows the rotation's direction and a constant angular velocity (slerp)."""
    a, b, turn = 1.2, 0.3, 120.0
    d = _view({"bar": {"type": "rectangle", "to_world": T().scale([a, b, 1]),
                       "to_world_end": T().rotate([0, 0, 1], turn) @ T().scale([a, b, 1]), "bsdf": BLACK}})
    frac = _rectangle_miss_fraction(a, b, turn)
    mirrored = _rectangle_miss_fraction(a, b, -turn)
    assert np.abs(frac - mirrored).max() > 0.3       # the expected image tells the direction
    _check_against(d, frac)


@movers
def test_moving_instance_sweeps_its_turn():
    """The rotating rectangle as an instance of a shape group turning 120 degrees, and a
    still instance of the same group above it (the group's shapes are in the static
    scene and in the moving instance's own): each pixel misses both for the computed
    fraction of time and area."""
    a, b, turn, lift = 1.2, 0.3, 120.0, 0.75
    d = _view({"bar": {"type": "shapegroup", "r": {"type": "rectangle", "to_world": T().scale([a, b, 1]),
                                                   "bsdf": BLACK}},
               "turning": {"type": "instance", "shapegroup": {"type": "ref", "id": "bar"},
                           "to_world_end": T().rotate([0, 0, 1], turn)},
               "still": {"type": "instance", "shapegroup": {"type": "ref", "id": "bar"},
                         "to_world": T().translate([0, lift, 0])}})
    _check_against(d, _rectangle_miss_fraction(a, b, turn, still=(-a, a, lift - b, lift + b)))


def _cube_pose(t):
    """The cube's pose at time t, built directly: moving along x and turning 90 degrees
    about (1, 1, 0) at a constant rate."""
    return T().translate([-0.8 + 1.6 * t, 0.1, -1.5]) @ T().rotate([math.sqrt(0.5), math.sqrt(0.5), 0.0], 90.0 * t) @ T().scale(0.3)


def _lit_floor(cube: dict, spp: int) -> dict:
    d = _view({"floor": {"type": "rectangle", "to_world": T().scale([3, 3, 1]),
                         "bsdf": {"type": "diffuse", "reflectance": 0.8}},
               "cube": {"type": "cube", "bsdf": {"type": "diffuse", "reflectance": 0.5}, **cube},
               "lamp": {"type": "point", "position": [0.3, 0.2, -4.0],
                        "intensity": {"type": "rgb", "value": 20.0}}}, spp=spp, sky=False)
    # Looking at the floor's front (+z side faces the camera at z = -5 after the flip).
    d["floor"]["to_world"] = T().rotate([0, 1, 0], 180.0) @ T().scale([3, 3, 1])
    return d


@movers
def test_moving_cube_shading_and_shadow_equal_the_time_average():
    """A diffuse cube above a floor under a point light, translating and turning during
    the shutter: the image (the cube's faces shaded with their moving normals, its
    shadow cast through shadow rays at each ray's time) equals the average of static
    renders at stratified times (4 strata, one random shift per batch: an unbiased
    estimate of the time integral)."""
    strata, spp_static = 4, 64
    moving = pbr.load_dict(_lit_floor({"to_world": _cube_pose(0.0), "to_world_end": _cube_pose(1.0)}, spp_static))
    est = estimate(lambda seed, spp: pbr.render(moving, seed=seed, spp=spp), 16 * strata * spp_static,
                   batches=16, seed=5)

    def averaged(seed, spp):
        shift = np.random.default_rng(seed).random()
        imgs = [np.asarray(pbr.render(pbr.load_dict(_lit_floor({"to_world": _cube_pose((k + shift) / strata)},
                                                               spp_static)),
                                      seed=seed * strata + k, spp=spp_static), np.float64) for k in range(strata)]
        return np.mean(imgs, axis=0)

    ref = estimate(averaged, 16 * spp_static, batches=16, seed=9)
    result = compare(est.mean, est.var, ref.mean, ref.var, image_mean_var_a=est.image_mean_var,
                     image_mean_var_b=ref.image_mean_var, dof=welch_dof(est.var, est.batches, ref.var, ref.batches))
    assert result, result
    # The shadow and the cube's streak are there (not a static cube, not no cube).
    still = np.asarray(pbr.render(pbr.load_dict(_lit_floor({"to_world": _cube_pose(0.0)}, 256)), seed=1), np.float64)
    assert np.abs(still - est.mean).max() > 0.2


PBRT_SPHERE = """
Scale -1 1 1
LookAt 0 0 5  0 0 0  0 1 0
Camera "orthographic" "float screenwindow" [-2 2 -1 1]
Film "rgb" "integer xresolution" 32 "integer yresolution" 16
Sampler "independent" "integer pixelsamples" 64
Integrator "path" "integer maxdepth" 1
PixelFilter "box"
TransformTimes 0 2
WorldBegin
LightSource "infinite" "rgb L" [1 1 1]
AttributeBegin
Material "diffuse" "rgb reflectance" [0 0 0]
Translate -1 0.2 0
ActiveTransform EndTime
Translate 2 -0.4 0
ActiveTransform All
Shape "sphere" "float radius" 0.4
AttributeEnd
ObjectBegin "tile"
Shape "trianglemesh" "point3 P" [-0.2 -0.2 0  0.2 -0.2 0  0.2 0.2 0  -0.2 0.2 0] "integer indices" [0 1 2 0 2 3]
ObjectEnd
AttributeBegin
Translate 0 -5 0
ActiveTransform EndTime
Rotate 90 0 0 1
ActiveTransform All
ObjectInstance "tile"
AttributeEnd
"""


@movers
def test_pbrt_active_transform_moves_shapes_and_instances(tmp_path):
    """pbrt-v4's ActiveTransform EndTime around a Shape gives the shape pbr's
    ``to_world_end`` (built in its object space) and ``transform_times``; around an
    ObjectInstance, the instance's. With TransformTimes 0 2 and pbrt-v4's default shutter
    [0, 1] the sphere covers half its path: the image is the closed-form fraction for
    the path to (0, 0) (pbrt's camera: world +x on the image's right)."""
    path = tmp_path / "moving.pbrt"
    path.write_text(PBRT_SPHERE)
    d = pbr.scene.pbrt.to_dict(str(path))
    ball = next(v for v in d.values() if isinstance(v, dict) and v.get("type") == "sphere")
    assert ball["transform_times"] == [0.0, 2.0]
    assert np.allclose(np.array(ball["to_world"].matrix)[:3, 3], [-1, 0.2, 0])
    assert np.allclose(np.array(ball["to_world_end"].matrix)[:3, 3], [1, -0.2, 0])
    inst = next(v for v in d.values() if isinstance(v, dict) and v.get("type") == "instance")
    end = np.array(inst["to_world_end"].matrix)
    assert np.allclose(end[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-6) and np.allclose(end[:3, 3], [0, -5, 0])
    frac = _sphere_miss_fraction((-1.0, 0.2, 0.0), (0.0, 0.0, 0.0), 0.4, mirror_x=True)
    scene = pbr.load_file(str(path))
    est = estimate(lambda seed, spp: pbr.render(scene, seed=seed, spp=spp), 1024, batches=16, seed=3)
    sky = est.mean[frac == 1.0].mean(axis=0)      # the sky's level from the pixels never covered
    result = compare(est.mean, est.var, frac[..., None] * sky, np.zeros_like(est.var),
                     image_mean_var_a=est.image_mean_var, dof=est.batches - 1)
    assert result, result
    # Saved as Mitsuba-style XML (transform_times as a string "t0 t1") and read back: the same image.
    xml = tmp_path / "moving.xml"
    xml.write_text(to_xml(d))
    again = pbr.load_file(str(xml))
    assert len(again.geometry.movers) == 2
    assert np.array_equal(np.asarray(pbr.render(again, seed=1, spp=16)), np.asarray(pbr.render(scene, seed=1, spp=16)))
    with pytest.raises(XMLError, match="animated transforms of shapes .* Mitsuba 3"):
        pbr.scene.pbrt.to_dict(str(path), mitsuba=True)


def test_moving_shapes_errors():
    """Clear errors: emitters on moving shapes, motion inside a shapegroup, integrators
    that trace light paths or static geometry, a bad end transform or times."""
    film = {"type": "hdrfilm", "width": 8, "height": 8}
    base = {"type": "scene", "cam": {"type": "perspective", "film": film}}
    moving = {"type": "sphere", "to_world_end": T().translate([1, 0, 0])}
    with pytest.raises(SceneError, match=r"scene.s.emitter: moving shapes .* cannot carry emitters"):
        pbr.load_dict({**base, "s": {**moving, "emitter": {"type": "area"}}})
    with pytest.raises(SceneError, match=r"scene.g.s.to_world_end: shapes inside a shapegroup cannot move"):
        pbr.load_dict({**base, "g": {"type": "shapegroup", "s": moving},
                       "i": {"type": "instance", "shapegroup": {"type": "ref", "id": "g"}}})
    for integrator in ("ptracer", "bdpt", "radiosity"):
        with pytest.raises(SceneError, match=rf"the '{integrator}' integrator does not support moving shapes"):
            pbr.load_dict({**base, "integrator": {"type": integrator}, "l": {"type": "constant"}, "s": moving})
    with pytest.raises(SceneError, match=r"scene.s.transform_times: the end time must exceed"):
        pbr.load_dict({**base, "s": {**moving, "transform_times": [1.0, 0.0]}})
    with pytest.raises(SceneError, match=r"scene.s.to_world_end: expected an invertible affine"):
        pbr.load_dict({**base, "s": {**moving, "to_world_end": np.zeros((4, 4))}})
    # An end transform equal to the start: a static shape, in Mitsuba's scene as before.
    scene = pbr.load_dict({**base, "s": {"type": "sphere", "to_world_end": T()}})
    assert not scene.geometry.moving and len(scene.shapes()) == 1


def test_moving_shape_bounds_cover_the_motion():
    """The scene's bounding box (which sizes infinite and distant lights) holds a moving
    shape over its whole motion: a unit sphere moving from x = 0 to x = 10 and a turning
    bar (a point at distance 2 from the axis passes through y = 2 half-way)."""
    film = {"type": "hdrfilm", "width": 8, "height": 8}
    scene = pbr.load_dict({"type": "scene", "cam": {"type": "perspective", "film": film},
                           "s": {"type": "sphere", "to_world_end": T().translate([10, 0, 0])},
                           "bar": {"type": "cube", "to_world": T().scale([2, 0.01, 0.01]),
                                   "to_world_end": T().rotate([0, 0, 1], 180.0) @ T().scale([2, 0.01, 0.01])}})
    bb = scene.bbox()
    assert bb.min[0] <= -2 and bb.max[0] >= 11 and bb.max[1] >= 2 - 1e-3 and bb.min[1] <= -1
    assert bb.max[0] < 11.5 and bb.max[1] < 2.5


@movers
def test_shapes_with_one_motion_share_a_mover():
    """Moving shapes with the same motion (the parts of one animated object: the same
    ``to_world`` and ``to_world_end``) are one Mitsuba scene, traced once per ray; another
    motion is another. Each hit still maps to its own shape (its BSDF): a red and a green
    ball moving together."""
    end = T().translate([0.5, 0, 0])
    red, green = ({"type": "diffuse", "reflectance": {"type": "rgb", "value": c}} for c in ([0.8, 0, 0], [0, 0.8, 0]))
    d = _view({"left": {"type": "sphere", "center": [0.5, 0, 0], "radius": 0.3, "to_world_end": end, "bsdf": red},
               "right": {"type": "sphere", "center": [-0.5, 0, 0], "radius": 0.3, "to_world_end": end, "bsdf": green},
               "other": {"type": "sphere", "radius": 0.1, "to_world": T().translate([0, 0.8, 0]),
                         "to_world_end": T().translate([0, 0.9, 0])}})
    scene = pbr.load_dict(d)
    assert len(scene.geometry.movers) == 2
    img = np.asarray(pbr.render(scene, spp=64, seed=1), np.float64)
    # World x > 0 is the image's left: the red ball there (x from 0.5 to 1: columns 8-12
    # always covered), the green one right of it (x from -0.5 to 0: columns 16-20).
    row = img[H // 2]
    red_px, green_px = row[10], row[18]
    assert red_px[0] > 3 * red_px[1] and green_px[1] > 3 * green_px[0], (red_px, green_px)


@movers
def test_hits_on_a_moving_ellipsoid_match_the_analytic_surface():
    """Rays at chosen times against a unit sphere stretched to an ellipsoid (0.6, 0.3,
    0.45) that moves and turns 90 degrees about (0, 1, 1)/sqrt(2): the hit point, the
    distance, the normal (the inverse transpose: proportional to the object-space point
    mapped by M^-T, not by M, for a non-uniform stretch), the shading frame and wi equal
    the values solved here in the ellipsoid's frame at each ray's time."""
    axis = np.array([0.0, 1.0, 1.0]) / math.sqrt(2.0)
    stretch = np.diag([0.6, 0.3, 0.45, 1.0])

    def pose(t):   # built directly: translation linear in t, a turn of 90 t degrees about axis
        th = math.radians(90.0 * t)
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        m = np.eye(4)
        m[:3, :3] = np.eye(3) + math.sin(th) * k + (1 - math.cos(th)) * k @ k
        m[:3, 3] = [-0.5 + 1.0 * t, 0.2, 0.1 * t]
        return m @ stretch

    film = {"type": "hdrfilm", "width": 8, "height": 8}
    scene = pbr.load_dict({"type": "scene", "cam": {"type": "perspective", "film": film},
                           "egg": {"type": "sphere", "to_world": pose(0.0), "to_world_end": pose(1.0)}})
    rng = np.random.default_rng(4)
    n = 64
    times = rng.random(n)
    origins = rng.normal(size=(n, 3)) * 0.2 + [0.0, 0.0, -4.0]
    targets = np.array([pose(t)[:3, 3] for t in times]) + rng.normal(size=(n, 3)) * 0.1
    dirs = targets - origins
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    ray = mi.Ray3f(mi.Point3f(*origins.T), mi.Vector3f(*dirs.T), mi.Float(np.full(n, 1e4)), mi.Float(times),
                   mi.Spectrum(0.0))
    si, shape = scene.geometry.intersect(ray, mi.Bool(True))
    hit = np.array(si.is_valid())
    assert hit.sum() >= n - 2
    got = {k: np.array(getattr(si, k)).reshape(3, -1).T if k != "t" else np.array(si.t) for k in ("p", "n", "t")}
    sh_n = np.array(si.sh_frame.n).reshape(3, -1).T
    wi = np.array(si.wi).reshape(3, -1).T
    for j in np.flatnonzero(hit):
        m = pose(times[j])
        inv = np.linalg.inv(m)
        o, d = inv[:3, :3] @ origins[j] + inv[:3, 3], inv[:3, :3] @ dirs[j]   # the ray in object space
        a, b, c = d @ d, 2 * o @ d, o @ o - 1.0
        t = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
        p_obj = o + t * d
        normal = inv[:3, :3].T @ p_obj
        normal /= np.linalg.norm(normal)
        assert got["t"][j] == pytest.approx(t, abs=2e-4)
        assert np.allclose(got["p"][j], origins[j] + t * dirs[j], atol=2e-4)
        assert np.allclose(got["n"][j], normal, atol=1e-3) and np.allclose(sh_n[j], normal, atol=1e-3)
        assert wi[j][2] == pytest.approx(-dirs[j] @ normal, abs=1e-3)     # wi in the shading frame
    assert np.all(np.array(shape)[hit] == 0)


@movers
@pytest.mark.parametrize("kind", ["obj", "ply"])
def test_rotating_mesh_file_sweeps_its_turn(tmp_path, kind):
    """The rotating rectangle of ``test_rotating_rectangle_sweeps_its_turn`` as a mesh
    file (OBJ: Mitsuba's reader; PLY: trimesh): mesh files are read in object space when
    they move (``to_world`` is not baked into the vertices)."""
    pos = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64)
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    path = tmp_path / f"square.{kind}"
    if kind == "obj":
        path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in pos) + "f 1 2 3\nf 1 3 4\n")
    else:
        write_ply(str(path), pos, tri, None, None)
    a, b, turn = 1.2, 0.3, 120.0
    d = _view({"bar": {"type": kind, "filename": str(path), "to_world": T().scale([a, b, 1]),
                       "to_world_end": T().rotate([0, 0, 1], turn) @ T().scale([a, b, 1]), "bsdf": BLACK}})
    _check_against(d, _rectangle_miss_fraction(a, b, turn))


def test_frozen_render_of_moving_shapes():
    """pbr.freeze records a render of a scene with moving shapes (their Mitsuba scenes
    are part of the frozen function's state) and replays it bit for bit."""
    d = _view({"ball": {"type": "sphere", "radius": 0.4, "to_world": T().translate([-1, 0.2, 0]),
                        "to_world_end": T().translate([1, -0.2, 0]), "bsdf": BLACK}})
    scene = pbr.load_dict(d)
    frozen = pbr.freeze(lambda scene, seed: pbr.render(scene, spp=16, seed=seed))
    for seed in range(3):
        assert np.array_equal(np.asarray(frozen(scene, seed)), np.asarray(pbr.render(scene, spp=16, seed=seed)))


def test_moving_shapes_on_optix_are_refused_with_a_clear_error(monkeypatch):
    """On CUDA each moving object's Mitsuba scene would be a second OptiX shader binding
    table in the kernel, whose rays Dr.Jit disables (the object vanishes from the image:
    measured on an H200): pbr refuses the scene there, naming the backend to use."""
    import pbr.geometry
    monkeypatch.setattr(pbr.geometry, "_traces_with_optix", lambda: True)
    d = _view({"ball": {"type": "sphere", "radius": 0.5, "to_world": T().translate([-0.5, 0, 0]),
                        "to_world_end": T().translate([0.5, 0, 0])}}, spp=4)
    with pytest.raises(SceneError, match="not supported on the CUDA backend.*set_backend"):
        pbr.load_dict(d)
