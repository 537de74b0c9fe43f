"""Filter importance sampling: weighted samples reproduce the filter's moments; the
filters with negative lobes match Mitsuba's images."""

import math

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

import pbr
from pbr import validate
from pbr.filters import FILTERS
from pbr.plugins.props import Props, SceneError

NAMES = ["box", "tent", "triangle", "gaussian", "mitchell", "catmullrom", "lanczos", "sinc"]


def make(name, **kw):
    return FILTERS[name](Props({"type": name, **kw}, "rfilter"))


def weighted_moments(f, n=1 << 20):
    u = (dr.arange(mi.Float, n) + 0.5) / n
    x, w = f.sample1(u)
    x = np.array(x, np.float64)
    w = np.broadcast_to(np.array(w, np.float64), x.shape)
    return x, w


@pytest.mark.parametrize("name", NAMES)
def test_weighted_moments_match_filter(name):
    f = make(name)
    x, w = weighted_moments(f)
    assert np.all(np.isfinite(w)) and np.all(np.abs(x) <= f.radius + 1e-6)
    if name in ("box", "tent", "triangle", "gaussian"):
        assert np.all(w >= 0)
    grid = np.linspace(-f.radius, f.radius, 200001)
    fx = np.array(f.eval(mi.Float(grid.astype(np.float32))), np.float64)
    for k in (2, 4):
        expect = np.trapezoid(fx * grid ** k, grid) / np.trapezoid(fx, grid)
        got = np.sum(w * x ** k) / np.sum(w)
        assert got == pytest.approx(expect, rel=2e-3, abs=1e-4 * f.radius ** k), (k, got, expect)
    if name not in ("box", "tent", "triangle", "gaussian"):   # tabulated: f / pdf is exact
        assert np.mean(w) == pytest.approx(np.trapezoid(fx, grid), rel=1e-3)


def test_filter_values_follow_mitsuba_and_pbrt():
    """Values at chosen points: Mitsuba's Mitchell (B = C = 1/3) m(0) = 8/9, m(1) = 1/18;
    Catmull-Rom c(0) = 1, c(1) = 0; Lanczos (3 lobes) at 0.5 = sinc(.5) sinc(1/6);
    pbrt-v4's Mitchell stretched to its radius, triangle max(0, 1 - |x|/r)."""
    def ev(f, x):
        return np.array(f.eval(mi.Float(x)), np.float64)
    assert ev(make("mitchell"), [0.0, 1.0, 2.5]) == pytest.approx([8 / 9, 1 / 18, 0.0], abs=1e-6)
    assert ev(make("mitchell", xradius=4.0), [2.0]) == pytest.approx([1 / 18], abs=1e-6)
    assert ev(make("catmullrom"), [0.0, 1.0, 1.5]) == pytest.approx([1.0, 0.0, -0.0625], abs=1e-6)
    s = lambda t: math.sin(math.pi * t) / (math.pi * t)  # noqa: E731
    assert ev(make("lanczos"), [0.0, 0.5, 3.5]) == pytest.approx([1.0, s(0.5) * s(0.5 / 3), 0.0], abs=1e-6)
    assert ev(make("sinc", tau=2.0), [0.5, 3.9]) == pytest.approx([s(0.5) * s(0.25), s(3.9) * s(1.95)], abs=1e-6)
    assert ev(make("triangle"), [1.0]) == pytest.approx([0.5])


def test_per_axis_radii_and_errors():
    f = make("mitchell", xradius=2.0, yradius=1.0)
    assert f.radius == 2.0 and f.y.radius == 1.0 and f.y.b == f.b
    _, w = f.sample(mi.Point2f(mi.Float([0.3]), mi.Float([0.9])))
    assert np.isfinite(np.array(w)).all()
    assert make("box").y is not None
    with pytest.raises(SceneError, match="rfilter.radius"):
        make("tent", radius=1.0, xradius=2.0)
    with pytest.raises(SceneError, match="rfilter.lobes"):
        make("lanczos", lobes=0)
    with pytest.raises(SceneError, match="rfilter.radius.*unknown parameter"):
        make("mitchell", radius=2.0)


def _scene(rfilter):
    """A small sharp-edged scene (a bright square on a dark wall) where the filter's
    shape, negative lobes included, decides the image."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 30.0,
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 20, "height": 16, "rfilter": rfilter},
                   "sampler": {"type": "independent", "sample_count": 64}},
        "wall": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.2}}},
        "lamp": {"type": "rectangle", "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [4.0, 2.0, 1.0]}},
                 "to_world": mi.ScalarTransform4f().translate([0.05, 0.03, 0.5]).rotate([0, 0, 1], 20).scale(0.3)},
        "sun": {"type": "constant", "radiance": {"type": "rgb", "value": 0.5}},
    }


def _compare(d_pbr, d_mi, spp=1024):
    scene = pbr.load_dict(d_pbr)
    res = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp)),
                                   validate.mitsuba_render_fn(d_mi), spp=spp, batches=16, seed_a=3, seed_b=4)
    print(res.summary())
    return res


@pytest.mark.slow
@pytest.mark.parametrize("rfilter", [{"type": "mitchell"}, {"type": "mitchell", "B": 0.0, "C": 0.75},
                                     {"type": "catmullrom"}, {"type": "lanczos"}, {"type": "lanczos", "lobes": 2}])
def test_negative_lobed_filters_match_mitsuba(rfilter):
    d = _scene(rfilter)
    assert _compare(d, d).passed


@pytest.mark.slow
def test_a_different_filter_fails_the_comparison():
    """Must-fail: pbr's box against Mitsuba's Lanczos (the ringing at the square's
    edges is what tells them apart)."""
    assert not _compare(_scene({"type": "box"}), _scene({"type": "lanczos"})).passed
