"""Next-event estimation traces a shadow ray only where the light sample's unoccluded
contribution is nonzero (pbrt-v4's ``SampleLd`` order; ``integrators.base.light_reaches``),
except in derivative passes, where a contribution of zero may still have a derivative."""

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr

T = lambda: mi.ScalarTransform4f  # noqa: E731


def _floor_scene(light_below: bool, reflectance=0.5, integrator="path"):
    """A one-sided diffuse floor (normal +z) seen from above, lit by a small area light
    facing it from above (outside the view), or (``light_below``) from below: there every light sample is
    behind the floor, where its BSDF is zero."""
    z, angle = (-1.0, 0.0) if light_below else (1.0, 180.0)
    return {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": 2} if integrator in ("path", "volpath", "prbvolpath", "bdpt") else {"type": integrator},
        "sensor": {"type": "perspective", "fov": 30.0,
                   "to_world": T().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "floor": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": reflectance}},
        "light": {"type": "rectangle", "to_world": T().translate([2, 0, z]).rotate([1, 0, 0], angle).scale(0.2),
                  "emitter": {"type": "area", "radiance": 30.0}},
    }


def _count_shadow_lanes(scene, **render):
    """(shadow-ray lanes traced in one render, the image)."""
    geo = scene.geometry
    count = dr.zeros(mi.UInt32, 1)
    orig = geo.occluded

    def occluded(ray, active):
        dr.scatter_reduce(dr.ReduceOp.Add, count, mi.UInt32(1), mi.UInt32(0), active)
        return orig(ray, active)

    geo.occluded = occluded
    try:
        img = np.asarray(pbr.render(scene, seed=1, progress=False, **render))
    finally:
        del geo.occluded
    return int(count[0]), img


@pytest.mark.parametrize("integrator", ["path", "direct", "whitted", "volpath", "prbvolpath"])
def test_no_shadow_ray_toward_a_light_behind_the_surface(integrator):
    n_above, img_above = _count_shadow_lanes(pbr.load_dict(_floor_scene(False, integrator=integrator)))
    n_below, img_below = _count_shadow_lanes(pbr.load_dict(_floor_scene(True, integrator=integrator)))
    print(f"{integrator}: shadow-ray lanes with the light above {n_above}, below {n_below}")
    # 8 x 8 pixels, 4 spp: every camera ray hits the floor and samples the light.
    assert n_above == 256 and img_above.mean() > 0.01
    assert n_below == 0 and img_below.max() == 0.0


@pytest.mark.parametrize("integrator, module", [("bdpt", "bdpt"), ("ptracer", "lightpath")])
def test_light_paths_connect_only_where_both_ends_scatter(monkeypatch, integrator, module):
    """bdpt's light sample (s = 1) and connections (light subpaths to the camera's
    vertices, light vertices to the camera), and the light tracer's connections to the
    camera: a point light under the floor lights only its back, so no connection needs a
    shadow ray; with the check removed they are traced (and the image is the same, black)."""
    import importlib
    d = _floor_scene(True, integrator=integrator)
    d["light"] = {"type": "point", "position": [0.3, 0.2, -1.0], "intensity": 10.0}
    n_skip, img_skip = _count_shadow_lanes(pbr.load_dict(d))
    monkeypatch.setattr(importlib.import_module(f"pbr.integrators.{module}"), "nonzero_estimate",
                        lambda contribution, em: em)
    n_all, img_all = _count_shadow_lanes(pbr.load_dict(d))
    print(f"{integrator}: shadow-ray lanes {n_skip}, without the check {n_all}")
    assert n_skip == 0 and n_all > 0
    assert np.array_equal(img_skip, img_all) and img_skip.max() == 0.0


def test_blocked_or_not_the_image_is_unchanged(monkeypatch):
    """Only lanes whose estimate is zero go without a shadow ray: the same scene rendered
    with every light sample tested (``nonzero_estimate`` passing every sampled lane) gives
    the same image, bit for bit."""
    from pbr.integrators import path
    d = pbr.cornell_box(16, 8)
    d["integrator"] = {"type": "path", "max_depth": 4}
    n_skip, img_skip = _count_shadow_lanes(pbr.load_dict(d))
    monkeypatch.setattr(path, "nonzero_estimate", lambda contribution, em: em)
    n_all, img_all = _count_shadow_lanes(pbr.load_dict(d))
    print(f"Cornell box: shadow-ray lanes {n_skip} (every sampled lane: {n_all})")
    assert n_skip < 0.95 * n_all
    assert np.array_equal(img_skip, img_all)


@pytest.mark.parametrize("integrator", ["path", "prbvolpath"])
def test_zero_reflectance_keeps_its_derivative(integrator):
    """A reflectance of 0 makes every light sample's estimate 0 but not its derivative:
    derivative passes trace those shadow rays. With direct light only (max_depth 2) the
    image is linear in the reflectance, so d image / d reflectance at 0 is the image at 1
    (the same samples: ``seed_grad`` = ``seed``), shadow included."""
    d = _floor_scene(False, reflectance=0.0, integrator=integrator)
    # An occluder out of view that shadows part of the floor: the derivative must see it.
    d["occluder"] = {"type": "rectangle", "to_world": T().translate([1.2, 0, 0.5]).scale(0.3)}
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    key = "floor.bsdf.reflectance.value"
    assert key in params, list(params.keys())
    v = params[key]
    dr.enable_grad(v)
    params.update()
    img = pbr.render(scene, params, spp=4, seed=1, seed_grad=1)
    dr.forward(v)
    fwd = np.asarray(dr.grad(img), np.float64)
    params[key] = type(v)(1.0)
    params.update()
    one = np.asarray(pbr.render(scene, spp=4, seed=1, progress=False), np.float64)
    print(f"d image / d reflectance: mean {fwd.mean():.5f}; image at reflectance 1: mean {one.mean():.5f}")
    assert one.mean() > 0.01
    assert fwd.mean() == pytest.approx(one.mean(), rel=1e-3)
