"""Pixel reconstruction filters ``box``, ``tent`` and ``gaussian`` (Mitsuba's names,
radii and formulas), used by *filter importance sampling* as in pbrt-v4: a camera
sample's offset from the pixel centre is drawn from a tabulated density close to the
filter, and carries the weight f(x) / pdf(x). The film divides by the sum of weights, so
each pixel estimates  int f(x - p) L(x) dx / int f(x - p) dx,  which is what Mitsuba's
splatting film converges to."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

_BINS = 256


class Filter:
    name = ""
    radius = 0.5

    def eval_np(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def eval(self, x):
        raise NotImplementedError

    def build(self) -> None:
        xs = np.linspace(-self.radius, self.radius, _BINS + 1)
        mid = 0.5 * (xs[1:] + xs[:-1])
        f = np.maximum(self.eval_np(mid), 0.0) + 1e-6
        pmf = f / f.sum()
        cdf = np.concatenate([[0.0], np.cumsum(pmf)])
        cdf[-1] = 1.0
        self._cdf = mi.Float(cdf.astype(np.float32))
        self._pmf = mi.Float(pmf.astype(np.float32))

    def _sample1(self, u):
        i = dr.binary_search(0, _BINS - 1, lambda k: dr.gather(mi.Float, self._cdf, k + 1) <= u)
        i = dr.minimum(i, _BINS - 1)
        c0 = dr.gather(mi.Float, self._cdf, i)
        pmf = dr.gather(mi.Float, self._pmf, i)
        dx = 2.0 * self.radius / _BINS
        t = dr.clip((u - c0) / pmf, 0.0, 1.0)
        x = -self.radius + (mi.Float(i) + t) * dx
        return x, self.eval(x) / (pmf / dx)

    def sample(self, u: mi.Point2f):
        """(offset from the pixel centre, weight f/pdf)."""
        x, wx = self._sample1(u.x)
        y, wy = self._sample1(u.y)
        return mi.Vector2f(x, y), wx * wy


class BoxFilter(Filter):
    name = "box"

    def __init__(self, props):
        self.radius = props.float("radius", 0.5, min=1e-6)
        props.finish()
        self.build()

    def eval_np(self, x):
        return (np.abs(x) <= self.radius).astype(np.float64)

    def eval(self, x):
        return dr.select(dr.abs(x) <= self.radius, 1.0, 0.0)

    def sample(self, u):
        return (u - 0.5) * (2.0 * self.radius), mi.Float(1.0)


class TentFilter(Filter):
    name = "tent"

    def __init__(self, props):
        self.radius = props.float("radius", 1.0, min=1e-6)
        props.finish()
        self.build()

    def eval_np(self, x):
        return np.maximum(0.0, 1.0 - np.abs(x) / self.radius)

    def eval(self, x):
        return dr.maximum(0.0, 1.0 - dr.abs(x) / self.radius)


class GaussianFilter(Filter):
    """exp(-x^2 / 2 sigma^2) minus its value at the radius 4 sigma (so it reaches 0)."""
    name = "gaussian"

    def __init__(self, props):
        self.stddev = props.float("stddev", 0.5, min=1e-6)
        props.finish()
        self.radius = 4.0 * self.stddev
        self._alpha = -1.0 / (2.0 * self.stddev ** 2)
        self._bias = float(np.exp(self._alpha * self.radius ** 2))
        self.build()

    def eval_np(self, x):
        return np.maximum(0.0, np.exp(self._alpha * x * x) - self._bias)

    def eval(self, x):
        return dr.maximum(0.0, dr.exp(self._alpha * x * x) - self._bias)


FILTERS = {"box": BoxFilter, "tent": TentFilter, "gaussian": GaussianFilter}
