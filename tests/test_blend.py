"""blendbsdf (Mitsuba) / mix (pbrt-v4): f = (1 - w) f_0 + w f_1, mixture-consistent sampling."""

import drjit as dr
import numpy as np
import pytest
import mitsuba as mi

import pbr
from bsdf_harness import OneBSDF, chi2_bsdf, direction, furnace
from mitsuba_scenes import material_box, compare_with_mitsuba

A = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}
B = {"type": "roughconductor", "distribution": "ggx", "alpha": 0.25}


def test_eval_is_the_weighted_sum():
    m = OneBSDF({"type": "blendbsdf", "weight": 0.3, "a": A, "b": B})
    a, b = OneBSDF(A), OneBSDF(B)
    wi, wo = direction(30, 0), direction(35, 180)
    fm, pm = (np.array(x) for x in m.eval_pdf(wi, wo))
    fa, pa = (np.array(x) for x in a.eval_pdf(wi, wo))
    fb, pb = (np.array(x) for x in b.eval_pdf(wi, wo))
    assert np.allclose(fm, 0.7 * fa + 0.3 * fb, rtol=1e-5)
    assert np.allclose(pm, 0.7 * pa + 0.3 * pb, rtol=1e-5)


@pytest.mark.parametrize("w", [0.0, 0.3, 0.8])
def test_chi2_mixture(w):
    ok, msg = chi2_bsdf({"type": "mix", "amount": w, "a": A, "b": B}, direction(40, 20))
    assert ok, msg


def test_albedo_is_the_weighted_sum():
    m, _ = furnace({"type": "blendbsdf", "weight": 0.4, "a": A, "b": B}, direction(20), n=1 << 20)
    a, _ = furnace(A, direction(20), n=1 << 20)
    b, _ = furnace(B, direction(20), n=1 << 20)
    assert np.allclose(m, 0.6 * a + 0.4 * b, rtol=5e-3)


def test_blend_of_blend_is_rejected():
    d = pbr.cornell_box(8, 4)
    d["floor"]["bsdf"] = {"type": "mix", "a": A, "b": {"type": "mix", "a": A, "b": B}}
    with pytest.raises(pbr.SceneError, match="scene.floor.bsdf.b: a mix cannot contain another blend"):
        pbr.load_dict(d)


def test_matches_mitsuba(scale):
    d = material_box({"type": "blendbsdf", "weight": 0.35, "a": A, "b": B},
                     {"type": "blendbsdf", "weight": 0.6, "a": {"type": "dielectric"},
                      "b": {"type": "diffuse", "reflectance": 0.4}}, scale)
    res = compare_with_mitsuba(d, scale)
    print(res.summary())
    assert res.passed, res.summary()


def test_blend_components_dispatch_over_their_families_only():
    """A blend evaluates its other component with a dispatch over the families blend
    components have (twosided back sides included), not over every family of the scene:
    the values equal those of a dispatch over all families, for lanes on both sides."""
    from pbr.scene.loader import Loader
    from bsdf_harness import OneBSDF
    blend = {"type": "blendbsdf", "weight": 0.4,
             "a": {"type": "twosided", "a": A, "b": {"type": "plastic"}},
             "b": {"type": "roughconductor", "material": "Cu", "alpha": 0.2}}
    one = OneBSDF(blend)
    B = one.bsdfs
    # Other families in the same set, as in a scene with more materials (the dicts stay
    # alive: the loader caches parsed BSDFs by the dict's identity).
    loader = one.loader
    others = [{"type": "dielectric"}, {"type": "conductor"}, {"type": "principled"}]
    for k, d in enumerate(others):
        loader.bsdf(d, f"scene.other{k}")
    loader.textures.build()
    B.build(loader.textures)
    assert set(B.component_families) == {"diffuse", "plastic", "roughconductor"} < set(B.order)
    rng = np.random.default_rng(5)
    n = 4096
    wi = mi.Vector3f(*rng.normal(size=(3, n)).astype(np.float32))
    wi = dr.normalize(wi)
    wo = dr.normalize(mi.Vector3f(*rng.normal(size=(3, n)).astype(np.float32)))
    u1, u2 = mi.Float(rng.random(n).astype(np.float32)), mi.Point2f(*rng.random((2, n)).astype(np.float32))
    ids = mi.UInt32(one.id) + dr.zeros(mi.UInt32, n)

    def run():
        f, pdf, bs = B.eval_pdf_sample(ids, one.ctx(wi, n), wo, u1, u2, mi.Bool(True))
        fe, pe = B.eval_pdf(ids, one.ctx(wi, n), wo, mi.Bool(True))
        return [np.array(x) for x in (f, pdf, bs.weight, bs.pdf, fe, pe)]

    restricted = run()
    B.component_families, B.component_family_of = B.order, B.family_of       # every family
    full = run()
    assert np.abs(restricted[4]).max() > 0
    for a, b in zip(restricted, full):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


def test_weight_derivative_at_zero():
    """d image / d weight at a weight of 0 (where an optimiser may start, or push it)
    against a one-sided finite difference on the same samples. The weight was clipped
    to [0, 1] with dr.clip, whose derivative is 0 at the bounds: the derivative was
    exactly 0 (a rough gold floor blended with a diffuse one, 16x16, 5 x 1024 spp:
    finite differences 0.261, now 0.259). (At a weight of 1 the diffuse component is
    never sampled: its derivative reaches the image only through the conductor's
    samples and light samples, a noisier estimate; not checked here.)"""
    w0, side = 0.0, 1
    import sys, os
    sys.path.insert(0, os.path.dirname(__file__))
    import grad_scenes as G
    from grad_harness import fd_image, forward_image
    d = G.metal_floor(res=8)
    d["floor"]["bsdf"] = {"type": "blendbsdf", "weight": 0.5, "bsdf_0": {"type": "diffuse", "reflectance": 0.5},
                          "bsdf_1": {"type": "roughconductor", "alpha": 0.1, "material": "Au"}}
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    key = "floor.bsdf.weight.value"
    params[key] = mi.Float(w0)
    params.update()
    g = float(np.mean(forward_image(scene, params, key, mi.Float(1.0), 256, seed=1)))
    r = float(np.mean(fd_image(scene, params, key, mi.Float(1.0), 0.01, 256, seed=1001, side=side)))
    assert abs(g - r) < 0.05 * abs(r), (g, r)
