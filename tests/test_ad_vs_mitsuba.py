"""Reverse-mode gradients of pbr (``prb``, ``prbvolpath``) against Mitsuba 3's
(``llvm_ad_spectral``) on the same scene dicts, parameter by parameter.

For each parameter theta (along a tangent t) both renderers estimate the scalar
g = d/d theta <w, image> with a fixed positive weight image w (a smooth pattern, or for
roughness a pbr render of the scene), from ``K`` independent batches (seed and
seed_grad new in every batch and different between the renderers); g_pbr and g_mi must
agree within ``Z_MAX`` combined standard errors (|g_pbr - g_mi| / sqrt(se_pbr^2 +
se_mi^2)). With Welch's t at 14-22 degrees of freedom, 4 keeps the chance that one of
the eight cases fails by chance near 1% (Bonferroni). Must-fail checks: every case must
also detect pbr's gradient times 1.1, and a reproduction of a fixed bug (one roughness
axis) must fail. Scenes: tests/grad_scenes.py and the Cornell-box material scenes.

Parameters differ where the plugins store different things. Mitsuba nests a medium as
``<shape>.interior_medium`` and its constant coefficients as ``.value.value``. Its
spectral variant keeps an RGB reflectance as the sigmoid coefficients c = fetch(rgb)
(``<bsdf>.reflectance.value``), and an RGB emitter as c = fetch(rgb / s), s = 2 max(rgb),
with s folded into the D65 table (``<emitter>.radiance.d65.values``); pbr's parameter
is the RGB itself. An RGB tangent t therefore maps to the coefficient tangent J t (J:
the Jacobian of Mitsuba's ``srgb_model_fetch``, by central differences), and for the
emitter also to the relative change of s. Its envmap stores per texel coefficients and
a scale (plus one wrap-around column on each side): the envmap tangent is "scale a
block of texels' RGB" in pbr and "scale their scale channel" in Mitsuba.
"""

from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr import validate
from grad_scenes import RES, backlit_cloud, backlit_medium, glass_backdrop, metal_floor, voxel_block
from mitsuba_scenes import lit_box, material_box

Z_MAX = 4.0
SABOTAGE = 1.1            # a gradient 10% too large must be detected


def weights(h=RES, w=RES) -> np.ndarray:
    """A smooth positive weight image (H, W, 3)."""
    y, x = np.mgrid[0:h, 0:w] / max(h - 1, 1)
    base = 0.6 + 0.4 * np.sin(3.0 * x + 1.0) * np.cos(2.0 * y)
    return (base[..., None] * np.array([1.0, 0.8, 0.6])).astype(np.float32)


# -- scenes ---------------------------------------------------------------------------------
def _small(d, integrator="prb", max_depth=4):
    """A Cornell-box scene at RES x RES with a short ``prb`` and hidden emitters."""
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = RES
    d["integrator"] = {"type": integrator, "max_depth": max_depth, "hide_emitters": True}
    return d


def sky_box(bsdf_small):
    """material_box open at the front, back and top, under a uniform (constant) sky."""
    d = material_box(bsdf_small)
    del d["light"], d["back"], d["ceiling"]
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 0.9, 0.8]}}
    return d


def _mitsuba_dict(d):
    """pbr-only integrator options removed."""
    d = dict(d)
    d["integrator"] = {k: v for k, v in d["integrator"].items() if k != "majorant_factor"}
    return d


# -- tangents (pbr params, Mitsuba params) -> arrays ------------------------------------------
def _const(*v):
    return lambda params, key: np.array(v, np.float64)


def _fetch_jacobian(rgb, h=1e-3):
    """d fetch(rgb) / d rgb (3x3) of Mitsuba's RGB-to-sigmoid-coefficient table."""
    J = np.zeros((3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        hi = np.array(mi.srgb_model_fetch(mi.ScalarColor3f(*(rgb + e))))
        lo = np.array(mi.srgb_model_fetch(mi.ScalarColor3f(*(rgb - e))))
        J[:, j] = (hi - lo) / (2 * h)
    return J


def _albedo_mi(rgb, t):
    return lambda params, key: {key: _fetch_jacobian(np.array(rgb)) @ np.array(t)}


def _emitter_mi(rgb, t):
    """Mitsuba's d65 spectrum: coefficients of rgb / s and the scale s in the D65 table."""
    def tangent(params, key):
        rgb_, t_ = np.array(rgb, np.float64), np.array(t, np.float64)
        k = int(np.argmax(rgb_))
        s, ds = 2 * rgb_[k], 2 * t_[k]
        dc = _fetch_jacobian(rgb_ / s) @ (t_ / s - rgb_ * ds / s ** 2)
        d65 = key.rsplit(".", 1)[0] + ".d65.values"
        return {key: dc, d65: np.asarray(params[d65], np.float64) * (ds / s)}
    return tangent


def _envmap_block_pbr(params, key):
    """Relative scaling of a block of texels: the tangent is their own RGB."""
    rgb = np.asarray(params[key], np.float64)
    t = np.zeros_like(rgb)
    t[4:8, 8:14] = rgb[4:8, 8:14]
    return t


def _envmap_block_mi(params, key):
    """The same change in Mitsuba's layout: channel 3 (the scale), one padding column."""
    data = np.asarray(params[key], np.float64)
    t = np.zeros_like(data)
    t[4:8, 9:15, 3] = data[4:8, 9:15, 3]
    return t


def _voxels(params, key):
    return voxel_block(tuple(params[key].shape)).astype(np.float64)


ALBEDO = [0.3, 0.5, 0.7]
LIGHT = [18.387, 13.9873, 6.75357]      # pbr.cornell_box()'s light (Mitsuba's Cornell box)
T_RGB = [1.0, 0.5, 0.2]

# name: (scene factory, pbr key, Mitsuba key, pbr tangent, Mitsuba tangent, spp, K, weights)
# weights: None (the smooth pattern) or "image" (image_weights)
HOMOGENEOUS = {"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.6}
CASES = {
    "albedo": (lambda: _small(material_box({"type": "diffuse", "reflectance": {"type": "rgb", "value": ALBEDO}})),
               "small-box.bsdf.reflectance.value", "small-box.bsdf.reflectance.value",
               _const(*T_RGB), _albedo_mi(ALBEDO, T_RGB), 128, 8, None),
    # BSDF sampling alone: under a uniform sky through the open box (the ceiling light
    # would be found too rarely for a 10% error to show at this budget); a grey albedo (a
    # uniform spectrum, the same parameter in both renderers: no RGB-to-coefficient map).
    "albedo_prb_basic": (lambda: _small(sky_box({"type": "diffuse", "reflectance": 0.5}), "prb_basic"),
                         "small-box.bsdf.reflectance.value", "small-box.bsdf.reflectance.value",
                         _const(1.0), _const(1.0), 256, 8, None),
    "roughness": (lambda: metal_floor(), "floor.bsdf.alpha.value", "floor.bsdf.alpha.value",
                  _const(1.0), _const(1.0), 256, 8, "image"),
    "ior": (lambda: glass_backdrop(), "glass.bsdf.eta", "glass.bsdf.eta", _const(1.0), _const(1.0), 1024, 12, None),
    "emitter": (lambda: _small(material_box({"type": "diffuse"})), "light.emitter.radiance.value",
                "light.emitter.radiance.value", _const(*T_RGB), _emitter_mi(LIGHT, T_RGB), 32, 8, None),
    "envmap": (lambda: _small(lit_box({"type": "roughconductor", "alpha": 0.2, "material": "Al"}, lighting="envmap")),
               "sky.data", "sky.data", _envmap_block_pbr, _envmap_block_mi, 128, 8, None),
    "sigma_t": (lambda: backlit_medium(HOMOGENEOUS), "cloud.interior_medium.sigma_t.value.value",
                "cloud.interior_medium.sigma_t.value.value", _const(1.0), _const(1.0), 128, 8, None),
    "medium_albedo": (lambda: backlit_medium(HOMOGENEOUS), "cloud.interior_medium.albedo.value.value",
                      "cloud.interior_medium.albedo.value.value", _const(1.0), _const(1.0), 128, 8, None),
    "grid_voxel": (lambda: backlit_cloud(), "cloud.interior_medium.sigma_t.data", "cloud.interior_medium.sigma_t.data",
                   _voxels, _voxels, 512, 12, None),
}


def image_weights(d, spp=256):
    """Weights that follow the image itself (a pbr render, its own seed): for
    parameters that mostly move light around (roughness), where a smooth pattern sees
    little net change."""
    img = np.asarray(pbr.render(pbr.load_dict(d), spp=spp, seed=999), np.float64)
    return (img / img.mean()).astype(np.float32)


def gradient_batches(renderer, d, key, tangent, spp, K, seed0, w=None):
    """K independent estimates of d <w, image> / d theta along ``tangent``."""
    if renderer == "pbr":
        scene = pbr.load_dict(d)
        params, render = pbr.traverse(scene), pbr.render
    else:
        validate.mitsuba_variant()
        scene = mi.load_dict(_mitsuba_dict(d))
        params, render = mi.traverse(scene), mi.render
    W = mi.TensorXf(weights() if w is None else w)
    t = tangent(params, key)
    t = t if isinstance(t, dict) else {key: t}
    v0 = {k: type(params[k])(params[k]) for k in t}
    out = []
    for i in range(K):
        # Fresh leaves, assigned (Mitsuba rebuilds derived tables, e.g. the envmap's
        # texture, only for keys that were assigned).
        leaves = {k: type(v0[k])(v0[k]) for k in t}
        for k, v in leaves.items():
            dr.enable_grad(v)
            params[k] = v
        params.update()
        img = render(scene, params, spp=spp, seed=seed0 + i, seed_grad=seed0 + 1000 + i)
        dr.backward(dr.sum(img * W, axis=None))
        out.append(sum(float(np.dot(np.asarray(dr.grad(v), np.float64).ravel(), np.ravel(t[k])))
                       for k, v in leaves.items()))
    for k in t:
        params[k] = type(v0[k])(v0[k])
    params.update()
    return np.array(out)


def z_score(a, b, scale_a=1.0):
    a = a * scale_a
    se2 = a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b)
    return abs(a.mean() - b.mean()) / np.sqrt(se2)


_RESULTS = {}


def _estimate(name, scale=1):
    """(pbr batches, Mitsuba batches, pbr seconds, Mitsuba seconds); ``scale`` multiplies
    spp and K (the slow variant)."""
    if (name, scale) not in _RESULTS:
        make, kp, km, tp, tm, spp, K, wk = CASES[name]
        t0 = time.time()
        w = image_weights(make()) if wk == "image" else None
        gp = gradient_batches("pbr", make(), kp, tp, spp * scale, K * scale, seed0=10, w=w)
        t1 = time.time()
        gm = gradient_batches("mitsuba", make(), km, tm, spp * scale, K * scale, seed0=50_000, w=w)
        _RESULTS[name, scale] = (gp, gm, t1 - t0, time.time() - t1)
    return _RESULTS[name, scale]


def _check(name, scale):
    gp, gm, tp, tm = _estimate(name, scale)
    z, zs = z_score(gp, gm), z_score(gp, gm, SABOTAGE)
    se_p, se_m = gp.std(ddof=1) / np.sqrt(len(gp)), gm.std(ddof=1) / np.sqrt(len(gm))
    print(f"{name}: pbr {gp.mean():.5g} +- {se_p:.2g} ({tp:.1f} s), Mitsuba {gm.mean():.5g} +- {se_m:.2g} "
          f"({tm:.1f} s), z {z:.2f}; pbr x{SABOTAGE}: z {zs:.2f}")
    assert z < Z_MAX, (name, z)
    # Must fail: the same comparison detects a gradient 10% too large.
    assert zs > Z_MAX, (name, "a 10% error would not be detected", zs)


@pytest.mark.parametrize("name", list(CASES))
def test_gradient_matches_mitsuba(name):
    _check(name, 1)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_gradient_matches_mitsuba_more_samples(name):
    _check(name, 4)


def test_one_roughness_axis_is_detected():
    """Must fail, a bug that was there: an isotropic roughconductor kept alpha_u and
    alpha_v in two texture slots under one key, so the parameter ``alpha`` moved only
    one axis. Differentiating alpha_u alone reproduces it and must disagree with
    Mitsuba's isotropic d/d alpha."""
    make, kp, km, tp, tm, spp, K, wk = CASES["roughness"]
    gm = _estimate("roughness")[1]
    d = make()
    bsdf = d["floor"]["bsdf"]
    bsdf["alpha_u"] = bsdf["alpha_v"] = bsdf.pop("alpha")
    g_one = gradient_batches("pbr", d, "floor.bsdf.alpha_u.value", tp, spp, K, seed0=10, w=image_weights(make()))
    z = z_score(g_one, gm)
    print(f"alpha_u only: pbr {g_one.mean():.5g} vs Mitsuba (alpha) {gm.mean():.5g}: z {z:.1f}")
    assert z > Z_MAX, z
