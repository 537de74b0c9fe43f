"""Derivatives of RGB albedos where the RGB-to-spectrum lookup has special cases: greys
(r = g = b, where the three dominant-channel tables meet and pbr uses the exact flat
solution), black and white (the ends of [0, 1]), and a colour next to grey. Every
channel is differentiated, in forward and reverse mode, against finite differences of
the image (issue 18: a grey's derivative depended on r alone, [0.084, 0, 0] instead of
[0.039, 0.031, 0.014], and was 0 at black and white).

Must-fail checks, done once by hand: with the old grey branch (coefficients
``(0, 0, c2(r))``, clipped) the grey case gave d/dg = d/db = 0 (error 1.0) and black and
white gave 0 everywhere; with ``rgb_to_coeffs``'s clip back to ``dr.clip`` black's
derivative was 0 (and the roughness floor's); with the sigmoid's derivative left to
Dr.Jit, white's was wrong (the expression's derivative cancels at x = 8192); without
the unbounded form's case for black, black emission's derivative was 0."""

import numpy as np
import drjit as dr
import mitsuba as mi
import pytest

import pbr
from pbr import spectrum as S
from grad_harness import fd_image, forward_image
import grad_scenes

KEY = "white.reflectance.value"
SPP, SEEDS = 64, (0, 1, 2, 3)
WHITE_STEP = 1.0 / 63.0      # one table cell: the secant pbr takes at white

# (name, albedo, finite-difference step, side: 0 central, +1 forward, -1 backward, max_depth)
CASES = [
    ("grey", [0.5, 0.5, 0.5], 0.02, 0, 4),
    ("dark grey", [0.05, 0.05, 0.05], 0.01, 0, 4),
    ("near grey", [0.5, 0.5, 0.52], 0.02, 0, 4),
    ("white", [1.0, 1.0, 1.0], WHITE_STEP, -1, 4),
    # Black: direct light only; light off the coloured walls sees how the darkest
    # colours' spectra differ from a grey's change (docs/inverse.md: 28% at max_depth 4).
    ("black", [0.0, 0.0, 0.0], WHITE_STEP, 1, 2),
]


def _scene(max_depth):
    d = pbr.cornell_box(16, SPP)
    d["integrator"] = {"type": "prb", "max_depth": max_depth}
    scene = pbr.load_dict(d)
    return scene, pbr.traverse(scene)


@pytest.fixture(scope="module")
def scenes():
    return {m: _scene(m) for m in {c[4] for c in CASES}}


def _jacobians(scene, params, albedo, eps, side):
    """d mean(image) / d albedo: (3 channels of the albedo, 3 of the image), by finite
    differences and forward mode, with standard errors over seeds; and reverse mode's
    d mean(R) / d albedo."""
    params[KEY] = mi.Color3f(*map(float, albedo))
    params.update()
    fd, fwd = [], []
    for k in range(3):
        t = mi.Color3f(*[1.0 if j == k else 0.0 for j in range(3)])
        fd.append([fd_image(scene, params, KEY, t, eps, SPP, seed=s, side=side).mean(axis=(0, 1)) for s in SEEDS])
        fwd.append([forward_image(scene, params, KEY, t, SPP, seed=s + 100).mean(axis=(0, 1)) for s in SEEDS])
    fd, fwd = np.array(fd).transpose(1, 0, 2), np.array(fwd).transpose(1, 0, 2)    # (seed, k, c)
    rev = []
    for s in SEEDS:
        dr.enable_grad(params[KEY])
        params.update()
        img = pbr.render(scene, params, spp=SPP, seed=s + 200, seed_grad=s + 300)
        dr.backward(dr.mean(img[..., 0], axis=None))
        rev.append(np.array(dr.grad(params[KEY]), np.float64).ravel())
        params[KEY] = mi.Color3f(*map(float, albedo))
        params.update()
    se = lambda a: a.std(0) / np.sqrt(len(SEEDS))                       # noqa: E731
    return fd.mean(0), se(fd), fwd.mean(0), se(fwd), np.mean(rev, 0), se(np.array(rev))


@pytest.mark.parametrize("name, albedo, eps, side, max_depth", CASES, ids=[c[0] for c in CASES])
def test_every_channel_matches_finite_differences(scenes, name, albedo, eps, side, max_depth):
    scene, params = scenes[max_depth]
    fd, fd_se, fwd, fwd_se, rev, rev_se = _jacobians(scene, params, albedo, eps, side)
    scale = np.abs(fd).max()
    assert np.abs(fd.diagonal()).min() > 0.1 * scale, fd          # every channel matters
    tol = 0.05 * scale + 4 * np.hypot(fd_se, fwd_se)
    assert np.all(np.abs(fwd - fd) <= tol), (name, fwd, fd, tol)
    # Reverse mode: d mean(R) / d (r, g, b) is the first image channel of each row.
    tol_r = 0.05 * scale + 4 * np.hypot(fd_se[:, 0], rev_se)
    assert np.all(np.abs(rev - fd[:, 0]) <= tol_r), (name, rev, fd[:, 0], tol_r)


# ------------------------------------------------------------------ spectra alone

def _spectral_derivative(rgb, k, unbounded=False):
    """d S(l) / d rgb_k of the albedo (or unbounded) spectrum on a 1 nm grid (forward mode)."""
    lam = np.arange(360.0, 831.0)
    x = mi.Color3f(*map(float, rgb))
    dr.enable_grad(x)
    c, scale = S.rgb_unbounded(x) if unbounded else (S.rgb_to_coeffs(x), 1.0)
    L = mi.Float(lam.astype(np.float32))
    idx = dr.zeros(mi.UInt32, len(lam))
    s = S.sigmoid_polynomial(mi.Array3f(*[dr.gather(mi.Float, c[j], idx) for j in range(3)]), mi.Spectrum(L, L, L, L))
    s = s * dr.gather(mi.Float, mi.Float(scale), idx)
    dr.set_grad(x, mi.Color3f(*[1.0 if j == k else 0.0 for j in range(3)]))
    dr.enqueue(dr.ADMode.Forward, x)
    dr.traverse(dr.ADMode.Forward)
    return lam, np.array(dr.grad(s[0]), np.float64)


def _rgb_under_d65(lam, spectrum):
    """Linear sRGB of a reflectance spectrum lit by D65 (the colour space's white)."""
    xyz, d65 = S.cie_tables_np()
    grid = 360.0 + 5.0 * np.arange(95)
    cmf = np.stack([np.interp(lam, grid, xyz[:, j]) for j in range(3)], 1)
    illum = np.interp(lam, grid, d65)
    return S.XYZ_TO_SRGB @ ((cmf * (spectrum * illum)[:, None]).sum(0) / (illum * cmf[:, 1]).sum())


@pytest.mark.parametrize("v", [0.0, 1e-3, 0.2, 0.5, 0.8, 1.0])
def test_grey_spectrum_derivative_reproduces_each_channel(v):
    """Raising channel k of a grey changes the spectrum's colour (under the colour
    space's white) by e_k: the upsampling reproduces RGB, so must its derivative."""
    for k in range(3):
        lam, d = _spectral_derivative([v] * 3, k)
        rgb = _rgb_under_d65(lam, d)
        assert np.allclose(rgb, np.eye(3)[k], atol=0.03), (v, k, rgb)


@pytest.mark.parametrize("v", [0.3, 1.5, 4.0])
def test_unbounded_grey_derivative_reproduces_each_channel(v):
    """The unbounded form (an IOR's eta and k, emission) of a grey: 2 max(rgb) times the
    albedo form of rgb / (2 max(rgb)), itself a grey (0.5)."""
    for k in range(3):
        lam, d = _spectral_derivative([v] * 3, k, unbounded=True)
        rgb = _rgb_under_d65(lam, d)
        assert np.allclose(rgb, np.eye(3)[k], atol=0.03), (v, k, rgb)


def test_clamps_keep_the_derivative():
    """At and beyond a numerical clamp the derivative is the one at the bound."""
    x = mi.Float(-1.0, 0.0, 0.5, 1.0, 2.0)
    dr.enable_grad(x)
    y = S.clamp_keep_grad(x, 0.0, 1.0)
    dr.forward_from(x)
    assert np.allclose(np.array(y), [0, 0, 0.5, 1, 1]) and np.allclose(np.array(dr.grad(y)), 1.0)


def test_roughness_below_its_floor_has_the_floors_derivative():
    """Microfacet alpha is floored at 1e-4; below it the image is the floor's, and so is
    its derivative (it was 0)."""
    scene = pbr.load_dict(grad_scenes.metal_floor(alpha=1e-4, res=8))
    params = pbr.traverse(scene)
    key = "floor.bsdf.alpha.value"
    at_floor = forward_image(scene, params, key, mi.Float(1.0), spp=16)
    params[key] = mi.Float(1e-6)
    params.update()
    below = forward_image(scene, params, key, mi.Float(1.0), spp=16)
    assert np.abs(at_floor).sum() > 0
    assert np.array_equal(below, at_floor)


@pytest.mark.parametrize("alpha", [1.5e-4, 3e-4])
def test_roughness_derivative_near_specular_matches_finite_differences(alpha):
    """d mean(image) / d alpha of a near-specular Beckmann conductor, reverse mode (4 seeds)
    against central differences (+-20%, common random numbers). It was biased: -553/-514/-564
    at alpha 1.5e-4 and +113/+89/+105 at 3e-4 against differences of 0.70 and 2.09 (the
    Beckmann visible-normal sampler's quantised sin(theta); see test_microfacet's
    test_tiny_roughness_sampling_matches_pdf_score). Tolerance: 4 standard errors of the
    seeds' mean plus 2 for the differences' own noise."""
    scene = pbr.load_dict(grad_scenes.metal_floor(alpha=alpha, res=8))
    params = pbr.traverse(scene)
    key = "floor.bsdf.alpha.value"
    rev = []
    for s in range(4):
        params[key] = mi.Float(alpha)
        dr.enable_grad(params[key])
        params.update()
        img = pbr.render(scene, params, spp=1024, seed=s, seed_grad=s + 100)
        dr.backward(dr.mean(img, axis=None))
        rev.append(float(np.asarray(dr.grad(params[key])).ravel()[0]))
    ends = []
    for v in (1.2 * alpha, 0.8 * alpha):
        params[key] = mi.Float(v)
        params.update()
        ends.append(float(np.asarray(pbr.render(scene, spp=1024, seed=0)).mean()))
    fd = (ends[0] - ends[1]) / (0.4 * alpha)
    se = np.std(rev, ddof=1) / 2.0
    assert abs(np.mean(rev) - fd) < 4.0 * se + 2.0, (rev, fd)


def test_black_emission_has_a_derivative():
    """An RGB radiance of 0 (unbounded form, scale 0) has the derivative of raising all
    channels together (a flat spectrum); it was 0."""
    d = pbr.cornell_box(8, 16)
    d["light"]["emitter"]["radiance"] = {"type": "rgb", "value": [0.0, 0.0, 0.0]}
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    key = "light.emitter.radiance.value"
    t = mi.Color3f(1.0, 1.0, 1.0)
    # 4096 spp (8x8 pixels): at 64 and 1024 the finite difference alone is ~6% and ~3%
    # noisy, so the 5% test passed or failed with the seed; at 4096 they agree within 1.2%
    fwd = forward_image(scene, params, key, t, spp=4096).mean()
    fd = fd_image(scene, params, key, t, 1.0, 4096, seed=5, side=1).mean()
    assert fwd > 0 and abs(fwd - fd) < 0.05 * fd, (fwd, fd)


@pytest.mark.parametrize("key, rgb", [("eta", [1.5, 1.5, 1.5]), ("k", [2.0, 2.0, 2.0]), ("eta", [0.2, 0.9, 1.1])])
def test_conductor_rgb_eta_and_k_match_finite_differences(key, rgb):
    """A rough conductor's RGB eta and k (pbrt-v4's unbounded upsampling, where values
    above 1 count): d mean(image) / d channel, reverse mode against central differences
    on the same seeds, for greys (the case of issue 18) and a colour. (Mitsuba's default
    clamped form makes values above 1 act as 1: differences are 0 there, and pbr's
    derivative is the one at 1, docs/inverse.md.)"""
    d = pbr.cornell_box(16, 64)
    d["integrator"] = {"type": "prb", "max_depth": 4}
    values = {"eta": [1.5] * 3, "k": [2.0] * 3, key: rgb}
    d["white"] = {"type": "roughconductor", "alpha": 0.3,
                  **{n: {"type": "rgb", "value": v, "upsampling": "unbounded"} for n, v in values.items()}}
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    k, spp, eps, seeds = f"white.{key}.value", 128, 0.05, (0, 1)
    rev, fd = [], []
    for s in seeds:
        params[k] = mi.Color3f(*rgb)
        dr.enable_grad(params[k])
        params.update()
        img = pbr.render(scene, params, spp=spp, seed=s, seed_grad=s + 50)
        dr.backward(dr.mean(img, axis=None))
        rev.append(np.array(dr.grad(params[k]), np.float64).ravel())
        row = []
        for c in range(3):
            ends = []
            for sign in (1.0, -1.0):
                x = list(rgb)
                x[c] += sign * eps
                params[k] = mi.Color3f(*x)
                params.update()
                ends.append(np.asarray(pbr.render(scene, spp=spp, seed=s), np.float64).mean())
            row.append((ends[0] - ends[1]) / (2 * eps))
        fd.append(row)
        params[k] = mi.Color3f(*rgb)
        params.update()
    rev, fd = np.mean(rev, 0), np.mean(fd, 0)
    assert np.abs(fd).min() > 0.05 * np.abs(fd).max(), fd           # every channel matters
    assert np.all(np.abs(rev - fd) <= 0.05 * np.abs(fd).max()), (rev, fd)


def test_white_derivative_table_can_be_made_inside_a_kernel():
    """White's derivative table is NumPy only: it may first be needed while a kernel is
    traced or recorded (made with Dr.Jit lookups it failed inside a symbolic loop:
    'Variable ... remains dirty')."""
    S._white_derivative_np.cache_clear()

    @dr.syntax
    def loop(n):
        i = mi.UInt32(0)
        while i < n:
            S._white_derivative_np()
            i += 1
        return i

    assert np.array(loop(mi.UInt32(2, 3))).tolist() == [2, 3]
    assert S._white_derivative_np().shape == (3, 3)
