"""``prb_basic`` (Mitsuba's basic Path Replay Backpropagation integrator: BSDF sampling
only, no next-event estimation, MIS or Russian roulette) against Mitsuba 3's own plugin
(llvm_ad_spectral) with the statistical image test; its gradients are compared with
Mitsuba's in tests/test_ad_vs_mitsuba.py (case ``albedo_prb_basic``).

Must fail: one bounce fewer than Mitsuba's max_depth (the depth convention), and
pbr's ``simplepath`` with ``samplelights=false`` given the same number (pbrt-v4's
``maxdepth`` counts bounces: the same estimator, one bounce more: not an alias).
"""

import numpy as np
import pytest

import pbr
from pbr import validate

RES, SPP, BATCHES = 16, 1024, 16


def box(integrator):
    d = pbr.cornell_box(RES, 16)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = integrator
    return d


def compare(d_pbr, d_mi):
    sc = pbr.load_dict(d_pbr)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(sc, seed=seed, spp=spp))   # noqa: E731
    res = validate.compare_renders(fa, validate.mitsuba_render_fn(d_mi), spp=SPP, batches=BATCHES,
                                   seed_a=21, seed_b=22)
    print(res.summary())
    return res


@pytest.mark.parametrize("kw", [{}, {"max_depth": 3, "hide_emitters": True}])
def test_prb_basic_matches_mitsuba(kw):
    d = box({"type": "prb_basic", **kw})
    res = compare(d, d)
    assert res.passed, res.summary()


def test_one_bounce_fewer_fails():
    d = box({"type": "prb_basic", "max_depth": 3, "hide_emitters": True})
    assert not compare(box({"type": "prb_basic", "max_depth": 2, "hide_emitters": True}), d).passed


def test_simplepath_is_not_an_alias():
    d = box({"type": "prb_basic", "max_depth": 2, "hide_emitters": True})
    sp = {"type": "simplepath", "samplelights": False, "hide_emitters": True}
    assert not compare(box({**sp, "maxdepth": 2}), d).passed
    # With pbrt-v4's count (bounces: max_depth - 1) it is the same estimator.
    assert compare(box({**sp, "maxdepth": 1}), d).passed


def test_parameters():
    sc = pbr.load_dict(box({"type": "prb_basic"}))
    assert sc.integrator.max_depth == 6 and not sc.integrator.next_event
    pbr.load_dict(box({"type": "prb_basic", "rr_depth": 2}))          # accepted, unused (as Mitsuba)
    with pytest.raises(pbr.SceneError, match=r"scene\.integrator\.light_sampler"):
        pbr.load_dict(box({"type": "prb_basic", "light_sampler": "bvh"}))
