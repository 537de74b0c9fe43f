"""Helpers for BSDF unit tests: build one BSDF from a Mitsuba-style dict, evaluate and
sample it for given local directions, chi-square tests (Mitsuba's ``mitsuba.chi2``)
and white-furnace estimates."""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from pbr.bsdfs.base import ShadingContext
from pbr.scene.loader import Loader
from pbr.spectrum import SampledWavelengths


class OneBSDF:
    """A BSDF dict loaded on its own, with a shading context for a local ``wi``."""

    def __init__(self, bsdf: dict, lam=(450.0, 520.0, 600.0, 680.0)):
        self.loader = Loader({"type": "scene"})
        self.id = self.loader.bsdf(bsdf, "scene.bsdf")
        self.loader.textures.build()
        self.loader.bsdfs.build(self.loader.textures)
        self.bsdfs = self.loader.bsdfs
        self.lam = lam

    def ctx(self, wi, n):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = wi
        si.uv = mi.Point2f(0.5, 0.5)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        si.n = mi.Vector3f(0, 0, 1)
        wl = SampledWavelengths(mi.Spectrum(*[mi.Float(l) for l in self.lam]) + dr.zeros(mi.Spectrum, n),
                                mi.Spectrum(1.0 / 470.0))
        return ShadingContext(si, wl)

    def eval_pdf(self, wi, wo):
        n = dr.width(wo)
        wi = mi.Vector3f(wi) + dr.zeros(mi.Vector3f, n)
        return self.bsdfs.eval_pdf(mi.UInt32(self.id) + dr.zeros(mi.UInt32, n), self.ctx(wi, n), wo, mi.Bool(True))

    def sample(self, wi, u1, u2):
        n = dr.width(u1)
        wi = mi.Vector3f(wi) + dr.zeros(mi.Vector3f, n)
        return self.bsdfs.sample(mi.UInt32(self.id) + dr.zeros(mi.UInt32, n), self.ctx(wi, n), u1, u2, mi.Bool(True))


def direction(theta_deg: float, phi_deg: float = 0.0) -> mi.Vector3f:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return mi.Vector3f(math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def chi2_bsdf(bsdf: dict, wi, sample_count=200_000, res=101, **kw) -> tuple[bool, str]:
    """Chi-square test of ``sample`` against ``pdf`` over the sphere of outgoing directions."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    b = OneBSDF(bsdf, **kw)

    def sample_func(s):
        # Failed samples (pdf 0) count with weight 0: the pdf then integrates to the
        # fraction of successful samples, which the test accounts for.
        bs = b.sample(wi, s.x, mi.Point2f(s.y, s.z))
        ok = (bs.pdf > 0) & ~bs.delta
        return dr.select(ok, bs.wo, mi.Vector3f(0, 0, 1)), dr.select(ok, 1.0, 0.0)

    def pdf_func(wo):
        return b.eval_pdf(wi, wo)[1]

    t = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                      sample_dim=3, sample_count=sample_count, res=res)
    ok = t.run()
    return ok, t.messages


def furnace(bsdf: dict, wi, n=1 << 18, **kw) -> np.ndarray:
    """Monte Carlo estimate of the directional albedo int f |cos| dwo per wavelength
    (the mean sampled weight), and its maximum weight."""
    b = OneBSDF(bsdf, **kw)
    u = (dr.arange(mi.Float, n) + 0.5) / n
    rng = mi.PCG32(n)
    bs = b.sample(wi, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()))
    w = np.array(bs.weight)
    del u
    return w.mean(axis=1), w.max(axis=1)


def chi2_rotated(bsdf: dict, wi, pdf_bsdf: dict | None = None, test_count: int = 1, seed: int = 0,
                 make=None, sample_count: int = 200_000):
    """Chi-square test of ``sample`` against ``eval_pdf`` robust to sharp lobes: Mitsuba's
    (phi, cos theta) cells are degenerate at the poles, where near-normal lobes lie, so the
    directions are rotated (a measure-preserving map) to put the local normal on the test's
    equator, and cells are integrated with 16x16 points. Failed samples (pdf 0) weigh 0;
    ``pdf_bsdf`` supplies a (deliberately wrong) density; ``seed`` varies the samples.
    Returns (passed, p-value, messages)."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    make = make or OneBSDF
    b = make(bsdf)
    p = b if pdf_bsdf is None else make(pdf_bsdf)

    def sample_func(s):
        bs = b.sample(wi, s.x, mi.Point2f(s.y, s.z))
        return mi.Vector3f(bs.wo.x, bs.wo.z, -bs.wo.y), dr.select(bs.pdf > 0, 1.0, 0.0)

    def pdf_func(v):
        return p.eval_pdf(wi, mi.Vector3f(v.x, -v.z, v.y))[1]

    t = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                      sample_dim=3, sample_count=sample_count, res=101, ires=16, seed=seed)
    ok = t.run(test_count=test_count, quiet=True)
    return ok, getattr(t, "p_value", float("nan")), t.messages


def random_samples(n, seed=7):
    """(u1, u2) uniform samples for ``sample`` calls."""
    rng = mi.PCG32(n, seed)
    return rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())


def random_directions(n, seed=3, upper=False):
    """``n`` uniformly distributed unit vectors (on the upper hemisphere if ``upper``)."""
    v = np.random.default_rng(seed).normal(size=(3, n))
    v /= np.linalg.norm(v, axis=0)
    if upper:
        v[2] = np.abs(v[2])
    return mi.Vector3f(*[mi.Float(x) for x in v])


def shared_family_results(bsdfs, wi, wo, samples=None, make=None):
    """Load several BSDF dicts into one scene (so instances of a family share one
    parameter table) and yield, per instance, the values through the shared table next to
    the instance loaded alone: dicts with f, pdf, f_alone, pdf_alone and, when ``samples``
    (u1, u2) are given, bs and bs_alone."""
    make = make or OneBSDF
    loader = Loader({"type": "scene"})
    ids = [loader.bsdf(dict(d), f"scene.b{i}") for i, d in enumerate(bsdfs)]
    loader.textures.build()
    loader.bsdfs.build(loader.textures)
    n = dr.width(wo)
    one = make(bsdfs[0])
    for i, d in zip(ids, bsdfs):
        alone = make(d)
        sel = mi.UInt32(i) + dr.zeros(mi.UInt32, n)
        ctx = one.ctx(mi.Vector3f(wi) + dr.zeros(mi.Vector3f, n), n)
        f, pdf = loader.bsdfs.eval_pdf(sel, ctx, wo, mi.Bool(True))
        fa, pa = alone.eval_pdf(wi, wo)
        r = {"f": np.array(f), "pdf": np.array(pdf), "f_alone": np.array(fa), "pdf_alone": np.array(pa)}
        if samples is not None:
            u1, u2 = samples
            r["bs"] = loader.bsdfs.sample(sel, ctx, u1, u2, mi.Bool(True))
            r["bs_alone"] = alone.sample(wi, u1, u2)
        yield r


def assert_scene_error(bsdf: dict, key: str, text: str) -> None:
    """Loading ``bsdf`` raises a SceneError whose message names ``key`` and says ``text``."""
    import pytest
    from pbr.plugins.props import SceneError
    with pytest.raises(SceneError) as e:
        OneBSDF(bsdf)
    assert key in str(e.value) and text in str(e.value), str(e.value)
