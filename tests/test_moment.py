"""``moment`` (Mitsuba's moment integrator): first and second moments of nested
integrators' samples as AOV channels.

* Against Mitsuba 3's own plugin (llvm_ad_spectral): the same channel names and order,
  and every channel (R, G, B, each nested integrator's mean XYZ, then the means of the
  squares) passes the statistical image test, nested ``path`` and ``depth``.
* The second moments predict the noise: the variance of a pixel's mean from one render
  (:meth:`MomentIntegrator.pixel_variance`) matches the spread of that mean across
  independent renders.
* Must fail: second moments taken as the square of the pixel's mean (instead of the mean
  of the samples' squares).
"""

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import validate
from pbr.integrators import moment as moment_mod

RES, SPP, BATCHES = 12, 1024, 16


def scene(res=RES):
    d = pbr.cornell_box(res, 16)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = {"type": "moment", "a": {"type": "path", "max_depth": 3, "hide_emitters": True},
                       "dd": {"type": "depth"}}
    return d


def compare(d):
    sc = pbr.load_dict(d)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(sc, seed=seed, spp=spp))   # noqa: E731
    validate.mitsuba_variant()
    scm = mi.load_dict(d)
    fb = lambda seed=0, spp=0: np.asarray(mi.render(scm, seed=seed, spp=spp))   # noqa: E731
    assert sc.integrator.aov_names == list(scm.integrator().aov_names())
    res = validate.compare_renders(fa, fb, spp=SPP, batches=BATCHES, seed_a=3, seed_b=4)
    print(res.summary())
    return res


def test_moment_matches_mitsuba():
    res = compare(scene())
    assert res.passed, res.summary()
    assert res.mean_ratio_per_channel.shape == (15,)


def test_squared_means_fail(monkeypatch):
    render = moment_mod.MomentIntegrator.render

    def squared_mean(self, *a, **k):
        img = np.array(render(self, *a, **k), np.float64)
        n = 3 * len(self.nested)
        img[..., 3 + n:] = img[..., 3:3 + n] ** 2
        return mi.TensorXf(img.astype(np.float32))
    monkeypatch.setattr(moment_mod.MomentIntegrator, "render", squared_mean)
    res = compare(scene())
    assert not res.passed


def test_pixel_variance_predicts_the_spread_of_pixel_means():
    """K renders at n spp: the mean over pixels of pixel_variance (one render's estimate
    of var(pixel mean)) equals the across-render variance of the pixel means, within
    the precision of the latter (chi-square with K - 1 dof per pixel, pooled)."""
    d = scene()
    d["integrator"] = {"type": "moment", "p": {"type": "path", "max_depth": 4, "hide_emitters": True}}
    sc = pbr.load_dict(d)
    n, K = 16, 32
    imgs = np.stack([np.asarray(pbr.render(sc, seed=s, spp=n), np.float64) for s in range(K)])
    means = imgs[..., 3:6]
    observed = means.var(axis=0, ddof=1)
    predicted = np.stack([sc.integrator.pixel_variance(im, n)[:, :, 0, :] for im in imgs]).mean(axis=0)
    ratio = predicted.sum(axis=(0, 1)) / observed.sum(axis=(0, 1))
    print("predicted / observed variance per X, Y, Z:", ratio)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio


def test_nested_integrators_are_checked():
    def make(**nested):
        d = scene(4)
        d["integrator"] = {"type": "moment", **nested}
        return pbr.load_dict(d)
    for bad in ("bdpt", "ptracer", "sppm", "mlt", "aov", "moment"):
        kw = {"type": bad}
        if bad == "aov":
            kw["aovs"] = "dd:depth"
        if bad == "moment":
            kw["x"] = {"type": "depth"}
        with pytest.raises(pbr.SceneError, match=r"scene\.integrator\.inner"):
            make(inner=kw)
    with pytest.raises(pbr.SceneError, match=r"scene\.integrator: expected at least one nested"):
        make()
    with pytest.raises(pbr.SceneError, match=r"scene\.integrator\.inner: expected a nested integrator"):
        make(inner={"type": "diffuse"})
    sc = make(first={"type": "depth"}, second={"type": "direct"})
    assert sc.integrator.aov_names == ["first.X", "first.Y", "first.Z", "second.X", "second.Y", "second.Z",
                                       "m2_first.X", "m2_first.Y", "m2_first.Z",
                                       "m2_second.X", "m2_second.Y", "m2_second.Z"]
    assert np.asarray(pbr.render(sc, spp=4)).shape == (4, 4, 15)
