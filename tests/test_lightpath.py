"""Light tracing: the emission sampling of the lights (``LightSet.sample_Le`` /
``pdf_Le``), the camera's importance (``sample_Wi``, ``We``, ``pdf_We``), film splatting,
and the ``ptracer`` integrator.

* Emission: the mean initial throughput ``E[L |n.d| / (pmf pdf_pos pdf_dir)]`` equals each
  light's analytic power (area pi A L, point 4 pi I, spot, directional pi r^2 E, constant
  4 pi^2 r^2 L, a uniform envmap, directionalarea A L); sampled directions follow
  ``pdf_Le`` (chi-square: area cosine lobe, spot cone, envmap importance); ``pdf_Le`` of a
  sampled ray reproduces the sample's densities.
* Camera: ``sample_Wi`` inverts ``sample_ray`` and agrees with ``We``/``pdf_We``; the
  importance integrates to 1 over the film (int We cos d omega).
* Splatting: weights of the box and Gaussian filters.
* ``ptracer`` against Mitsuba's ``ptracer`` (Cornell box with its Gaussian film; glass
  sphere caustics under an area light and a point light; a point light inside a glass
  ball, where importance transport differs from radiance transport by eta^2, and
  directionalarea beams) and against pbr's ``path`` (an independent estimator, box
  filter), plus the foundation BDPT uses (``LightTracingIntegrator``: camera image +
  splats). Must-fail: a radiance-transport BSDF on light paths (lamp in glass: x2.25) and
  a 4% error in the camera importance.
"""

import math
import sys

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr import validate
from pbr import spectrum as spec
from pbr.plugins.props import Props, SceneError
from pbr.spectrum import SampledWavelengths

RES, SPP, BATCHES = 20, 1024, 16
N_SAMPLES = 1 << 18


def T():
    return mi.ScalarTransform4f()


def cbox(res=RES, filt="box", integrator="ptracer", max_depth=-1, **kw):
    d = pbr.cornell_box(res, 16)
    d["sensor"]["film"]["rfilter"] = {"type": filt}
    d["integrator"] = {"type": integrator, "max_depth": max_depth, **kw}
    return d


def pbr_fn(d):
    scene = pbr.load_dict(d)
    return lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))


def compare(fa, fb, scale=1, spp=SPP):
    return validate.compare_renders(fa, fb, spp=spp * scale, batches=BATCHES, seed_a=31, seed_b=32)


def vs_mitsuba(d, scale=1):
    return compare(pbr_fn(d), validate.mitsuba_render_fn(d), scale)


# ------------------------------------------------------------------------- emission

def emit(scene, n=N_SAMPLES, seed=0):
    """n rays from the scene's lights, and their wavelengths."""
    L = scene.lights
    rng = mi.PCG32(n, seed)
    wl = SampledWavelengths.sample_visible(rng.next_float32())
    u = [rng.next_float32() for _ in range(5)]
    s = L.sample_Le(L.sampler("power"), u[0], mi.Point2f(u[1], u[2]), mi.Point2f(u[3], u[4]), wl, mi.Bool(True))
    return s, wl


def power_estimate(scene):
    """Mean and standard error of Y(weight): the emitted power (luminance units)."""
    s, wl = emit(scene)
    y = np.array(spec.to_xyz(s.weight, wl)[1], dtype=np.float64)
    return y.mean(), y.std() / math.sqrt(len(y))


def scene_with(**emitters):
    d = {"type": "scene", "floor": {"type": "rectangle", "to_world": T().translate([0, -1, 0]).scale(2.0)}}
    d.update(emitters)
    return pbr.load_dict(d)


@pytest.mark.parametrize("kind", ["area", "sphere", "point", "spot", "directional", "constant", "envmap",
                                  "directionalarea", "mixed"])
def test_emitted_power(kind):
    from pbr.lights.spot import spot_solid_angle
    if kind == "area":
        sc = scene_with(l={"type": "rectangle", "to_world": T().scale([0.3, 0.2, 1.0]),
                           "emitter": {"type": "area", "radiance": 2.0}})
        expect = math.pi * (0.6 * 0.4) * 2.0
    elif kind == "sphere":
        sc = scene_with(l={"type": "sphere", "radius": 0.1, "emitter": {"type": "area", "radiance": 2.0}})
        expect = math.pi * (4 * math.pi * 0.01) * 2.0
    elif kind == "point":
        sc = scene_with(l={"type": "point", "position": [0, 0.5, 0], "intensity": 3.0})
        expect = 4 * math.pi * 3.0
    elif kind == "spot":
        sc = scene_with(l={"type": "spot", "to_world": T().look_at([0, 1, 0], [0, -1, 0.3], [0, 0, 1]),
                           "cutoff_angle": 30.0, "beam_width": 10.0, "intensity": 3.0})
        expect = 3.0 * spot_solid_angle(math.radians(30.0), math.radians(10.0))
    elif kind == "directional":
        sc = scene_with(l={"type": "directional", "direction": [0.3, -1, 0.2], "irradiance": 3.0})
        r = sc.lights.families["directional"].radius
        expect = math.pi * r * r * 3.0
    elif kind == "constant":
        sc = scene_with(l={"type": "constant", "radiance": 0.5})
        r = sc.lights.families["constant"].radius
        expect = 4 * math.pi * math.pi * r * r * 0.5
    elif kind == "envmap":
        sc = scene_with(l={"type": "envmap", "bitmap": np.full((8, 16, 3), 0.5, np.float32)})
        r = sc.lights.families["envmap"].radius
        expect = 4 * math.pi * math.pi * r * r * 0.5
    elif kind == "directionalarea":
        sc = scene_with(l={"type": "disk", "to_world": T().scale(0.5), "emitter": {"type": "directionalarea",
                                                                                 "radiance": 2.0}})
        expect = math.pi * 0.25 * 2.0
    else:  # several lights of different families: the power-proportional pick
        sc = scene_with(a={"type": "point", "position": [0, 0.5, 0], "intensity": 3.0},
                        b={"type": "rectangle", "to_world": T().scale([0.3, 0.2, 1.0]),
                           "emitter": {"type": "area", "radiance": 2.0}},
                        c={"type": "spot", "to_world": T().look_at([0, 1, 0], [0, -1, 0.3], [0, 0, 1]),
                           "cutoff_angle": 30.0, "beam_width": 30.0, "intensity": 3.0})
        expect = 4 * math.pi * 3.0 + math.pi * 0.24 * 2.0 + 3.0 * 2 * math.pi * (1 - math.cos(math.radians(30)))
    m, se = power_estimate(sc)
    # The D65 spectra have unit luminance up to the CIE tables' rounding (<1e-3).
    assert abs(m - expect) < 4 * se + 1e-3 * expect, (m, se, expect)
    assert se < 0.01 * expect


def _chi2(sample_dir, pdf_dir, res=51, ires=16):
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    t = ChiSquareTest(SphericalDomain(), sample_dir, pdf_dir, sample_dim=2, sample_count=300_000, res=res, ires=ires)
    return t.run(), t.messages


def _one_light(**em):
    return scene_with(**em)


@pytest.mark.parametrize("kind", ["area", "spot", "envmap"])
def test_sample_Le_direction_chi2(kind):
    """Directions of sample_Le follow pdf_Le's pdf_dir (a fixed point/normal per light)."""
    if kind == "area":
        sc = _one_light(l={"type": "rectangle", "to_world": T().rotate([1, 0, 0], 30), "emitter": {"type": "area"}})
    elif kind == "spot":
        sc = _one_light(l={"type": "spot", "to_world": T().look_at([0, 1, 0], [0.5, -1, 0.3], [0, 0, 1]),
                           "cutoff_angle": 40.0})
    else:
        sys.path.insert(0, __file__.rsplit("/", 1)[0])
        from mitsuba_scenes import sky_image
        sc = _one_light(l={"type": "envmap", "bitmap": sky_image(), "to_world": T().rotate([0, 1, 0], 20)})
    lights = sc.lights
    light = mi.UInt32(0)
    ref = emit(sc, 4)[0]
    p0, n0 = ref.o, ref.n          # any sample's point and normal (planar / point lights)

    def sample_dir(u):
        n = dr.width(u)
        wl = SampledWavelengths(mi.Spectrum(550.0) + dr.zeros(mi.Spectrum, n), mi.Spectrum(1.0))
        s = lights.sample_Le(lights.sampler("power"), dr.zeros(mi.Float, n),
                             mi.Point2f(0.5, 0.5) + dr.zeros(mi.Point2f, n), u, wl, mi.Bool(True))
        return s.d

    def pdf_dir(d):
        n = dr.width(d)
        p = dr.gather(mi.Point3f, p0, dr.zeros(mi.UInt32, n))
        nn = dr.gather(mi.Normal3f, n0, dr.zeros(mi.UInt32, n))
        return lights.pdf_Le(light, p, nn, d, mi.Bool(True))[1]

    # The cone's edge is a jump of the density: integrate its bins finely.
    ok, msg = _chi2(sample_dir, pdf_dir, ires=32 if kind == "spot" else 16)
    assert ok, msg


@pytest.mark.parametrize("kind", ["area-mesh", "point", "spot", "directional", "envmap"])
def test_pdf_Le_matches_sample(kind):
    ems = {"area-mesh": {"type": "cube", "to_world": T().scale(0.2), "emitter": {"type": "area"}},
           "point": {"type": "point", "position": [0, 1, 0]},
           "spot": {"type": "spot", "to_world": T().look_at([0, 1, 0], [0, -1, 0], [0, 0, 1])},
           "directional": {"type": "directional", "direction": [0, -1, 0.5]},
           "envmap": {"type": "envmap", "bitmap": np.random.default_rng(0).random((8, 16, 3)).astype(np.float32)}}
    sc = _one_light(l=ems[kind], m={"type": "point", "position": [0.3, 0.2, 0.1]})
    s, _ = emit(sc, 4096)
    pp, pd = sc.lights.pdf_Le(s.light, s.o, s.n, s.d, mi.Bool(True))
    ok = np.array(s.pdf_dir) > 0
    assert ok.mean() > 0.95
    def arr(x):  # (literal densities have width 1)
        return np.broadcast_to(np.array(x), ok.shape)
    np.testing.assert_allclose(arr(pp)[ok], arr(s.pdf_pos)[ok], rtol=1e-4)
    np.testing.assert_allclose(arr(pd)[ok], arr(s.pdf_dir)[ok], rtol=2e-3)
    pmf = np.array(sc.lights.pmf_Le(sc.lights.sampler("power"), s.light, mi.Bool(True)))
    np.testing.assert_allclose(pmf, np.array(s.pmf), rtol=1e-6)


def test_rebuild_refreshes_the_light_samplers():
    """Light samplers are built per scene build: after params.update() the integrator's
    prepare step takes the new ones, whose probabilities follow the new powers (a stale
    emission sampler would keep picking the lights 1:1)."""
    sc = scene_with(a={"type": "point", "position": [0.3, 0.5, 0.0], "intensity": 1.0},
                    b={"type": "point", "position": [-0.3, 0.5, 0.0], "intensity": 1.0},
                    integrator={"type": "ptracer"})
    old = sc.integrator.emission_sampler
    np.testing.assert_allclose(old.pmf_np, [0.5, 0.5], rtol=1e-6)
    params = pbr.traverse(sc)
    params["a.intensity.value"] = mi.Color3f(3.0)
    params.update()
    new = sc.integrator.emission_sampler
    assert new is not old and new is sc.lights.sampler("power")
    np.testing.assert_allclose(new.pmf_np, [0.75, 0.25], rtol=1e-5)


# --------------------------------------------------------------------------- camera

def _camera(**kw):
    d = pbr.cornell_box(32, 4)
    d["sensor"]["film"]["width"] = 40          # not square: the aspect ratio matters
    d["sensor"].update(kw)
    return pbr.load_dict(d).sensors[0]


@pytest.mark.parametrize("kw", [{}, {"principal_point_offset_x": 0.1, "fov_axis": "y"}])
def test_sample_Wi_inverts_sample_ray(kw):
    cam = _camera(**kw)
    rng = np.random.default_rng(1)
    pos = mi.Point2f(*rng.random((2, 1000)).astype(np.float32))
    ray = cam.sample_ray(pos)
    t = mi.Float(rng.uniform(0.5, 3.0, 1000).astype(np.float32))
    cs = cam.sample_Wi(ray.o + ray.d * t)
    assert np.all(np.array(cs.valid))
    np.testing.assert_allclose(np.array(cs.pos), np.array(pos), atol=2e-5)
    np.testing.assert_allclose(np.array(-cs.wi), np.array(ray.d), atol=1e-5)
    We, wpos = cam.We(ray)
    np.testing.assert_allclose(np.array(We), np.array(cs.We), rtol=1e-4)
    np.testing.assert_allclose(np.array(wpos), np.array(pos), atol=2e-5)
    pdf_pos, pdf_dir = cam.pdf_We(ray)
    # pdf_dir = We cos: the density of sample_ray's directions.
    cos = np.array(dr.dot(ray.d, mi.Vector3f(*cam.to_world[:3, 2].tolist())))
    np.testing.assert_allclose(np.array(pdf_dir), np.array(We) * cos, rtol=1e-4)
    # pdf (solid angle at the point) = dist^2 / cos.
    dist = np.array(t) + np.array(dr.norm(ray.o - cs.p))
    np.testing.assert_allclose(np.array(cs.pdf), dist ** 2 / cos, rtol=1e-3)


def test_importance_integrates_to_one():
    """int We cos d omega over all directions = 1 (uniform sphere directions)."""
    cam = _camera(fov=50)
    n = 1 << 20
    rng = mi.PCG32(n)
    d = mi.warp.square_to_uniform_sphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    m = cam.to_world.tolist()
    o = mi.Point3f(m[0][3], m[1][3], m[2][3])
    We, _ = cam.We(mi.Ray3f(o, d))
    cos = dr.dot(d, mi.Vector3f(m[0][2], m[1][2], m[2][2]))
    v = np.array(We * cos * 4 * math.pi, dtype=np.float64)
    assert abs(v.mean() - 1) < 4 * v.std() / math.sqrt(n)
    # Points behind the camera or off the film are invalid.
    cs = cam.sample_Wi(o - mi.Vector3f(m[0][2], m[1][2], m[2][2]))
    assert not bool(cs.valid[0])


# ------------------------------------------------------------------------ splatting

@pytest.mark.parametrize("filt", ["box", "gaussian", "tent"])
def test_splat_weights(filt):
    from pbr.integrators.lightpath import SplatFilm
    cam = _camera(film={"type": "hdrfilm", "width": 8, "height": 6, "rfilter": {"type": filt}})
    pos = mi.Point2f([2.75 / 8, 0.5], [0.25, 0.0])    # (2.75, 1.5) in pixels; the top edge
    film = SplatFilm(cam)
    film.splat_xyz(pos, mi.Array3f(mi.Float([1.0, 1.0]), 0.0, 0.0), mi.Bool([True, False]))
    img = np.array(film.buf).reshape(6, 8, 3)[..., 0]
    assert img.sum() == pytest.approx(1.0, rel=1e-5)        # the whole footprint is inside
    if filt == "box":
        assert img[1, 2] == pytest.approx(1.0)
    elif filt == "tent":                                  # radius 1: 0.75 and 0.25 along x
        assert img[1, 2] == pytest.approx(0.75) and img[1, 3] == pytest.approx(0.25)
    else:
        assert img[1, 2] == img.max() and np.count_nonzero(img) > 4
    edge = SplatFilm(cam)
    edge.splat_xyz(pos, mi.Array3f(mi.Float([0.0, 1.0]), 0.0, 0.0), mi.Bool([False, True]))
    lost = 1.0 - np.array(edge.buf).sum()
    assert (lost > 0.3) if filt != "box" else lost == pytest.approx(0.5, abs=0.5)


# ------------------------------------------------------------------------- ptracer

def caustic_box(light="area", rough=None, res=RES):
    d = cbox(res)
    del d["small-box"], d["large-box"]
    glass = {"type": "dielectric", "int_ior": 1.5}
    if rough:
        glass = {"type": "roughdielectric", "int_ior": 1.5, "alpha": rough}
    d["glass"] = {"type": "sphere", "center": [0.0, -0.35, 0.0], "radius": 0.35, "bsdf": glass}
    if light == "point":
        del d["light"]
        d["pl"] = {"type": "point", "position": [0.1, 0.8, 0.1], "intensity": {"type": "rgb", "value": [2.0, 2.0, 2.0]}}
    return d


def lamp_box(rough=None):
    """A point light inside a glass ball: light paths start inside glass, so importance
    transport (no 1/eta^2 on refraction) matters (x eta^2 = 2.25 otherwise)."""
    d = cbox()
    del d["small-box"], d["large-box"], d["light"]
    glass = {"type": "roughdielectric", "int_ior": 1.5, "alpha": rough} if rough else \
        {"type": "dielectric", "int_ior": 1.5}
    d["glass"] = {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.4, "bsdf": glass}
    d["pl"] = {"type": "point", "position": [0.1, 0.1, 0.05], "intensity": {"type": "rgb", "value": [2.0, 2.0, 2.0]}}
    return d


def test_ptracer_cornell_gaussian_vs_mitsuba(scale):
    res = vs_mitsuba(cbox(filt="gaussian"), scale)
    assert res, res


@pytest.mark.parametrize("light", ["area", "point"])
def test_ptracer_caustic_vs_mitsuba(light, scale):
    """A glass sphere on the floor: its caustic, and a black sphere (specular surfaces
    seen directly are black in a particle tracer)."""
    res = vs_mitsuba(caustic_box(light), scale)
    assert res, res


@pytest.mark.parametrize("rough", [None, 0.2])
def test_ptracer_lamp_in_glass_vs_mitsuba(rough, scale):
    res = vs_mitsuba(lamp_box(rough), scale)
    assert res, res


def test_ptracer_directionalarea_and_spot_vs_mitsuba(scale):
    """A parallel beam (directionalarea, delta in direction) and a spot light (cone
    sampling) in the open Cornell box."""
    d = cbox()
    del d["light"]
    d["beam"] = {"type": "rectangle", "to_world": T().translate([0.1, 0.95, 0.1]).rotate([1, 0, 0], 100).scale(0.4),
                 "emitter": {"type": "directionalarea", "radiance": {"type": "rgb", "value": [3.0, 2.5, 1.5]}}}
    d["spot"] = {"type": "spot", "to_world": T().look_at([-0.5, 0.9, 0.5], [0.3, -1, -0.2], [0, 0, 1]),
                 "cutoff_angle": 25.0, "intensity": {"type": "rgb", "value": [1.0, 2.0, 3.0]}}
    res = vs_mitsuba(d, scale)
    assert res, res


def test_ptracer_environment_vs_mitsuba_and_path(scale):
    """An envmap and a directional sun through the open box. Against Mitsuba with
    hide_emitters (Mitsuba's ptracer estimates the directly seen sky by sampling directions
    from the camera, a heavy-tailed estimator the z-test cannot judge); against path with
    the sky visible."""
    sys.path.insert(0, __file__.rsplit("/", 1)[0])
    from mitsuba_scenes import sky_image
    d = cbox(hide_emitters=True)
    del d["light"], d["back"], d["ceiling"]
    d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(sky_image()), "scale": 1.0}
    d["sun"] = {"type": "directional", "direction": [0.3, -1, -0.6], "irradiance": {"type": "rgb", "value": [2.0, 2.0, 2.0]}}
    res = vs_mitsuba(d, scale)
    assert res, res
    d["integrator"] = {"type": "ptracer", "max_depth": 3}
    fa = pbr_fn(d)
    d["integrator"] = {"type": "path", "max_depth": 3}
    res = compare(fa, pbr_fn(d), scale)
    assert res, res


def test_radiance_transport_on_light_paths_fails(monkeypatch):
    """Must fail: light paths with the radiance-transport BSDF (1/eta^2 on refraction)."""
    import pbr.integrators.ptracer as pt
    monkeypatch.setattr(pt, "sample_importance", lambda bsdfs, b, ctx, u1, u2, a: bsdfs.sample(b, ctx, u1, u2, a))
    res = vs_mitsuba(lamp_box())
    assert not res and res.mean_ratio > 2.0, res


def point_cbox(integrator):
    """The diffuse Cornell box lit by a point light (no emitter in view: a precise image
    mean), box filter (both films estimate the same pixel integral)."""
    d = cbox(integrator=integrator, max_depth=3)
    del d["light"]
    d["pl"] = {"type": "point", "position": [0.1, 0.7, 0.2], "intensity": {"type": "rgb", "value": [2.0, 1.8, 1.5]}}
    return d


def test_ptracer_vs_path():
    """Independent estimators of the diffuse Cornell box, with its area light seen
    directly and with a point light."""
    res = compare(pbr_fn(cbox(max_depth=3)), pbr_fn(cbox(integrator="path", max_depth=3)))
    assert res, res
    res = compare(pbr_fn(point_cbox("ptracer")), pbr_fn(point_cbox("path")))
    assert res, res


def test_wrong_importance_fails(monkeypatch):
    """Must fail: a camera importance 6% too large."""
    from pbr.cameras import PerspectiveCamera
    orig = PerspectiveCamera.sample_Wi

    def biased(self, ref_p, u=None):
        cs = orig(self, ref_p, u)
        cs.We = cs.We * 1.06
        return cs
    monkeypatch.setattr(PerspectiveCamera, "sample_Wi", biased)
    res = compare(pbr_fn(point_cbox("ptracer")), pbr_fn(point_cbox("path")))
    assert not res and not res.ratio_ok and res.mean_ratio > 1.0, res


def test_light_tracing_integrator_foundation():
    """BDPT's plumbing: a LightTracingIntegrator whose camera samples return the emitted
    radiance seen directly and whose light paths splat their camera connections equals
    path (the camera image and the splatted image add up)."""
    from pbr.integrators.lightpath import LightTracingIntegrator
    from pbr.integrators.ptracer import ParticleTracerIntegrator

    class Split(LightTracingIntegrator):
        name = "split"

        def __init__(self):
            self.pt = ParticleTracerIntegrator(Props({"type": "ptracer", "max_depth": 4}, "scene.integrator"))

        def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
            self.pt.camera, self.pt.splats = self.camera, self.splats
            self.pt.emission_sampler = self.emission_sampler
            self.pt._trace(scene, rng, wl, active)
            return self.pt._visible_emitters(scene, ray, wl, active), mi.Bool(active)

    scene = pbr.load_dict(cbox(integrator="path", max_depth=4))
    integ = Split()
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, integrator=integ, seed=seed, spp=spp))  # noqa: E731
    res = compare(fa, pbr_fn(cbox(integrator="path", max_depth=4)))
    assert res, res


def test_max_depth_and_hide_emitters():
    def img(**kw):
        return np.asarray(pbr.render(pbr.load_dict(cbox(res=12, **kw)), spp=16))
    assert np.all(img(max_depth=0) == 0)
    only_light = img(max_depth=1)
    assert only_light.max() > 1 and np.count_nonzero(only_light.sum(axis=2)) < 12 * 12 // 4
    assert np.all(img(max_depth=1, hide_emitters=True) == 0)
    both = img(max_depth=2)
    assert both.sum() > only_light.sum()


def test_load_errors():
    d = cbox()
    d["portal"] = {"type": "portalenvmap", "bitmap": np.ones((4, 8, 3), np.float32),
                   "portal": [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]]}
    with pytest.raises(SceneError, match=r"scene\.portal: .*ptracer"):
        pbr.load_dict(d)
    d = cbox()
    d["fog"] = {"type": "homogeneous", "sigma_t": 1.0}
    d["large-box"]["interior"] = {"type": "ref", "id": "fog"}
    d["fog"]["id"] = "fog"
    with pytest.raises(SceneError, match="media"):
        pbr.load_dict(d)
    with pytest.raises(SceneError, match="samples_per_pass"):
        pbr.load_dict(cbox(samples_per_pass=0))
    sc = pbr.load_dict(cbox(samples_per_pass=3))
    with pytest.raises(SceneError, match="multiple of samples_per_pass"):
        pbr.render(sc, spp=16)
    with pytest.raises(NotImplementedError):
        sc.integrator.render_backward(sc, None)
