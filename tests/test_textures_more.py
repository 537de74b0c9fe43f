"""Texture combinators: pbrt-v4's ``scale`` and ``mix`` (arbitrarily nested over constants,
checkerboards and bitmaps) and Mitsuba's ``checkerboard`` with textured colours. Values
against hand-computed spectra, emitters (D65 applied once), gradients, key paths in
errors and in ``pbr.traverse``, and renders against Mitsuba (``mix`` and ``scale`` of a
diffuse albedo equal Mitsuba's ``blendbsdf`` of diffuse BSDFs, by linearity)."""

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr.scene.loader import Loader
from pbr import spectrum as spec
from pbr import textures as tx
from pbr.textures import load_spectrum
from mitsuba_scenes import material_box, compare_with_mitsuba, gradient_png
from test_mitsuba_compare import small_box, check

LAM = (450.0, 520.0, 600.0, 680.0)
# Piecewise-linear spectra: exact, hand-computable values at LAM.
A = {"type": "spectrum", "value": [(400.0, 0.2), (700.0, 0.8)]}    # 0.3  0.44 0.6  0.76
B = {"type": "spectrum", "value": [(400.0, 0.9), (700.0, 0.3)]}    # 0.8  0.66 0.5  0.34
A_AT = np.array([0.3, 0.44, 0.6, 0.76])
B_AT = np.array([0.8, 0.66, 0.5, 0.34])


class Tex:
    """Textures loaded on their own; ``ev(name, uv)`` evaluates one at the wavelengths LAM."""

    def __init__(self, defs: dict, emitter=False):
        self.loader = Loader({"type": "scene"})
        self.slots = {k: load_spectrum(self.loader, v, f"scene.{k}", emitter) for k, v in defs.items()}
        self.set = self.loader.textures
        self.set.build()

    def ev(self, name, uv=(0.5, 0.5), illuminant=True):
        u = np.atleast_1d(np.asarray(uv, np.float64).T[0])
        v = np.atleast_1d(np.asarray(uv, np.float64).T[1])
        lam = mi.Spectrum(*[mi.Float(l) + dr.zeros(mi.Float, len(u)) for l in LAM])
        out = self.set.eval(mi.UInt32(self.slots[name]) + dr.zeros(mi.UInt32, len(u)),
                            mi.Point2f(mi.Float(u), mi.Float(v)), lam, mi.Bool(True), illuminant)
        return np.array(out).T.squeeze()


# ------------------------------------------------------------------------ values

def test_scale_and_mix_of_constants():
    t = Tex({"s": {"type": "scale", "tex": A, "scale": 0.5},
             "s_spec": {"type": "scale", "tex": A, "scale": B},
             "m": {"type": "mix", "tex1": A, "tex2": B, "amount": 0.25},
             "m_spec": {"type": "mix", "tex1": A, "tex2": B, "amount": A},
             "m_default": {"type": "mix"},
             "s_default": {"type": "scale", "scale": 3.0},
             "plain": A})
    assert np.allclose(t.ev("s"), 0.5 * A_AT, rtol=1e-5)
    assert np.allclose(t.ev("s_spec"), A_AT * B_AT, rtol=1e-5)
    assert np.allclose(t.ev("m"), 0.75 * A_AT + 0.25 * B_AT, rtol=1e-5)
    assert np.allclose(t.ev("m_spec"), (1 - A_AT) * A_AT + A_AT * B_AT, rtol=1e-5)
    assert np.allclose(t.ev("m_default"), 0.5)          # pbrt-v4: tex1 0, tex2 1, amount 0.5
    assert np.allclose(t.ev("s_default"), 3.0)          # tex defaults to 1
    assert np.allclose(t.ev("plain"), A_AT, rtol=1e-5)  # plain slots are unaffected


def test_arbitrary_nesting():
    nested = {"type": "scale", "scale": 2.0, "tex": {
        "type": "mix", "amount": {"type": "scale", "tex": 0.5, "scale": 0.5},
        "tex1": {"type": "mix", "tex1": A, "tex2": B, "amount": 0.5},
        "tex2": {"type": "scale", "tex": {"type": "scale", "tex": B, "scale": 0.5}, "scale": A}}}
    t = Tex({"n": nested, "plain": B})
    inner1 = 0.5 * (A_AT + B_AT)
    inner2 = 0.5 * B_AT * A_AT
    assert np.allclose(t.ev("n"), 2.0 * (0.75 * inner1 + 0.25 * inner2), rtol=1e-5)
    assert np.allclose(t.ev("plain"), B_AT, rtol=1e-5)
    assert t.set.depth == 4


def test_descent_only_follows_deep_children(monkeypatch):
    """A deep chain costs one extra leaf evaluation per level, not three: the scale chain
    scale(scale(scale(A, 0.5), 0.5), 0.5) needs 4 leaf evaluations, not 3^3 = 27."""
    t = Tex({"chain": {"type": "scale", "scale": 0.5, "tex": {
        "type": "scale", "scale": 0.5, "tex": {"type": "scale", "tex": A, "scale": 0.5}}}})
    calls = []
    orig = tx.TextureSet._eval_leaf
    monkeypatch.setattr(tx.TextureSet, "_eval_leaf", lambda self, *a: calls.append(1) or orig(self, *a))
    assert np.allclose(t.ev("chain"), 0.125 * A_AT, rtol=1e-5)
    assert len(calls) == 4


def test_reach_traces_only_what_the_slots_use():
    """``eval(..., reach=slots)`` (what BSDF families pass: their instances' slots) gives
    the values of an unrestricted evaluation, for every slot of a set that mixes every
    kind and spectrum base, while tracing only what the slots reach (an RGB albedo's
    lookup holds no tabulated-spectrum or bitmap code)."""
    bmp = {"type": "bitmap", "data": _img(), "filter_type": "bilinear"}
    rgb = {"type": "rgb", "value": [0.7, 0.2, 0.1]}
    t = Tex({"rgb": rgb, "tab": A, "bmp": bmp,
             "ck": {"type": "checkerboard", "color0": rgb, "color1": B},
             "m": {"type": "mix", "tex1": bmp, "tex2": A, "amount": {"type": "checkerboard"}}})
    uv = np.array(UV4 + [(0.1, 0.9), (0.6, 0.4)])
    lam = mi.Spectrum(*[mi.Float(l) + dr.zeros(mi.Float, len(uv)) for l in LAM])
    st = mi.Point2f(mi.Float(uv[:, 0]), mi.Float(uv[:, 1]))

    def ev(slot, reach):
        s = mi.UInt32(slot) + dr.zeros(mi.UInt32, len(uv))
        return np.array(t.set.eval(s, st, lam, mi.Bool(True), reach=reach))

    for name, slot in t.slots.items():
        assert np.allclose(ev(slot, (slot,)), ev(slot, None), rtol=1e-6, atol=1e-7), name
    both = (t.slots["rgb"], t.slots["ck"])
    assert np.allclose(ev(t.slots["ck"], both), ev(t.slots["ck"], None), rtol=1e-6)
    f_all, f_rgb = t.set.features(), t.set.features((t.slots["rgb"],))
    assert f_all.has_table and f_all.bitmaps and f_all.composites
    assert not (f_rgb.has_table or f_rgb.bitmaps or f_rgb.composites or f_rgb.checkers)
    assert f_rgb.leaf_kinds == {tx.CONSTANT}
    f_ck = t.set.features((t.slots["ck"],))           # a checkerboard reaches its colours
    assert f_ck.has_table and f_ck.has_sigmoid and f_ck.checkers and not f_ck.bitmaps


def _img():
    img = np.zeros((2, 2, 3), np.float32)
    img[0, 0] = [0.8, 0.1, 0.1]
    img[0, 1] = [0.1, 0.8, 0.1]
    img[1, 0] = [0.1, 0.1, 0.8]
    img[1, 1] = [0.5, 0.5, 0.5]
    return img


UV4 = [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)]


def test_over_bitmaps_and_checkerboards():
    bmp = {"type": "bitmap", "data": _img(), "filter_type": "nearest"}
    ck = {"type": "checkerboard", "color0": 0.0, "color1": 1.0}       # 0 at (.25,.25) and (.75,.75)
    t = Tex({"bmp": bmp, "ck": ck,
             "s": {"type": "scale", "tex": bmp, "scale": 0.5},
             "m": {"type": "mix", "tex1": bmp, "tex2": A, "amount": ck},
             "m_bmp_amount": {"type": "mix", "tex1": A, "tex2": B, "amount": bmp}})
    b = t.ev("bmp", UV4)
    assert np.allclose(t.ev("s", UV4), 0.5 * b, rtol=1e-5)
    m = t.ev("m", UV4)
    for i, on in enumerate([0, 1, 1, 0]):
        assert np.allclose(m[i], A_AT if on else b[i], rtol=1e-5)
    assert np.allclose(t.ev("m_bmp_amount", UV4), (1 - b) * A_AT + b * B_AT, rtol=1e-5)


def test_checkerboard_with_textured_colours():
    """Mitsuba's checkerboard takes any texture as a colour; colours are evaluated at the
    surface uv (not the checkerboard's to_uv)."""
    bmp = {"type": "bitmap", "data": _img(), "filter_type": "nearest"}
    t = Tex({"bmp": bmp,
             "ck": {"type": "checkerboard", "color0": bmp, "color1": {"type": "scale", "tex": A, "scale": 0.5},
                    "to_uv": mi.ScalarTransform4f().scale([2, 2, 1])}})
    uv = [(0.1, 0.1), (0.3, 0.1), (0.6, 0.1), (0.8, 0.1), (0.3, 0.3)]
    b, c = t.ev("bmp", uv), t.ev("ck", uv)
    for i, second in enumerate([False, True, False, True, False]):
        assert np.allclose(c[i], 0.5 * A_AT if second else b[i], rtol=1e-5)
    assert t.set.kind_of(t.slots["ck"]) == tx.COMPOSITE


def test_emitter_scale_applies_d65_once():
    """In an emitter the scaled texture is an illuminant, the factor is not."""
    t = Tex({"rgb": {"type": "rgb", "value": [0.8, 0.4, 0.2]},
             "s": {"type": "scale", "tex": {"type": "rgb", "value": [0.8, 0.4, 0.2]}, "scale": 3.0},
             "m": {"type": "mix", "tex1": {"type": "rgb", "value": [0.8, 0.4, 0.2]}, "tex2": 2.0, "amount": 0.5}},
            emitter=True)
    e = t.ev("rgb")
    d65 = np.array(spec.d65(mi.Spectrum(*LAM))).ravel()
    assert np.allclose(t.ev("s"), 3.0 * e, rtol=1e-5)
    # A float in an emitter is a grey illuminant: 2 * D65 (up to the grey upsampling).
    grey2 = Tex({"g": 2.0}, emitter=True).ev("g")
    assert np.allclose(grey2, 2.0 * d65, rtol=1e-3)
    assert np.allclose(t.ev("m"), 0.5 * e + 0.5 * grey2, rtol=1e-5)
    # Light power estimates see the composite too.
    cv = t.set.constant_value
    assert cv(t.slots["s"]) == pytest.approx(3.0 * cv(t.slots["rgb"]))


def test_gradients_reach_the_leaves():
    t = Tex({"m": {"type": "mix", "tex1": A, "tex2": 0.9, "amount": 0.25},
             "s": {"type": "scale", "tex": 0.4, "scale": 0.5}})
    items = t.set.items
    amount = next(it for it in items if getattr(it, "path", "") == "m.amount")
    tex2 = next(it for it in items if getattr(it, "path", "") == "m.tex2")
    sc = next(it for it in items if getattr(it, "path", "") == "s.scale")
    for it in (amount, tex2, sc):
        dr.enable_grad(it.params["value"])
    t.set.build()
    lam = mi.Spectrum(*LAM)
    v = t.set.eval(mi.UInt32(t.slots["m"]), mi.Point2f(0.5, 0.5), lam, mi.Bool(True), False)
    w = t.set.eval(mi.UInt32(t.slots["s"]), mi.Point2f(0.5, 0.5), lam, mi.Bool(True), False)
    dr.backward(dr.sum(v[0]) + dr.sum(w[0]))
    assert float(dr.grad(amount.params["value"])[0]) == pytest.approx(0.9 - A_AT[0], rel=1e-5)
    assert float(dr.grad(tex2.params["value"])[0]) == pytest.approx(0.25, rel=1e-5)
    assert float(dr.grad(sc.params["value"])[0]) == pytest.approx(0.4, rel=1e-5)


# ------------------------------------------------------------ errors, traverse

@pytest.mark.parametrize("tex, match", [
    ({"type": "mix", "tex1": 0.2, "amout": 0.3}, r"scene\.m\.bsdf\.reflectance\.amout: unknown parameter 'amout'"),
    ({"type": "scale", "tex": {"type": "rgb", "value": [2, 0, 0]}},
     r"scene\.m\.bsdf\.reflectance\.tex\.value: must be in \[0, 1\] \(an albedo\)"),
    ({"type": "mix", "tex2": {"type": "scale", "tex": {"type": "bogus"}}},
     r"scene\.m\.bsdf\.reflectance\.tex2\.tex: unsupported texture/spectrum type 'bogus'"),
    ({"type": "scale", "scale": "x"}, r"scene\.m\.bsdf\.reflectance\.scale: expected a float or a texture"),
    ({"type": "checkerboard", "color0": {"type": "mix", "tex1": 0.1, "what": 1}},
     r"scene\.m\.bsdf\.reflectance\.color0\.what: unknown parameter"),
])
def test_errors_name_the_key_path(tex, match):
    d = pbr.cornell_box(8, 4)
    d["m"] = {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": tex}}
    with pytest.raises(pbr.SceneError, match=match):
        pbr.load_dict(d)


def test_traverse_and_update():
    d = material_box({"type": "diffuse", "reflectance": {
        "type": "mix", "tex1": {"type": "bitmap", "data": _img()},
        "tex2": {"type": "rgb", "value": [0.2, 0.3, 0.4]},
        "amount": {"type": "scale", "tex": 0.5, "scale": 0.8}}})
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    keys = set(params.keys())
    assert {"small-box.bsdf.reflectance.tex1.data", "small-box.bsdf.reflectance.tex2.value",
            "small-box.bsdf.reflectance.amount.tex.value", "small-box.bsdf.reflectance.amount.scale.value"} <= keys
    # Updating a leaf below two combinators changes the render (amount 0.4 -> 0).
    a = np.asarray(pbr.render(scene, spp=16, seed=1))
    params["small-box.bsdf.reflectance.amount.scale.value"] = mi.Float(0.0)
    params.update()
    b = np.asarray(pbr.render(scene, spp=16, seed=1))
    assert np.abs(a - b).max() > 1e-3


# -------------------------------------------------------------------- renders

_png = gradient_png


def test_mix_and_scale_match_mitsuba_blendbsdf(tmp_path, scale):
    """diffuse(mix(X, Y, a)) == blendbsdf(diffuse(X), diffuse(Y), weight a) and
    diffuse(scale(X, s)) == blendbsdf(diffuse(0), diffuse(X), weight s), by linearity."""
    png = _png(tmp_path)
    bmp = {"type": "bitmap", "filename": png}
    rgb = {"type": "rgb", "value": [0.2, 0.3, 0.8]}
    d_pbr, d_mi = small_box(scale), small_box(scale)
    d_pbr["back"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "mix", "tex1": bmp, "tex2": rgb, "amount": 0.3}}
    d_mi["back"]["bsdf"] = {"type": "blendbsdf", "weight": 0.3, "a": {"type": "diffuse", "reflectance": bmp},
                            "b": {"type": "diffuse", "reflectance": rgb}}
    d_pbr["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "scale", "tex": bmp, "scale": 0.6}}
    d_mi["floor"]["bsdf"] = {"type": "blendbsdf", "weight": 0.6, "a": {"type": "diffuse", "reflectance": 0.0},
                             "b": {"type": "diffuse", "reflectance": bmp}}
    check(d_pbr, d_mi, scale)


def test_checkerboard_of_textures_matches_mitsuba(tmp_path, scale):
    png = _png(tmp_path)
    d = small_box(scale)
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {
        "type": "checkerboard", "color0": {"type": "bitmap", "filename": png},
        "color1": {"type": "rgb", "value": [0.1, 0.2, 0.6]},
        "to_uv": mi.ScalarTransform4f().scale([4, 4, 1])}}
    res = compare_with_mitsuba(d, scale)
    print(res.summary())
    assert res.passed, res.summary()


def test_top_level_scale_and_mix_textures_load():
    import pbr
    d = pbr.cornell_box(8, 4)
    d["tint"] = {"type": "scale", "tex": {"type": "rgb", "value": [0.5, 0.5, 0.5]}, "scale": 0.5}
    d["blend"] = {"type": "mix", "tex1": 0.2, "tex2": 0.8, "amount": 0.25}
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "ref", "id": "blend"}}
    scene = pbr.load_dict(d)
    assert np.all(np.isfinite(np.asarray(pbr.render(scene))))
