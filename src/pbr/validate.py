"""Statistical comparison of Monte Carlo renders (the test in docs/architecture.md, "Validation").

Two renderers that estimate the same image differ only by noise; a biased one differs
by more. To tell the two apart, each image is estimated from ``batches`` independent
renders (:func:`estimate`), which gives per pixel and channel a mean and the variance of
that mean. :func:`compare` then applies two tests:

1. Per pixel and channel, a two-sided z-test of equal means,
   ``z = |ma - mb| / sqrt(va + vb)``, at a Sidak-corrected level so that a correct
   renderer fails *any* pixel-channel with probability ``alpha`` (the pixel-channels
   are treated as independent tests). At least ``min_pass`` of them must pass; the slack
   absorbs the heavy tails of a variance estimated from few batches and of skewed
   Monte Carlo noise (fireflies).
2. The whole-image mean ratio ``r = mean(ma) / mean(mb)`` must be 1 within
   ``ratio_sigmas`` (default 3) standard errors, so that a correct renderer fails it
   with probability ~0.27%. This is the sensitive test: a small global bias (a 1%
   energy loss) hides in per-pixel noise but not in the mean over all pixels.

The standard error of the image mean should come from the batches themselves
(:attr:`Estimate.image_mean_var`, which :func:`compare_renders` passes on): pixel
filters wider than a pixel (Mitsuba's default Gaussian) and the shared path of the
three colour channels correlate pixel-channels, so summing per-pixel variances
underestimates it (measured on a 32x32 Cornell box: 5x for the Gaussian filter,
2.3x for a box filter). Without it :func:`compare` falls back to that sum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = [
    "Estimate", "Result", "estimate", "compare", "compare_renders",
    "mitsuba_variant", "mitsuba_render_fn", "mitsuba_reference", "mse", "relative_mse", "welch_dof",
]

#: Seeds of one :func:`estimate` call are ``seed * SEED_STRIDE + i``: calls with different
#: ``seed`` never share a render seed (as long as ``batches <= SEED_STRIDE``).
SEED_STRIDE = 1 << 16

_erfc = np.frompyfunc(math.erfc, 1, 1)


def _beta_cf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz)."""
    tiny, c, d = 1e-300, 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 300):
        for num in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                    -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    return h


def _betainc(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta function I_x(a, b)."""
    if x <= 0.0 or x >= 1.0:
        return 0.0 if x <= 0.0 else 1.0
    ln = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(ln) * _beta_cf(a, b, x) / a
    return 1.0 - math.exp(ln) * _beta_cf(b, a, 1.0 - x) / b


def _student_p(t: float, dof: float) -> float:
    """Two-sided tail probability P(|T| >= t) of Student's t with ``dof`` degrees of freedom."""
    if math.isnan(t) or math.isnan(dof):
        return math.nan
    if math.isinf(t):
        return 0.0
    if math.isinf(dof):
        return math.erfc(t / math.sqrt(2.0))
    return _betainc(0.5 * dof, 0.5, dof / (dof + t * t))


_student = np.frompyfunc(_student_p, 2, 1)


def welch_dof(var_a, batches_a: int, var_b, batches_b: int) -> np.ndarray:
    """Welch-Satterthwaite degrees of freedom of ``(mean_a - mean_b) / sqrt(var_a + var_b)``
    for variances of means estimated from ``batches_a`` and ``batches_b`` batches."""
    va, vb = np.asarray(var_a, np.float64), np.asarray(var_b, np.float64)
    den = va * va / (batches_a - 1) + vb * vb / (batches_b - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, (va + vb) ** 2 / np.where(den > 0, den, 1.0), np.inf)


class Estimate(tuple):
    """``(mean, var)`` of an image estimated from independent batches.

    Unpacks like a pair; also carries ``image_mean_var`` (the variance of the mean over
    all pixel-channels, measured across batches, so it includes their correlation),
    ``batches`` and ``spp_per_batch``.
    """

    def __new__(cls, mean, var, image_mean_var, batches, spp_per_batch):
        self = super().__new__(cls, (mean, var))
        self.image_mean_var = float(image_mean_var)
        self.batches = int(batches)
        self.spp_per_batch = int(spp_per_batch)
        return self

    @property
    def mean(self) -> np.ndarray:
        return self[0]

    @property
    def var(self) -> np.ndarray:
        return self[1]


def estimate(render_fn: Callable, spp: int, batches: int = 16, seed: int = 0) -> Estimate:
    """Mean image and variance of that mean from ``batches`` independent renders.

    Calls ``render_fn(seed=s, spp=spp // batches)`` for ``s = seed * SEED_STRIDE + i``;
    each call returns something ``np.asarray`` turns into a float (H, W, C) image.
    The variance is the across-batch sample variance divided by ``batches`` (float64,
    accumulated with Welford's update so memory does not grow with ``batches``).
    """
    if batches < 2:
        raise ValueError(f"estimate: batches must be >= 2 to measure a variance, got {batches}")
    if batches > SEED_STRIDE:
        raise ValueError(f"estimate: batches must be <= {SEED_STRIDE}, got {batches}")
    if seed < 0:
        raise ValueError(f"estimate: seed must be >= 0, got {seed}")
    spp_b = spp // batches
    if spp_b < 1:
        raise ValueError(f"estimate: spp ({spp}) must be >= batches ({batches})")
    mean = m2 = None
    img_means = np.empty(batches)
    for i in range(batches):
        x = np.asarray(render_fn(seed=seed * SEED_STRIDE + i, spp=spp_b), dtype=np.float64)
        if mean is None:
            mean, m2 = np.zeros_like(x), np.zeros_like(x)
        elif x.shape != mean.shape:
            raise ValueError(f"estimate: render {i} has shape {x.shape}, expected {mean.shape}")
        d = x - mean
        mean += d / (i + 1)
        m2 += d * (x - mean)
        img_means[i] = x.mean()
    var = m2 / (batches - 1) / batches
    return Estimate(mean, var, img_means.var(ddof=1) / batches, batches, spp_b)


@dataclass(repr=False, eq=False)
class Result:
    """Outcome of :func:`compare`; ``str(result)`` is a one-paragraph summary."""

    passed: bool
    pass_fraction: float
    n: int
    z: np.ndarray
    p_values: np.ndarray
    alpha_sidak: float
    mean_ratio: float
    mean_ratio_stderr: float
    ratio_ok: bool
    alpha: float = 0.01
    min_pass: float = 0.9975
    ratio_sigmas: float = 3.0
    n_failed: int = 0
    mean_ratio_per_channel: np.ndarray = field(default_factory=lambda: np.empty(0))

    def summary(self) -> str:
        verdict = "PASS" if self.passed else "FAIL"
        finite = self.z[np.isfinite(self.z)]
        zmax = float(finite.max()) if finite.size else float("nan")
        nsig = (abs(self.mean_ratio - 1) / self.mean_ratio_stderr
                if self.mean_ratio_stderr > 0 else float("inf") if self.mean_ratio != 1 else 0.0)
        return (
            f"{verdict}: {self.n - self.n_failed}/{self.n} pixel-channels pass "
            f"({100 * self.pass_fraction:.3f}%, need {100 * self.min_pass:.2f}%; "
            f"Sidak level {self.alpha_sidak:.3g} for alpha {self.alpha}; max finite z {zmax:.2f}); "
            f"mean ratio {self.mean_ratio:.5f} +- {self.mean_ratio_stderr:.5f} "
            f"({nsig:.2f} sigma, {'ok' if self.ratio_ok else 'NOT ok'} at {self.ratio_sigmas:g} sigma); "
            f"per channel {np.array2string(np.asarray(self.mean_ratio_per_channel), precision=5)}"
        )

    __str__ = summary
    __repr__ = summary

    def __bool__(self) -> bool:
        return bool(self.passed)


def _ratio(a: float, va: float, b: float, vb: float) -> tuple[float, float]:
    """Ratio a/b and its delta-method standard error, var(r) ~ (va + r^2 vb) / b^2."""
    if b == 0:
        return (1.0, 0.0) if a == 0 and va == 0 and vb == 0 else (math.inf, math.inf)
    r = a / b
    return r, math.sqrt(max(va + r * r * vb, 0.0)) / abs(b)


def compare(mean_a, var_a, mean_b, var_b, alpha: float = 0.01, min_pass: float = 0.9975,
            ratio_sigmas: float = 3.0, ratio_atol: float = 1e-4,
            image_mean_var_a: float | None = None, image_mean_var_b: float | None = None,
            zero_var_rtol: float = 1e-6, dof=None) -> Result:
    """Test whether two estimated images have the same expectation (see module docstring).

    ``var_*`` are variances of the means (as returned by :func:`estimate`). A
    pixel-channel where both variances are 0 passes iff its means agree within
    ``zero_var_rtol`` (relative). ``ratio_ok`` requires ``|r - 1| <= max(ratio_sigmas *
    stderr, ratio_atol)``; the floor only matters for (near-)noiseless images, where it
    absorbs float32 rounding. ``image_mean_var_*`` (variance of the image mean, e.g.
    :attr:`Estimate.image_mean_var`) override the per-pixel sum, which assumes
    independent pixel-channels. Non-finite means fail. ``dof`` (a number or per
    pixel-channel, e.g. :func:`welch_dof`): take p-values from Student's t with that many
    degrees of freedom instead of the normal distribution (variances from few batches).
    """
    ma, mb = np.asarray(mean_a, np.float64), np.asarray(mean_b, np.float64)
    va, vb = np.asarray(var_a, np.float64), np.asarray(var_b, np.float64)
    if not (ma.shape == mb.shape == va.shape == vb.shape):
        raise ValueError(f"compare: shapes differ: mean_a {ma.shape}, var_a {va.shape}, "
                         f"mean_b {mb.shape}, var_b {vb.shape}")
    if ma.size == 0:
        raise ValueError("compare: empty images")
    if (va < 0).any() or (vb < 0).any():
        raise ValueError("compare: negative variance")
    if not (0 < alpha < 1 and 0 < min_pass <= 1):
        raise ValueError(f"compare: need 0 < alpha < 1 and 0 < min_pass <= 1 (got {alpha}, {min_pass})")
    n = ma.size

    diff = np.abs(ma - mb)
    s2 = va + vb
    zero = s2 == 0
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(zero, 0.0, diff / np.sqrt(np.where(zero, 1.0, s2)))
    equal = diff <= zero_var_rtol * np.maximum(np.abs(ma), np.abs(mb))
    z[zero & ~equal] = np.inf
    z[~(np.isfinite(ma) & np.isfinite(mb))] = np.nan
    if dof is None:
        p = _erfc(z / math.sqrt(2.0)).astype(np.float64)  # two-sided normal tail; nan stays nan
    else:
        p = _student(z, np.broadcast_to(np.asarray(dof, np.float64), z.shape)).astype(np.float64)

    alpha_sidak = -math.expm1(math.log1p(-alpha) / n)  # 1 - (1 - alpha)^(1/n), accurately
    ok = p >= alpha_sidak
    n_ok = int(ok.sum())
    frac = n_ok / n

    A, B = float(ma.mean()), float(mb.mean())
    VA = float(va.sum()) / n**2 if image_mean_var_a is None else float(image_mean_var_a)
    VB = float(vb.sum()) / n**2 if image_mean_var_b is None else float(image_mean_var_b)
    r, se = _ratio(A, VA, B, VB)
    ratio_ok = bool(math.isfinite(r) and abs(r - 1) <= max(ratio_sigmas * se, ratio_atol))

    per_ch = np.empty(0)
    if ma.ndim >= 1:
        axes = tuple(range(ma.ndim - 1))
        with np.errstate(divide="ignore", invalid="ignore"):
            per_ch = ma.mean(axis=axes) / mb.mean(axis=axes) if axes else ma / mb

    return Result(passed=bool(frac >= min_pass and ratio_ok), pass_fraction=frac, n=n, z=z,
                  p_values=p, alpha_sidak=alpha_sidak, mean_ratio=r, mean_ratio_stderr=se,
                  ratio_ok=ratio_ok, alpha=alpha, min_pass=min_pass, ratio_sigmas=ratio_sigmas,
                  n_failed=n - n_ok, mean_ratio_per_channel=per_ch)


def compare_renders(fn_a: Callable, fn_b: Callable, spp: int, batches: int = 16,
                    seed_a: int = 0, seed_b: int = 1, **kw) -> Result:
    """Estimate two renderers' images from independent seeds and :func:`compare` them.

    ``fn_a``/``fn_b`` have the :func:`estimate` signature ``(seed=, spp=) -> image``; the
    seeds must differ (else two identical renderers give identical, correlated noise).
    The batches' image-mean variances are passed on; ``kw`` goes to :func:`compare`.
    """
    if seed_a == seed_b:
        raise ValueError("compare_renders: seed_a and seed_b must differ (independent noise)")
    ea = estimate(fn_a, spp, batches, seed_a)
    eb = estimate(fn_b, spp, batches, seed_b)
    kw.setdefault("image_mean_var_a", ea.image_mean_var)
    kw.setdefault("image_mean_var_b", eb.image_mean_var)
    return compare(ea.mean, ea.var, eb.mean, eb.var, **kw)


def mitsuba_variant() -> str:
    """Select and return the Mitsuba variant of pbr's backend (``llvm_ad_spectral`` or
    ``cuda_ad_spectral``), selecting pbr's default backend if none is active.

    pbr runs on that variant's types, so a reference rendered in another variant would
    switch pbr's types under it (and compare a CPU render with a GPU one). An unusable
    backend raises :class:`pbr.BackendError`; there is no silent fallback.
    """
    from . import backend as _backend

    _backend.ensure()
    return _backend.variant()


def mitsuba_render_fn(scene_dict: dict | str, sensor: int = 0, **params) -> Callable[..., np.ndarray]:
    """Load ``scene_dict`` with Mitsuba once (a ``str`` is an XML file, loaded with
    ``mi.load_file(path, **params)``, ``params`` overriding its ``<default>`` values);
    return ``render(seed, spp) -> float32 (H, W, 3)``."""
    import mitsuba as mi

    mitsuba_variant()
    if isinstance(scene_dict, str):
        scene = mi.load_file(scene_dict, **params)
    elif params:
        raise TypeError(f"mitsuba_render_fn: parameters {sorted(params)} only apply to an XML file")
    else:
        scene = mi.load_dict(scene_dict)

    def render(seed: int = 0, spp: int = 0) -> np.ndarray:
        img = np.asarray(mi.render(scene, spp=spp, seed=seed, sensor=sensor), dtype=np.float32)
        return img[..., :3]

    return render


def mitsuba_reference(scene_dict: dict, spp: int, seed: int = 0, sensor: int = 0) -> np.ndarray:
    """One Mitsuba render of ``scene_dict`` (spectral variant) as a float32 (H, W, 3) array."""
    return mitsuba_render_fn(scene_dict, sensor)(seed=seed, spp=spp)


def mse(a, b) -> float:
    """Mean squared error between two images."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.mean((a - b) ** 2))


def relative_mse(a, b, eps: float = 1e-2) -> float:
    """Mean of ``(a - b)^2 / (b^2 + eps)``, with ``b`` the reference; ``eps`` keeps
    dark pixels from dominating (the usual relMSE of rendering papers)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.mean((a - b) ** 2 / (b * b + eps)))
