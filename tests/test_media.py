"""Participating media and the volumetric integrators (volpath, simplevolpath).

Statistical image comparisons with Mitsuba's ``volpath`` (pbr.validate), consistency
checks that need no reference (the majorant grid changes nothing but the cost; the
simple and MIS estimators agree), phase-function sampling (chi-square), and the
extremes of the parameter ranges."""

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import validate
from pbr.media.grid import write_vol, read_vol, cell_maxima

from mitsuba_scenes import material_box, compare_with_mitsuba


def fog_ball(medium, bsdf="null", integrator="volpath", max_depth=6):
    """The material box (hidden ceiling light, box filter) with a sphere of medium."""
    d = material_box({"type": "diffuse"}, max_depth=max_depth)
    d["integrator"]["type"] = integrator
    d["ball"] = {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.35,
                 "bsdf": {"type": bsdf} if isinstance(bsdf, str) else bsdf, "interior": medium}
    return d


def blob(n=16):
    """A smooth density blob (max 12) with an empty slab: sparse enough for the majorant grid."""
    z, y, x = np.mgrid[0:n, 0:n, 0:n] / (n - 1.0)
    g = np.exp(-((x - 0.5) ** 2 + (y - 0.4) ** 2 + (z - 0.6) ** 2) / 0.05) * 12.0
    g[:, :, : n // 4] = 0.0
    return g.astype(np.float32)


def grid_cube(vol_path, albedo=0.85):
    T = mi.ScalarTransform4f
    d = material_box({"type": "diffuse"})
    d["integrator"]["type"] = "volpath"
    # Above both blocks: a medium boundary must not overlap or touch other surfaces
    # (a cloud cube at the origin cuts the large block and is coplanar with the small
    # block's top, and the two renderers then resolve the ambiguity differently).
    c, h = np.array([0.1, 0.55, 0.1]), 0.3
    d["cloud"] = {"type": "cube", "to_world": T().translate(c.tolist()).scale(h), "bsdf": {"type": "null"},
                  "interior": {"type": "heterogeneous", "albedo": albedo,
                               "sigma_t": {"type": "gridvolume", "filename": vol_path,
                                           "to_world": T().translate((c - h).tolist()).scale(2 * h)}}}
    return d


def _check(res, label):
    print(f"{label}: {res}")
    assert res.passed, f"{label}: {res}"


# -- statistical comparisons with Mitsuba's volpath ------------------------------------------
COMPARISONS = {
    "homogeneous-null": lambda tmp: fog_ball({"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.8,
                                              "phase": {"type": "hg", "g": 0.6}}),
    "homogeneous-dielectric": lambda tmp: fog_ball(
        {"type": "homogeneous", "sigma_t": 2.0, "albedo": {"type": "rgb", "value": [0.9, 0.6, 0.3]}},
        bsdf={"type": "dielectric", "int_ior": 1.33}),
    "chromatic": lambda tmp: fog_ball({"type": "homogeneous", "scale": 8.0, "albedo": 0.9,
                                       "sigma_t": {"type": "rgb", "value": [0.1, 0.5, 0.9]}}),
    "rayleigh": lambda tmp: fog_ball({"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.9,
                                      "phase": {"type": "rayleigh"}}),
}


@pytest.mark.parametrize("name", sorted(COMPARISONS))
def test_volpath_matches_mitsuba(name, tmp_path, scale):
    _check(compare_with_mitsuba(COMPARISONS[name](tmp_path), scale), name)


def test_heterogeneous_grid_matches_mitsuba(tmp_path, scale):
    vol = str(tmp_path / "blob.vol")
    write_vol(vol, blob())
    _check(compare_with_mitsuba(grid_cube(vol), scale), "grid")


def test_emitter_inside_medium_matches_mitsuba(scale):
    d = fog_ball({"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.9, "phase": {"type": "hg", "g": -0.3}})
    d["lamp"] = {"type": "sphere", "center": [0.05, 0.0, 0.05], "radius": 0.07,
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [8.0, 6.0, 3.0]}}}
    # The lamp is shown: with hide_emitters, Mitsuba 3.9's volpath skips a hidden emitter
    # by a purely geometric search for the next surface, so the medium inside and behind
    # the lamp is neither attenuating nor scattering on that camera ray; pbr keeps
    # tracking the medium (the lamp's pixels differ by up to 1.7x; docs/media.md).
    d["integrator"]["hide_emitters"] = False
    _check(compare_with_mitsuba(d, scale), "emitter in medium")


def test_camera_inside_medium_matches_mitsuba(scale):
    d = material_box({"type": "diffuse"})
    d["integrator"]["type"] = "volpath"
    d["fog"] = {"type": "homogeneous", "sigma_t": 0.25, "albedo": 0.7}
    d["sensor"]["medium"] = {"type": "ref", "id": "fog"}
    # The fog fills a sphere around the whole scene (rays leaving the box exit it).
    d["atmosphere"] = {"type": "sphere", "radius": 20.0, "bsdf": {"type": "null"},
                       "interior": {"type": "ref", "id": "fog"}}
    _check(compare_with_mitsuba(d, scale), "camera in medium")


def test_wrong_albedo_fails_the_comparison():
    """Must-fail: an albedo 0.95 instead of 0.8 in pbr is detected (the ball is a small part
    of the image, so smaller changes hide in the noise of the image mean)."""
    d = fog_ball({"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.8})
    ref = fog_ball({"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.95})
    scene = pbr.load_dict(ref)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))  # noqa: E731
    res = validate.compare_renders(fa, validate.mitsuba_render_fn(d), spp=1024, batches=16, seed_a=21, seed_b=22)
    print(res)
    assert not res.passed


# -- checks without a reference ------------------------------------------------------------
def _render(d, spp, seed=0):
    return np.asarray(pbr.render(pbr.load_dict(d), spp=spp, seed=seed))


def _prbvolpath_vs_volpath(make, sabotage=None):
    """prbvolpath (its primal image) against volpath, two independent estimators."""
    d_prb = make("prbvolpath")
    if sabotage:
        sabotage(d_prb)
    s_ref, s_prb = pbr.load_dict(make("volpath")), pbr.load_dict(d_prb)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(s_ref, seed=seed, spp=spp))  # noqa: E731
    fb = lambda seed=0, spp=0: np.asarray(pbr.render(s_prb, seed=seed, spp=spp))  # noqa: E731
    return validate.compare_renders(fa, fb, spp=256, batches=8)


def _hg_ball(integrator):
    return fog_ball({"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.8, "phase": {"type": "hg", "g": 0.6}},
                    integrator=integrator)


@pytest.mark.parametrize("kind", ["homogeneous", "grid"])
def test_prbvolpath_primal_agrees_with_volpath(kind, tmp_path):
    if kind == "homogeneous":
        make = _hg_ball
    else:
        write_vol(str(tmp_path / "blob.vol"), blob())

        def make(integrator):
            d = grid_cube(str(tmp_path / "blob.vol"))
            d["integrator"]["type"] = integrator
            return d
    _check(_prbvolpath_vs_volpath(make), f"prbvolpath vs volpath ({kind})")


def test_prbvolpath_wrong_albedo_fails():
    """Must-fail for the comparison above: albedo 0.95 instead of 0.8 in prbvolpath."""
    def sabotage(d):
        d["ball"]["interior"]["albedo"] = 0.95
    res = _prbvolpath_vs_volpath(_hg_ball, sabotage)
    print(res)
    assert not res.passed


def test_majorant_grid_changes_cost_not_result(tmp_path, monkeypatch):
    """The 16^3 majorant grid and a single global majorant give the same expectation."""
    import pbr.media.mediumset as media
    vol = str(tmp_path / "blob.vol")
    write_vol(vol, blob())
    d = grid_cube(vol)
    est = {}
    for res in (1, 16):
        monkeypatch.setattr(media, "MAJORANT_RES", res)
        monkeypatch.setattr(pbr.media.majorant, "MAJORANT_RES", res)
        est[res] = validate.estimate(lambda seed=0, spp=0: _render(d, spp, seed), spp=256, batches=8, seed=res)
    res = validate.compare(*est[1], *est[16])
    print(res)
    assert res.passed


def sky_ball(medium, integrator, max_depth=4, res=16):
    """A medium ball over a diffuse floor under a uniform sky: every estimator finds the
    light by phase/BSDF sampling alone (no rare events for the z-test)."""
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "integrator": {"type": integrator, "max_depth": max_depth},
            "sensor": {"type": "perspective", "fov": 35,
                       "to_world": T().look_at(origin=[0, 1.0, 4.0], target=[0, 0.2, 0], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
            "sky": {"type": "constant", "radiance": 1.0},
            "floor": {"type": "rectangle", "to_world": T().translate([0, -0.6, 0]).rotate([1, 0, 0], -90).scale(3),
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.5, 0.3]}}},
            "ball": {"type": "sphere", "radius": 0.6, "bsdf": {"type": "null"}, "interior": medium}}


def test_simplevolpath_agrees_with_volpath(scale):
    med = {"type": "homogeneous", "sigma_t": {"type": "rgb", "value": [0.2, 0.5, 0.9]}, "scale": 5.0, "albedo": 0.9}
    a, b = sky_ball(med, "volpath"), sky_ball(med, "simplevolpath")
    fa = lambda seed=0, spp=0: _render(a, spp, seed)  # noqa: E731
    fb = lambda seed=0, spp=0: _render(b, spp, seed)  # noqa: E731
    res = validate.compare_renders(fa, fb, spp=1024 * scale, batches=16)
    print(res)
    assert res.passed


def test_volpath_beats_simplevolpath_on_chromatic_medium():
    """A strongly chromatic medium: volpath (light sampling, spectral MIS) has a much lower
    pixel variance than simplevolpath (hero wavelength only, no light sampling) at equal
    sample count. (The effect of spectral MIS alone, against Mitsuba's hero-wavelength
    volpath, is measured in benchmarks/bench_volpath.py.)"""
    med = {"type": "homogeneous", "sigma_t": {"type": "rgb", "value": [0.05, 0.3, 1.0]}, "scale": 10.0, "albedo": 0.95}
    var = {}
    for integ in ("volpath", "simplevolpath"):
        d = sky_ball(med, integ)
        _, v = validate.estimate(lambda seed=0, spp=0: _render(d, spp, seed), spp=64, batches=8)
        var[integ] = float(np.mean(v))
    print(var)
    assert var["volpath"] < 0.5 * var["simplevolpath"]


@pytest.mark.parametrize("sigma_t,albedo,g", [(1e-4, 0.5, 0.0), (1e4, 0.5, 0.0), (30.0, 1.0, 0.99),
                                              (30.0, 0.0, -0.99), (1e4, 1.0, -0.99)])
def test_extremes_are_finite_and_terminate(sigma_t, albedo, g):
    d = fog_ball({"type": "homogeneous", "sigma_t": sigma_t, "albedo": albedo,
                  "phase": {"type": "hg", "g": g}}, max_depth=64)
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 12
    scene = pbr.load_dict(d)
    img = np.asarray(pbr.render(scene, spp=16))
    # (linear sRGB of saturated spectra may be slightly negative: no sign check)
    assert np.all(np.isfinite(img)) and img.mean() > 0
    assert scene.integrator.capped == 0


def test_null_collision_bound_is_reported(tmp_path):
    """A medium whose majorant is far above its density makes many null collisions;
    with a tiny bound they are cut off and reported, not looped on forever."""
    g = np.full((4, 4, 4), 1e-3, np.float32)
    g[0, 0, 0] = 1e4    # one dense voxel: the whole-grid majorant is huge
    d = fog_ball({"type": "heterogeneous", "sigma_t": {"type": "gridvolume", "data": g}})
    d["integrator"]["max_null_collisions"] = 2
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 8
    del d["ball"]
    T = mi.ScalarTransform4f
    d["cube"] = {"type": "cube", "to_world": T().translate([0.5, 0.5, 0.5]).scale(0.5), "bsdf": {"type": "null"},
                 "interior": d.pop("fog", None) or {"type": "heterogeneous",
                                                    "sigma_t": {"type": "gridvolume", "data": g}}}
    scene = pbr.load_dict(d)
    with pytest.warns(RuntimeWarning, match="max_null_collisions"):
        img = np.asarray(pbr.render(scene, spp=8))
    assert np.all(np.isfinite(img)) and scene.integrator.capped > 0


# -- building blocks -----------------------------------------------------------------------
def test_vol_file_round_trip_and_mitsuba_reads_it(tmp_path):
    g = np.random.default_rng(3).random((3, 4, 5, 3)).astype(np.float32)
    path = str(tmp_path / "g.vol")
    write_vol(path, g, bbox=((0, 0, 0), (2, 1, 1)))
    data, bbox = read_vol(path)
    assert np.array_equal(data, g) and np.allclose(bbox, [[0, 0, 0], [2, 1, 1]])
    mi.set_variant(validate.mitsuba_variant())
    vg = mi.VolumeGrid(path)
    assert tuple(vg.size()) == (5, 4, 3) and vg.channel_count() == 3
    assert np.allclose(np.array(vg), g)


def test_cell_maxima_bound_trilinear_values():
    rng = np.random.default_rng(1)
    g = rng.random((7, 11, 5)) ** 4
    cm = cell_maxima(g, 16)
    nz, ny, nx = g.shape
    p = rng.random((20000, 3))
    x = p * np.array([nx, ny, nz]) - 0.5
    i0 = np.floor(x).astype(int)
    f = x - i0
    v = 0
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = (f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1]) * (f[:, 2] if dz else 1 - f[:, 2])
                v = v + w * g[np.clip(i0[:, 2] + dz, 0, nz - 1), np.clip(i0[:, 1] + dy, 0, ny - 1),
                              np.clip(i0[:, 0] + dx, 0, nx - 1)]
    c = np.minimum((p * 16).astype(int), 15)
    assert np.all(v <= cm[c[:, 2], c[:, 1], c[:, 0]] + 1e-9)
    assert cm.mean() < 0.8 * g.max()     # tighter than the global bound


@pytest.mark.parametrize("phase", [{"type": "isotropic"}, {"type": "hg", "g": 0.7}, {"type": "hg", "g": -0.4},
                                   {"type": "rayleigh"}])
def test_phase_function_sampling_chi2(phase):
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    from pbr.phase import HG, RAYLEIGH, phase_eval, phase_sample
    mi.set_variant(validate.mitsuba_variant())
    kind = RAYLEIGH if phase["type"] == "rayleigh" else HG
    g = phase.get("g", 0.0)
    wo = mi.Vector3f(0.3, -0.2, 0.932)
    wo = wo / float(np.linalg.norm([0.3, -0.2, 0.932]))

    def sample(u):
        wi, _ = phase_sample(mi.UInt32(kind), mi.Float(g), wo, mi.Point2f(u), {kind})
        return wi

    def pdf(wi):
        return phase_eval(mi.UInt32(kind), mi.Float(g), wo, wi, {kind})

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=2,
                         sample_count=200_000, res=101)
    assert test.run(), test.messages


def test_medium_errors():
    from pbr.plugins.props import SceneError
    bad = [({"type": "homogeneous", "albedo": 1.5}, "albedo"),
           ({"type": "homogeneous", "sigma_t": -1.0}, "sigma_t"),
           ({"type": "homogeneous", "sigma_t": 1.0, "sigma_a": 1.0}, "sigma_a"),
           ({"type": "heterogeneous", "sigma_t": {"type": "gridvolume"}}, "sigma_t"),
           ({"type": "homogeneous", "phase": {"type": "hg", "g": 2.0}}, "g"),
           ({"type": "homogeneous", "sigmaa": 1.0}, "sigmaa")]
    for med, key in bad:
        with pytest.raises(SceneError, match=f"scene.ball.interior.*{key}"):
            pbr.load_dict(fog_ball(med))


# -- shadow rays toward a light close to a surface ----------------------------------------------
def _light_over_floor(integrator, height=0.1):
    """A floor lit by a downward-facing area light ``height`` above it, seen from the side:
    most of the image is direct light from a shadow ray that starts on the floor and ends
    on the nearby light."""
    T = mi.ScalarTransform4f
    return {"type": "scene", "integrator": {"type": integrator, "max_depth": 2},
            "sensor": {"type": "perspective", "fov": 40,
                       "to_world": T().look_at(origin=[0, 0.6, 3.0], target=[0, 0, 0], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 24, "height": 16, "rfilter": {"type": "box"}}},
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(2.0),
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.7]}}},
            "light": {"type": "rectangle", "to_world": T().translate([0, height, 0]).rotate([1, 0, 0], 90).scale(0.8),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [4.0, 4.0, 4.0]}}}}


@pytest.mark.parametrize("integrator", ["volpath", "prbvolpath"])
def test_shadow_rays_reach_a_light_close_to_a_surface(integrator):
    """volpath's shadow rays used to keep the direction from the unshifted hit point after
    the spawn offset, so they met the light's own surface just short of the sampled point
    and counted it as an occluder: 0.48 of path's image with the light 0.1 above the
    floor. Compared with path (another estimator, whose shadow test is Mitsuba's)."""
    s_path, s_vol = pbr.load_dict(_light_over_floor("path")), pbr.load_dict(_light_over_floor(integrator))
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(s_path, seed=seed, spp=spp))  # noqa: E731
    fb = lambda seed=0, spp=0: np.asarray(pbr.render(s_vol, seed=seed, spp=spp))  # noqa: E731
    res = validate.compare_renders(fa, fb, spp=256, batches=8)
    _check(res, f"{integrator} vs path, light 0.1 above the floor")


def test_gridvolume_accepts_mitsuba_volumegrid():
    """Mitsuba's tutorials build a grid as ``'grid': mi.VolumeGrid(tensor)``; pbr reads it
    as it reads ``'data'`` (same scene parameter, same image)."""
    g = blob(8)
    vg = mi.VolumeGrid(mi.TensorXf(g[..., None]))     # (in pbr's variant: the backend under test)
    imgs = []
    for key, value in (("grid", vg), ("data", g)):
        d = fog_ball({"type": "heterogeneous", "sigma_t": {"type": "gridvolume", key: value}})
        d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 8
        scene = pbr.load_dict(d)
        params = pbr.traverse(scene)
        np.testing.assert_array_equal(np.asarray(params["ball.interior_medium.sigma_t.data"])[..., 0], g)
        imgs.append(np.asarray(pbr.render(scene, spp=4)))
    np.testing.assert_array_equal(imgs[0], imgs[1])
