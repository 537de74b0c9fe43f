"""Pixel reconstruction filters ``box``, ``tent`` and ``gaussian`` (Mitsuba's names,
radii and formulas), used by *filter importance sampling* as in pbrt-v4: a camera
sample's offset from the pixel centre is drawn (analytically, per axis) from a density
proportional or close to the filter, and carries the weight f(x) / pdf(x). The film divides by the sum of weights, so
each pixel estimates  int f(x - p) L(x) dx / int f(x - p) dx,  which is what Mitsuba's
splatting film converges to."""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from .plugins.registry import Registry

FILTERS = Registry("rfilter")


class Filter:
    """A separable pixel filter: ``eval`` its value, ``sample1`` one axis's offset."""

    name = ""
    radius = 0.5

    def eval(self, x):
        raise NotImplementedError

    def sample1(self, u):
        """(offset along one axis, weight f / pdf) for a uniform ``u``."""
        raise NotImplementedError

    def sample(self, u: mi.Point2f):
        """(offset from the pixel centre, weight f/pdf); the filters are separable."""
        x, wx = self.sample1(u.x)
        y, wy = self.sample1(u.y)
        return mi.Vector2f(x, y), wx * wy


@FILTERS.register("box")
class BoxFilter(Filter):
    """``box``: a constant over [-radius, radius].

    ======  =====  =======  ===================
    name    type   default  meaning
    ======  =====  =======  ===================
    radius  float  0.5      half-width (pixels)
    ======  =====  =======  ===================
    """

    name = "box"

    def __init__(self, props):
        self.radius = props.float("radius", 0.5, min=1e-6)
        props.finish()

    def eval(self, x):
        return dr.select(dr.abs(x) <= self.radius, 1.0, 0.0)

    def sample1(self, u):
        return (u - 0.5) * (2.0 * self.radius), mi.Float(1.0)


@FILTERS.register("tent")
class TentFilter(Filter):
    """``tent``: a triangle over [-radius, radius], sampled exactly.

    ======  =====  =======  ===================
    name    type   default  meaning
    ======  =====  =======  ===================
    radius  float  1        half-width (pixels)
    ======  =====  =======  ===================
    """

    name = "tent"

    def __init__(self, props):
        self.radius = props.float("radius", 1.0, min=1e-6)
        props.finish()

    def eval(self, x):
        return dr.maximum(0.0, 1.0 - dr.abs(x) / self.radius)

    def sample1(self, u):
        """Inverse CDF of the tent: exact importance sampling, constant weight."""
        lo = u < 0.5
        t = dr.select(lo, dr.sqrt(2.0 * u) - 1.0, 1.0 - dr.sqrt(dr.maximum(2.0 - 2.0 * u, 0.0)))
        return t * self.radius, mi.Float(1.0)


@FILTERS.register("gaussian")
class GaussianFilter(Filter):
    """``gaussian``: exp(-x^2 / 2 sigma^2) minus its value at the radius 4 sigma (so it
    reaches 0), sampled as a truncated normal.

    ======  =====  =======  ==============
    name    type   default  meaning
    ======  =====  =======  ==============
    stddev  float  0.5      sigma (pixels)
    ======  =====  =======  ==============
    """
    name = "gaussian"

    def __init__(self, props):
        self.stddev = props.float("stddev", 0.5, min=1e-6)
        props.finish()
        self.radius = 4.0 * self.stddev
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

