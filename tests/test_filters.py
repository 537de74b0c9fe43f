"""Filter importance sampling: weighted samples reproduce the filter's moments."""

import math

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

from pbr.filters import FILTERS
from pbr.plugins.props import Props


@pytest.mark.parametrize("name", ["box", "tent", "gaussian"])
def test_weighted_moments_match_filter(name):
    f = FILTERS[name](Props({"type": name}, "rfilter"))
    n = 1 << 20
    u = (dr.arange(mi.Float, n) + 0.5) / n
    x, w = f.sample1(u)
    x = np.array(x, np.float64)
    w = np.broadcast_to(np.array(w, np.float64), x.shape)
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.all(np.abs(x) <= f.radius + 1e-6)
    grid = np.linspace(-f.radius, f.radius, 200001)
    fx = np.array(f.eval(mi.Float(grid.astype(np.float32))), np.float64)
    for k in (2, 4):
        expect = np.trapezoid(fx * grid ** k, grid) / np.trapezoid(fx, grid)
        got = np.sum(w * x ** k) / np.sum(w)
        assert got == pytest.approx(expect, rel=2e-3), (k, got, expect)
