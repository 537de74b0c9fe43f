"""Pixel reconstruction filters, used by *filter importance sampling* as in pbrt-v4: a
camera sample's offset from the pixel centre is drawn per axis from a density close to
|f| and carries the weight f(x) / pdf(x) (negative where the filter is). The film divides
by the sum of weights, so each pixel estimates  int f(x - p) L(x) dx / int f(x - p) dx,
which is what Mitsuba's splatting film converges to.

Mitsuba's names and parameters: ``box``, ``tent``, ``gaussian``, ``mitchell`` (``B``,
``C``), ``catmullrom``, ``lanczos`` (``lobes``). pbrt-v4's: ``triangle``, ``sinc``
(``tau``), and pbrt-v4's parameters ``xradius``/``yradius`` (and ``sigma`` for
``gaussian``) on every filter that pbrt-v4 has. Filters whose per-axis radii differ keep
one 1D filter per axis (:attr:`Filter.y`).

Filters that are not sampled analytically (``mitchell``, ``catmullrom``, ``lanczos``,
``sinc``) are sampled from an inverse-CDF table of |f| (:class:`TabulatedFilter`):
x is linearly interpolated between 1024 quantiles, so the density is exactly
``1 / (1024 (x[i+1] - x[i]))`` on segment i and the weight f / pdf is exact.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .plugins.registry import Registry

FILTERS = Registry("rfilter")


def _select(c, a, b):
    return dr.select(c, a, b) if isinstance(c, dr.ArrayBase) else np.where(c, a, b)


def _sinc(x):
    """sin(x) / x, NumPy or Dr.Jit. Below |x| = 0.1 its series 1 - x^2/6 + x^4/120
    (error < 3e-10): on CUDA, Dr.Jit's single-precision ``sin`` is ``sin.approx``, whose
    absolute error (~5e-7) is all of sin(x) for tiny x (sin(1e-20) = 0 there, which made
    the filter 0 at its centre)."""
    series = 1.0 - x * x * (1.0 / 6.0 - x * x / 120.0)
    if isinstance(x, dr.ArrayBase):
        return dr.select(dr.abs(x) < 0.1, series, dr.sin(x) / x)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.abs(x) < 0.1, series, np.sin(x) / x)


def _axis_radii(props, default: float, mitsuba_name: str | None = "radius"):
    """(x radius, y radius): pbrt-v4's ``xradius``/``yradius``, or Mitsuba's one
    ``mitsuba_name`` (None: the filter has no radius parameter in Mitsuba)."""
    if mitsuba_name and props.has(mitsuba_name):
        if props.has("xradius") or props.has("yradius"):
            raise props.error(mitsuba_name, f"give either {mitsuba_name!r} or 'xradius'/'yradius', not both")
        r = props.float(mitsuba_name, default, min=1e-6)
        return r, r
    rx = props.float("xradius", default, min=1e-6)
    return rx, props.float("yradius", rx if props.has("xradius") else default, min=1e-6)


class Filter:
    """A separable pixel filter: ``eval`` its 1D value, ``sample1`` one axis's offset;
    ``y`` is the filter of the y axis (itself unless the radii differ)."""

    name = ""
    radius = 0.5

    @property
    def y(self) -> "Filter":
        return self.__dict__.get("_y", self)

    def with_y_radius(self, ry: float) -> None:
        """Give the y axis its own radius (a copy of this filter with ``radius = ry``)."""
        if ry != self.radius:
            other = object.__new__(type(self))
            other.__dict__.update({k: v for k, v in self.__dict__.items() if k != "_y"})
            other.radius = ry
            other._setup()
            self._y = other

    def _setup(self) -> None:
        """Derived constants of the radius (subclasses)."""

    def eval(self, x):
        raise NotImplementedError

    def sample1(self, u):
        """(offset along one axis, weight f / pdf) for a uniform ``u``."""
        raise NotImplementedError

    def sample(self, u: mi.Point2f):
        """(offset from the pixel centre, weight f/pdf); the filters are separable."""
        x, wx = self.sample1(u.x)
        y, wy = self.y.sample1(u.y)
        return mi.Vector2f(x, y), wx * wy


@FILTERS.register("box")
class BoxFilter(Filter):
    """``box``: a constant over [-radius, radius].

    ========  =====  =======  =======================================
    name      type   default  meaning
    ========  =====  =======  =======================================
    radius    float  0.5      half-width (pixels; Mitsuba's name)
    xradius   float  0.5      half-width along x (pbrt-v4's name)
    yradius   float  xradius  half-width along y (pbrt-v4's name)
    ========  =====  =======  =======================================
    """

    name = "box"

    def __init__(self, props):
        self.radius, ry = _axis_radii(props, 0.5)
        props.finish()
        self.with_y_radius(ry)

    def eval(self, x):
        return dr.select(dr.abs(x) <= self.radius, 1.0, 0.0)

    def sample1(self, u):
        return (u - 0.5) * (2.0 * self.radius), mi.Float(1.0)


@FILTERS.register("tent", "triangle")
class TentFilter(Filter):
    """``tent`` (Mitsuba's) / ``triangle`` (pbrt-v4's): max(0, 1 - |x| / radius), sampled
    exactly (pbrt-v4's max(0, radius - |x|) is the same filter: the film normalises).

    ========  =====  =======  ===================================================
    name      type   default  meaning
    ========  =====  =======  ===================================================
    radius    float  1        half-width (pixels; ``tent``)
    xradius   float  2        half-width along x (pbrt-v4's ``triangle``; 1 for
                              ``tent``)
    yradius   float  xradius  half-width along y
    ========  =====  =======  ===================================================
    """

    name = "tent"

    def __init__(self, props):
        self.name = props.type or "tent"
        self.radius, ry = _axis_radii(props, 2.0 if self.name == "triangle" else 1.0)
        props.finish()
        self.with_y_radius(ry)

    def eval(self, x):
        return dr.maximum(0.0, 1.0 - dr.abs(x) / self.radius)

    def sample1(self, u):
        """Inverse CDF of the tent: exact importance sampling, constant weight."""
        lo = u < 0.5
        t = dr.select(lo, dr.sqrt(2.0 * u) - 1.0, 1.0 - dr.sqrt(dr.maximum(2.0 - 2.0 * u, 0.0)))
        return t * self.radius, mi.Float(1.0)


@FILTERS.register("gaussian")
class GaussianFilter(Filter):
    """``gaussian``: exp(-x^2 / 2 sigma^2) minus its value at the radius (so it reaches 0),
    sampled as a truncated normal. Mitsuba's: ``stddev``, radius 4 sigma; pbrt-v4's:
    ``sigma`` and ``xradius``/``yradius`` (pbrt-v4's default radius is 1.5: a pbrt-v4
    scene's reader passes it).

    ========  =====  ==========  ===================================================
    name      type   default     meaning
    ========  =====  ==========  ===================================================
    stddev    float  0.5         sigma (pixels; Mitsuba's name)
    sigma     float  0.5         sigma (pixels; pbrt-v4's name)
    xradius   float  4 sigma     half-width along x (pbrt-v4's name)
    yradius   float  xradius     half-width along y (pbrt-v4's name)
    ========  =====  ==========  ===================================================
    """
    name = "gaussian"

    def __init__(self, props):
        if props.has("stddev") and props.has("sigma"):
            raise props.error("sigma", "give either 'stddev' (Mitsuba's) or 'sigma' (pbrt-v4's), not both")
        self.stddev = props.float("sigma" if props.has("sigma") else "stddev", 0.5, min=1e-6)
        self.radius, ry = _axis_radii(props, 4.0 * self.stddev, mitsuba_name=None)
        props.finish()
        self._setup()
        self.with_y_radius(ry)

    def _setup(self):
        self._alpha = -1.0 / (2.0 * self.stddev ** 2)
        self._bias = math.exp(self._alpha * self.radius ** 2)
        # Sampling density: the normal distribution truncated to [-radius, radius].
        self._erf_r = math.erf(self.radius / (self.stddev * math.sqrt(2.0)))
        self._norm = self.stddev * math.sqrt(2.0 * math.pi) * self._erf_r

    def eval(self, x):
        return dr.maximum(0.0, dr.exp(self._alpha * x * x) - self._bias)

    def sample1(self, u):
        """Truncated normal by inverse CDF; weight f / pdf = 1 - bias / exp(alpha x^2)."""
        v = dr.clip((2.0 * u - 1.0) * self._erf_r, -0.99999994, 0.99999994)
        x = dr.clip(dr.erfinv(v) * (self.stddev * math.sqrt(2.0)), -self.radius, self.radius)
        g = dr.exp(self._alpha * x * x)
        return x, dr.maximum(0.0, (g - self._bias) / g) * self._norm


class TabulatedFilter(Filter):
    """A filter sampled from an inverse-CDF table of |f| (see the module docstring).
    Subclasses define ``profile(x)`` for NumPy and Dr.Jit arrays alike (zero outside
    [-radius, radius] is applied here)."""

    N_QUANTILES = 1024
    N_CELLS = 16384

    def profile(self, x):
        raise NotImplementedError

    def _setup(self):
        r = self.radius
        edges = np.linspace(-r, r, self.N_CELLS + 1)
        mid = 0.5 * (edges[1:] + edges[:-1])
        dens = np.abs(self.profile(mid)) + 1e-9 * np.max(np.abs(self.profile(mid)))
        cdf = np.concatenate([[0.0], np.cumsum(dens)])
        cdf /= cdf[-1]
        u = np.linspace(0.0, 1.0, self.N_QUANTILES + 1)
        q = np.interp(u, cdf, edges)    # the piecewise-linear CDF's exact inverse
        q[0], q[-1] = -r, r
        self._quantiles = mi.Float(q.astype(np.float32))   # made here: not inside a frozen render

    def eval(self, x):
        return dr.select(dr.abs(x) < self.radius, self.profile(x), 0.0)

    def sample1(self, u):
        n = self.N_QUANTILES
        table = self._quantiles
        t = dr.clip(u * n, 0.0, n * (1.0 - 2.0 ** -24))
        i = mi.UInt32(t)
        a = dr.gather(mi.Float, table, i)
        b = dr.gather(mi.Float, table, i + 1)
        x = dr.fma(t - mi.Float(i), b - a, a)
        return x, self.eval(x) * ((b - a) * n)


def _mitchell(x, b: float, c: float):
    """Mitchell-Netravali's cubic on [-2, 2] (0 outside)."""
    x = abs(x)
    x2 = x * x
    x3 = x2 * x
    near = ((12 - 9 * b - 6 * c) * x3 + (-18 + 12 * b + 6 * c) * x2 + (6 - 2 * b)) * (1.0 / 6.0)
    far = ((-b - 6 * c) * x3 + (6 * b + 30 * c) * x2 + (-12 * b - 48 * c) * x + (8 * b + 24 * c)) * (1.0 / 6.0)
    return _select(x < 1.0, near, _select(x < 2.0, far, 0.0))


@FILTERS.register("mitchell")
class MitchellFilter(TabulatedFilter):
    """``mitchell``: the Mitchell-Netravali cubic (Mitsuba's and pbrt-v4's), stretched to
    the radius as pbrt-v4 does (f(x) = m(2 x / radius); at the default radius 2, Mitsuba's
    m(x)). Negative lobes: the weights of the samples there are negative.

    ========  =====  =======  ============================================
    name      type   default  meaning
    ========  =====  =======  ============================================
    B         float  1/3      B of the paper
    C         float  1/3      C of the paper
    xradius   float  2        half-width along x (pbrt-v4's name)
    yradius   float  xradius  half-width along y (pbrt-v4's name)
    ========  =====  =======  ============================================
    """

    name = "mitchell"

    def __init__(self, props):
        self.b = props.float("B", 1.0 / 3.0)
        self.c = props.float("C", 1.0 / 3.0)
        self.radius, ry = _axis_radii(props, 2.0, mitsuba_name=None)
        props.finish()
        self._setup()
        self.with_y_radius(ry)

    def profile(self, x):
        return _mitchell(x * (2.0 / self.radius), self.b, self.c)


@FILTERS.register("catmullrom")
class CatmullRomFilter(TabulatedFilter):
    """``catmullrom``: Mitsuba's Catmull-Rom filter, the Mitchell-Netravali cubic with
    B = 0, C = 1/2 over [-2, 2]. No parameters.

    ====  ====  =======  =======
    name  type  default  meaning
    ====  ====  =======  =======
    ====  ====  =======  =======
    """

    name = "catmullrom"
    radius = 2.0

    def __init__(self, props):
        props.finish()
        self._setup()

    def profile(self, x):
        return _mitchell(x, 0.0, 0.5)


@FILTERS.register("lanczos", "sinc")
class LanczosFilter(TabulatedFilter):
    """``lanczos`` (Mitsuba's) / ``sinc`` (pbrt-v4's): the windowed sinc
    sinc(x) sinc(x / tau) for |x| < radius. Mitsuba's ``lanczos`` has tau = radius =
    ``lobes``; pbrt-v4's ``sinc`` has its own ``tau`` and ``xradius``/``yradius``.

    ========  =====  =======  =================================================
    name      type   default  meaning
    ========  =====  =======  =================================================
    lobes     int    3        ``lanczos``: tau and radius (Mitsuba's name)
    tau       float  3        ``sinc``: the window's width (pbrt-v4's name)
    xradius   float  4        ``sinc``: half-width along x (pbrt-v4's name)
    yradius   float  xradius  ``sinc``: half-width along y
    ========  =====  =======  =================================================
    """

    def __init__(self, props):
        self.name = props.type or "lanczos"
        if self.name == "lanczos":
            self.tau = float(props.int("lobes", 3, min=1))
            self.radius, ry = self.tau, self.tau
        else:
            self.tau = props.float("tau", 3.0, min=1e-6)
            self.radius, ry = _axis_radii(props, 4.0, mitsuba_name=None)
        props.finish()
        self._setup()
        self.with_y_radius(ry)

    def profile(self, x):
        x1 = abs(x) * math.pi
        return _sinc(x1) * _sinc(x1 / self.tau)
