"""Gradients of ``prb`` and ``prbvolpath`` against finite differences, parameter by
parameter, with Mitsuba's AD-integrator metric (see grad_harness): albedo, roughness,
IOR, emitter radiance, environment-map texels, a homogeneous medium's sigma_t and
albedo, and one voxel of a density grid; forward and reverse mode."""

import numpy as np
import drjit as dr
import mitsuba as mi
import pytest

import pbr
from grad_harness import (BWD_ERR, FWD_MEAN_ERR, backward_error, backward_gradient, fd_image, forward_error,
                          forward_image, projection)
from mitsuba_scenes import lit_box, material_box

RES = 16


def _box(small, large=None, lighting="area", integrator="prb", max_depth=4):
    d = lit_box(small, large, lighting) if lighting != "area" else material_box(small, large)
    for k in ("sensor",):
        d[k]["film"]["width"] = d[k]["film"]["height"] = RES
    d["integrator"] = {"type": integrator, "max_depth": max_depth}
    return d


def _fog(medium):
    d = _box({"type": "diffuse"}, integrator="prbvolpath")
    d["ball"] = {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.35, "bsdf": {"type": "null"},
                 "interior": medium}
    return d


def _density(n=6):
    z, y, x = np.mgrid[0:n, 0:n, 0:n] / (n - 1.0)
    return (1.0 + 4.0 * np.exp(-((x - 0.5) ** 2 + (y - 0.5) ** 2 + (z - 0.5) ** 2) / 0.1)).astype(np.float32)


def _grid():
    T = mi.ScalarTransform4f
    d = _box({"type": "diffuse"}, integrator="prbvolpath")
    c, h = [0.1, 0.55, 0.1], 0.3
    d["cloud"] = {"type": "cube", "to_world": T().translate(c).scale(h), "bsdf": {"type": "null"},
                  "interior": {"type": "heterogeneous", "albedo": 0.8,
                               "sigma_t": {"type": "gridvolume", "data": mi.TensorXf(_density()[..., None]),
                                           "to_world": T().translate([x - h for x in c]).scale(2 * h)}}}
    return d


def _voxel_tangent(params, key):
    t = np.zeros(params[key].shape, np.float32)
    t[2:4, 2:4, 2:4, 0] = 1.0
    return mi.TensorXf(t)


def _texel_tangent(params, key):
    rng = np.random.default_rng(3)
    return mi.TensorXf(rng.uniform(0.0, 1.0, params[key].shape).astype(np.float32))


# name: (scene dict factory, key, tangent factory, eps, fd spp, ad spp)
CASES = {
    "albedo": (lambda: _box({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.5, 0.7]}}),
               "small-box.bsdf.reflectance.value", lambda p, k: mi.Color3f(1, 1, 1), 0.02, 8192, 2048),
    "roughness": (lambda: _box({"type": "roughconductor", "alpha": 0.25, "material": "Au"}, lighting="point"),
                  "small-box.bsdf.alpha.value", lambda p, k: mi.Float(1.0), 0.01, 8192, 2048),
    "ior": (lambda: _box({"type": "roughdielectric", "alpha": 0.3, "int_ior": 1.5}, lighting="point"),
            "small-box.bsdf.eta", lambda p, k: mi.Float(1.0), 0.02, 8192, 2048),
    "emitter": (lambda: _box({"type": "diffuse"}), "light.emitter.radiance.value",
                lambda p, k: mi.Color3f(1, 0.5, 0.2), 0.5, 4096, 1024),
    "envmap": (lambda: _box({"type": "roughconductor", "alpha": 0.2, "material": "Al"}, lighting="envmap"),
               "sky.data", _texel_tangent, 0.05, 8192, 2048),
    "sigma_t": (lambda: _fog({"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.8}),
                "ball.interior.sigma_t.value", lambda p, k: mi.Float(1.0), 0.05, 8192, 2048),
    "medium_albedo": (lambda: _fog({"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.6}),
                      "ball.interior.albedo.value", lambda p, k: mi.Float(1.0), 0.02, 8192, 2048),
    "grid_voxel": (_grid, "cloud.interior.sigma_t.data", _voxel_tangent, 1.0, 8192, 2048),
}


# Forward mode is tested where it is known to work (RGB albedo, emitter radiance). For
# the other parameters the forward derivative must cross into the rendering loop's AD
# scope from a table built outside it: Dr.Jit 1.5 refuses that for path ("forward-
# propagate derivatives across edge ... outside of the current dr.isolate_grad() scope")
# and the envmap texels even come out as a silent zero image. Reverse mode (what
# optimisation uses) is tested for every parameter.
FORWARD_OK = {"albedo", "emitter"}


def _setup(name):
    make, key, tangent, eps, spp_fd, spp_ad = CASES[name]
    scene = pbr.load_dict(make())
    params = pbr.traverse(scene)
    assert key in params, list(params.keys())
    tan = tangent(params, key)
    ref = fd_image(scene, params, key, tan, eps, spp_fd)
    assert np.abs(ref).mean() > 1e-4, f"{name}: the parameter does not change the image"
    return scene, params, key, tan, ref, spp_ad, (make, eps, spp_fd)


# Measured and not yet explained (so not hidden): the IOR of a rough dielectric (reverse
# mode 0.507 vs finite differences 0.417) and a block of grid voxels (0.0313 vs 0.0239).
# Suspects: boundaries of the refraction half-vector's valid region moving with eta (a
# discontinuity that detached sampling cannot differentiate), and the grid's trilinear
# lookup derivative. The strict xfail notices when they are fixed.
REVERSE_OPEN = {"ior", "grid_voxel"}


@pytest.mark.parametrize("name", [n if n not in REVERSE_OPEN else pytest.param(
    n, marks=pytest.mark.xfail(raises=AssertionError, strict=True, reason="open gradient discrepancy"))
    for n in CASES])
def test_reverse_mode_matches_finite_differences(name):
    scene, params, key, tan, ref, spp, (make, eps, spp_fd) = _setup(name)
    w = projection(fd_image(scene, params, key, tan, eps, spp_fd // 2, seed=5000))
    g = backward_gradient(scene, params, key, tan, spp, w)
    err = backward_error(g, ref, w)
    print(f"{name}: d loss: finite differences {np.sum(w * ref):.5g}, reverse mode {g:.5g} (error {err:.4f})")
    assert err < BWD_ERR, (name, err)


@pytest.mark.parametrize("name", sorted(FORWARD_OK))
def test_forward_mode_matches_finite_differences(name):
    scene, params, key, tan, ref, spp, _ = _setup(name)
    fwd = forward_image(scene, params, key, tan, spp)
    err = forward_error(fwd, ref)
    print(f"{name}: forward image mean {fwd.mean():.5g} vs {ref.mean():.5g}, per-pixel error {err:.4f}")
    assert err < FWD_MEAN_ERR, (name, err)
