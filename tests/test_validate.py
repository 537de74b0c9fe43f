"""Tests of pbr.validate: the statistical image comparison must pass a renderer against
itself (independent seeds) and fail a slightly biased one.

The render tests use only Mitsuba (a 32x32 Cornell box, 16 batches), each compared with
the unmodified scene at 8192 spp. Measured on a 2-core CPU (LLVM); the whole file takes
~15-20 s, the slowest test ~6 s plus the ~6 s shared reference:

- vs itself: 100% of 3072 pixel-channels pass (max z 4.0-4.5 against a Sidak threshold
  of 4.65), mean ratio within 0.3-1.7 standard errors (stderr ~0.0013 at 8192 spp).
- light radiance x1.02 (2048 spp): ratio 1.015-1.022 (5.4-9.0 stderr), and 0.3-1.7% of
  pixel-channels fail (mostly those that see the light, whose variance is small).
- max_depth 8 -> 7 (a 0.57% energy loss, ~1% in red, up to ~3% in some red pixels):
  ~2.1% of pixel-channels fail (0.25% allowed), ratio 0.992-0.997 (1.9-5.5 stderr).
  At 4096 spp only 0.5-0.9% fail, too close to the threshold, hence 8192.
- not used: red wall albedo x1.02 changes the image mean by 0.2% and passed at 8192 spp
  (99.77% of pixel-channels, ratio 1.3 stderr): too subtle for a CI-sized render.
"""

import math

import numpy as np
import pytest

import pbr  # noqa: F401  (configures libLLVM before Mitsuba/Dr.Jit start)
from pbr import validate as V


# --------------------------------------------------------------------------- estimate

def _gaussian_renderer(mu, sigma, calls=None):
    """A fake renderer: per-sample N(mu, sigma^2) noise averaged over spp samples."""
    def render(seed, spp):
        if calls is not None:
            calls.append((seed, spp))
        rng = np.random.default_rng(seed)
        return (mu + sigma / math.sqrt(spp) * rng.standard_normal(np.shape(mu))).astype(np.float32)
    return render


def test_estimate_mean_var_and_seeds():
    mu = np.full((4, 5, 3), 2.0)
    calls = []
    est = V.estimate(_gaussian_renderer(mu, 1.0, calls), spp=64, batches=8, seed=3)
    assert [c[1] for c in calls] == [8] * 8
    seeds = [c[0] for c in calls]
    assert len(set(seeds)) == 8
    imgs = np.stack([np.asarray(_gaussian_renderer(mu, 1.0)(seed=s, spp=8), np.float64) for s in seeds])
    mean, var = est  # unpacks like a pair
    assert mean.dtype == np.float64 and mean.shape == (4, 5, 3)
    np.testing.assert_allclose(mean, imgs.mean(0), rtol=1e-12)
    np.testing.assert_allclose(var, imgs.var(0, ddof=1) / 8, rtol=1e-10)
    assert est.image_mean_var == pytest.approx(imgs.mean(axis=(1, 2, 3)).var(ddof=1) / 8, rel=1e-10)

    calls2 = []
    V.estimate(_gaussian_renderer(mu, 1.0, calls2), spp=64, batches=8, seed=4)
    assert not set(seeds) & {c[0] for c in calls2}, "different seeds must not share render seeds"


def test_estimate_rejects_bad_arguments():
    r = _gaussian_renderer(np.zeros((2, 2, 3)), 1.0)
    with pytest.raises(ValueError):
        V.estimate(r, spp=16, batches=1)
    with pytest.raises(ValueError):
        V.estimate(r, spp=8, batches=16)


def test_image_mean_var_includes_channel_correlation():
    """Identical noise in the 3 channels triples the variance of the image mean; the
    per-pixel sum (which assumes independence) misses that, the batches do not."""
    def render(seed, spp):
        rng = np.random.default_rng(seed)
        return np.repeat(1 + rng.standard_normal((16, 16, 1)), 3, axis=2)
    est = V.estimate(render, spp=256, batches=256)
    naive = est.var.sum() / est.var.size ** 2
    assert est.image_mean_var / naive == pytest.approx(3.0, rel=0.3)
    # compare() uses it for the ratio's standard error, and compare_renders passes it on.
    r = V.compare(est.mean, est.var, est.mean, est.var,
                  image_mean_var_a=est.image_mean_var, image_mean_var_b=0.0)
    assert r.mean_ratio_stderr == pytest.approx(math.sqrt(est.image_mean_var) / est.mean.mean(), rel=1e-9)
    r_naive = V.compare(est.mean, est.var, est.mean, est.var)
    assert r_naive.mean_ratio_stderr == pytest.approx(math.sqrt(2 * naive) / est.mean.mean(), rel=1e-9)
    r = V.compare_renders(render, render, spp=256, batches=256)
    assert r.mean_ratio_stderr / r_naive.mean_ratio_stderr == pytest.approx(math.sqrt(3), rel=0.2)


# --------------------------------------------------------------------------- compare

def test_p_values_and_sidak_level():
    ma = np.array([0.0, 1.959963984540054, 1.0, 2.5758293035489004])
    r = V.compare(ma, np.full(4, 0.5), np.zeros(4), np.full(4, 0.5))
    np.testing.assert_allclose(r.z, ma, rtol=1e-12)
    np.testing.assert_allclose(r.p_values, [1.0, 0.05, 0.31731050786291415, 0.01], rtol=1e-9)
    assert r.n == 4
    assert r.alpha_sidak == pytest.approx(1 - 0.99 ** 0.25, rel=1e-12)
    assert r.alpha_sidak == pytest.approx(0.0025094, rel=1e-4)


def test_null_hypothesis_rejection_rates():
    """With exact Gaussian noise and known variances, the Sidak-corrected per-pixel test
    fails any pixel of an image with probability alpha, the 3-sigma ratio test 0.27%."""
    rng = np.random.default_rng(1)
    trials, n, alpha = 400, 1000, 0.2
    va = rng.uniform(0.5, 2.0, n) * 1e-2
    vb = rng.uniform(0.5, 2.0, n) * 1e-2
    mu = rng.uniform(1.0, 3.0, n)
    any_fail = ratio_fail = default_fail = 0
    for _ in range(trials):
        ma = mu + np.sqrt(va) * rng.standard_normal(n)
        mb = mu + np.sqrt(vb) * rng.standard_normal(n)
        r = V.compare(ma, va, mb, vb, alpha=alpha)
        any_fail += r.n_failed > 0
        ratio_fail += not r.ratio_ok
        default_fail += not V.compare(ma, va, mb, vb).passed
    sd = math.sqrt(trials * alpha * (1 - alpha))
    assert abs(any_fail - trials * alpha) < 4 * sd, any_fail
    assert ratio_fail <= 6, ratio_fail  # expected 1.1
    assert default_fail <= 6, default_fail


def test_small_global_shift_fails_on_ratio_only():
    """A 2% bias is invisible per pixel (10% noise) but not in the mean over 3072 values."""
    rng = np.random.default_rng(2)
    shape = (32, 32, 3)
    v = np.full(shape, 0.1 ** 2)
    ma = 1 + 0.1 * rng.standard_normal(shape)
    mb = 1 + 0.1 * rng.standard_normal(shape)
    ok = V.compare(ma, v, mb, v)
    assert ok.passed and ok.ratio_ok and ok.pass_fraction == 1.0, ok
    bad = V.compare(1.02 * ma, 1.02 ** 2 * v, mb, v)
    assert bad.pass_fraction == 1.0 and not bad.ratio_ok and not bad.passed, bad
    assert bad.mean_ratio == pytest.approx(1.02, abs=0.01)
    assert bad.mean_ratio_stderr == pytest.approx(0.1 * math.sqrt(2 / 3072), rel=0.05)
    assert "FAIL" in str(bad) and "PASS" in str(ok)


def test_local_outliers_fail_on_pass_fraction():
    """Pixel-channels far off fail individually; more than 0.25% of them fail the image."""
    rng = np.random.default_rng(3)
    shape = (32, 32, 3)
    v = np.full(shape, 0.01 ** 2)
    ma = 1 + 0.01 * rng.standard_normal(shape)
    mb = 1 + 0.01 * rng.standard_normal(shape)
    few, many = ma.copy(), ma.copy()
    # Alternating signs keep the image mean (and so the ratio test) nearly unchanged.
    few.reshape(-1)[:5] += 0.2 * np.array([1, -1, 1, -1, 1])   # 5/3072 = 0.16%: tolerated
    many.reshape(-1)[:20] += 0.2 * np.tile([1, -1], 10)         # 20/3072 = 0.65%: not
    r_few, r_many = V.compare(few, v, mb, v), V.compare(many, v, mb, v)
    assert r_few.n_failed == 5 and r_few.ratio_ok and r_few.passed, r_few
    assert r_many.n_failed == 20 and r_many.ratio_ok and not r_many.passed, r_many
    assert np.all(r_many.p_values.reshape(-1)[:20] < r_many.alpha_sidak)


def test_zero_variance():
    z = np.zeros(4)
    m = np.array([0.0, 1.0, 2.0, 3.0])
    r = V.compare(m, z, m * (1 + 1e-7), z)
    assert r.passed and r.n_failed == 0 and np.all(r.z == 0) and np.all(r.p_values == 1)
    r = V.compare(m, z, m * (1 + 1e-3), z)
    assert r.n_failed == 3 and not r.passed      # the 0 == 0 entry still passes
    assert np.isinf(r.z[1:]).all() and np.all(r.p_values[1:] == 0)
    # One side noiseless: the other side's variance is used.
    r = V.compare(np.array([1.0]), np.array([0.0]), np.array([1.1]), np.array([0.01]))
    assert r.z[0] == pytest.approx(1.0)
    # All black, noiseless: passes with ratio 1.
    r = V.compare(np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), np.zeros((2, 2, 3)))
    assert r.passed and r.mean_ratio == 1.0


def test_nonfinite_and_bad_input():
    m, v = np.ones(3000), np.full(3000, 0.01)
    bad = m.copy()
    bad[:10] = np.nan
    r = V.compare(bad, v, m, v)
    assert r.n_failed == 10 and not r.passed
    with pytest.raises(ValueError):
        V.compare(m, v, m[:10], v[:10])
    with pytest.raises(ValueError):
        V.compare(m, -v, m, v)


def test_mse_helpers():
    a, b = np.array([1.0, 2.0]), np.array([1.0, 4.0])
    assert V.mse(a, b) == 2.0
    assert V.relative_mse(a, b, eps=0.0) == pytest.approx(0.125)


# --------------------------------------------------------------------------- Mitsuba

# See the module docstring for what these spp give.
SPP = 8192          # the unmodified reference and the depth-bias test
SPP_LIGHT = 2048    # a 2% radiance change needs fewer samples


def _cornell(max_depth=None, light_scale=1.0):
    V.mitsuba_variant()
    import mitsuba as mi
    d = mi.cornell_box()
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 32
    if max_depth is not None:
        d["integrator"]["max_depth"] = max_depth
    if light_scale != 1.0:
        rad = d["light"]["emitter"]["radiance"]
        rad["value"] = [light_scale * x for x in rad["value"]]
    return d


@pytest.fixture(scope="module")
def reference():
    """The unmodified Cornell box (max_depth 8), estimated once at SPP from seed 1."""
    assert _cornell()["integrator"]["max_depth"] == 8
    return V.estimate(V.mitsuba_render_fn(_cornell()), SPP, seed=1)


def _compare_to(reference, est):
    return V.compare(est.mean, est.var, reference.mean, reference.var,
                     image_mean_var_a=est.image_mean_var,
                     image_mean_var_b=reference.image_mean_var)


def test_mitsuba_reference_image():
    img = V.mitsuba_reference(_cornell(), spp=4, seed=0)
    assert img.dtype == np.float32 and img.shape == (32, 32, 3)
    assert np.isfinite(img).all() and 0.05 < img.mean() < 0.5


def test_mitsuba_vs_itself_passes(reference):
    r_est = V.estimate(V.mitsuba_render_fn(_cornell()), SPP, seed=2)
    r = _compare_to(reference, r_est)
    print(r)
    assert r.passed, r
    assert r.mean_ratio_stderr < 0.002
    # Mitsuba's Gaussian pixel filter and the channels' shared paths correlate
    # pixel-channels: the batches' image-mean variance exceeds the per-pixel sum (~5x).
    naive = V.compare(r_est.mean, r_est.var, reference.mean, reference.var)
    assert r.mean_ratio_stderr > 1.5 * naive.mean_ratio_stderr


def test_compare_renders_self_passes():
    fn = V.mitsuba_render_fn(_cornell())
    r = V.compare_renders(fn, fn, spp=1024, seed_a=5, seed_b=6)
    print(r)
    assert r.passed, r


def test_mitsuba_light_x102_fails(reference):
    r = _compare_to(reference, V.estimate(V.mitsuba_render_fn(_cornell(light_scale=1.02)), SPP_LIGHT, seed=3))
    print(r)
    assert not r.ratio_ok and not r.passed, r
    assert r.mean_ratio > 1.005


def test_mitsuba_max_depth_minus_one_fails(reference):
    r = _compare_to(reference, V.estimate(V.mitsuba_render_fn(_cornell(max_depth=7)), SPP, seed=4))
    print(r)
    assert not r.passed, r
    assert r.pass_fraction < 0.995 and r.mean_ratio < 1.0


def test_student_t_p_values():
    """Two-sided tail probabilities of Student's t (table values) and Welch's degrees of
    freedom; compare(dof=...) uses them, and dof=inf is the normal test."""
    for t, dof, p in ((2.131, 15, 0.05), (2.947, 15, 0.01), (1.0, 1, 0.5), (12.706, 1, 0.05), (2.576, np.inf, 0.01)):
        assert V._student_p(t, dof) == pytest.approx(p, rel=2e-3), (t, dof)
    assert V.welch_dof(1.0, 16, 0.0, 16) == pytest.approx(15.0)
    assert V.welch_dof(1.0, 9, 1.0, 9) == pytest.approx(16.0)
    z = np.full(100, 3.0)
    normal = V.compare(z, np.ones(100), np.zeros(100), np.zeros(100))
    few = V.compare(z, np.ones(100), np.zeros(100), np.zeros(100), dof=4)
    assert (few.p_values > 3 * normal.p_values).all()
    same = V.compare(z, np.ones(100), np.zeros(100), np.zeros(100), dof=np.inf)
    np.testing.assert_allclose(same.p_values, normal.p_values, rtol=1e-9)
