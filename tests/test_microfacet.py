"""Microfacet distributions: normalisation and sampling (chi-square)."""

import math

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

from pbr.bsdfs.microfacet import Microfacet


def _grid(n=1000):
    th = (np.arange(n) + 0.5) / n * np.pi / 2
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, P = np.meshgrid(th, ph)
    m = mi.Vector3f(mi.Float((np.sin(T) * np.cos(P)).ravel()), mi.Float((np.sin(T) * np.sin(P)).ravel()),
                    mi.Float(np.cos(T).ravel()))
    dA = np.sin(T).ravel() * (np.pi / 2 / n) * (2 * np.pi / (2 * n))
    return m, np.cos(T).ravel(), dA


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
@pytest.mark.parametrize("au, av", [(0.05, 0.05), (0.3, 0.3), (0.2, 0.5), (1.0, 1.0)])
def test_projected_area_is_one(kind, au, av):
    m, cos, dA = _grid(1500 if au < 0.1 else 800)
    D = np.array(Microfacet(kind, mi.Float(au), mi.Float(av)).D(m))
    assert np.sum(D * cos * dA) == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("kind, visible", [("ggx", True), ("ggx", False), ("beckmann", False)])
@pytest.mark.parametrize("au, av, theta", [(0.3, 0.3, 30), (0.3, 0.6, 60), (0.6, 0.3, 85), (1.0, 1.0, 10)])
def test_sampling_matches_pdf(kind, visible, au, av, theta):
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    t = math.radians(theta)
    wi = mi.Vector3f(math.sin(t), 0.0, math.cos(t))
    md = Microfacet(kind, mi.Float(au), mi.Float(av), visible)
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=lambda s: md.sample(wi, s)[0],
                         pdf_func=lambda m: md.pdf(wi, m), sample_dim=2, sample_count=200_000, res=101)
    assert test.run(), test.messages


def test_wrong_pdf_is_rejected():
    """The chi-square test can fail: a pdf for the wrong roughness is rejected."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    wi = mi.Vector3f(math.sin(0.5), 0.0, math.cos(0.5))
    md = Microfacet("ggx", mi.Float(0.3), mi.Float(0.3))
    wrong = Microfacet("ggx", mi.Float(0.33), mi.Float(0.33))
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=lambda s: md.sample(wi, s)[0],
                         pdf_func=lambda m: wrong.pdf(wi, m), sample_dim=2, sample_count=200_000, res=101)
    assert not test.run()
