"""``diffusetransmission`` (pbrt-v4): Lambertian reflection r and transmission t on both
sides. Sampling against the density (chi-square, from above and below), energy (the
reflected and transmitted albedos are r and t), reciprocity, parameters and errors, and
renders: with t = 0 it matches Mitsuba's two-sided ``diffuse`` (the statistical image
test), and thin sheets lit from behind or inside a uniform emitter show the analytic
radiance (t F L and (r + t) L)."""

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr import validate
from bsdf_harness import OneBSDF, chi2_bsdf, direction
from mitsuba_scenes import material_box, BATCHES, SPP


LAM = (450.0, 520.0, 600.0, 680.0)
# Piecewise-linear spectra with hand-computable values at LAM (independent of RGB upsampling).
R_SPEC = {"type": "spectrum", "value": [(400.0, 0.2), (700.0, 0.8)]}   # 0.3 0.44 0.6 0.76
T_SPEC = {"type": "spectrum", "value": [(400.0, 0.5), (700.0, 0.2)]}   # 0.45 0.38 0.3 0.22
R_AT = np.array([0.3, 0.44, 0.6, 0.76])
T_AT = np.array([0.45, 0.38, 0.3, 0.22])


def _u(n, seed=5):
    rng = mi.PCG32(n, seed)
    return rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())


def _dt(r=R_SPEC, t=T_SPEC, **kw):
    return {"type": "diffusetransmission", "reflectance": r, "transmittance": t, **kw}


# ----------------------------------------------------------------------- sampling

@pytest.mark.parametrize("theta", [10, 60, 87, 93, 120, 170])
@pytest.mark.parametrize("rt", [(R_SPEC, T_SPEC), (0.9, 0.05), (0.0, 0.6), (0.5, 0.0)],
                         ids=["spectral", "mostly-r", "t-only", "r-only"])
def test_sampling_matches_pdf(theta, rt):
    ok, msg = chi2_bsdf(_dt(*rt), direction(theta, 35))
    assert ok, msg


def test_chi2_rejects_wrong_lobe_probability():
    """The test has power: sampling r = 0.6, t = 0.3 against the density of r = 0.5, t = 0.4
    (lobe probabilities 2/3 vs 5/9) is rejected."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    b, wrong = OneBSDF(_dt(0.6, 0.3)), OneBSDF(_dt(0.5, 0.4))
    wi = direction(40)

    def sample_func(s):
        bs = b.sample(wi, s.x, mi.Point2f(s.y, s.z))
        return bs.wo, dr.select(bs.pdf > 0, 1.0, 0.0)

    t = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func,
                      pdf_func=lambda wo: wrong.eval_pdf(wi, wo)[1], sample_dim=3, sample_count=200_000, res=101)
    assert not t.run(quiet=True)


# ------------------------------------------------------------------------ energy

@pytest.mark.parametrize("theta", [0, 45, 89, 91, 135, 180])
def test_albedos_are_r_and_t(theta):
    """Sampled weights: the reflected part averages to r(lambda), the transmitted part to
    t(lambda), per wavelength; each weight is r / P_r or t / P_t exactly."""
    n = 1 << 18
    wi = direction(theta, 20)
    u1, u2 = _u(n)
    bs = OneBSDF(_dt(), lam=LAM).sample(wi, u1, u2)
    w, wo_z, pdf = np.array(bs.weight), np.array(bs.wo.z), np.array(bs.pdf)
    assert np.all(pdf > 0) and np.all(np.isfinite(w))
    refl = wo_z * (1 if theta < 90 else -1) > 0
    p_r = R_AT.max() / (R_AT.max() + T_AT.max())
    assert abs(refl.mean() - p_r) < 5 * math.sqrt(p_r * (1 - p_r) / n)
    assert np.allclose(w[:, refl], (R_AT / p_r)[:, None], rtol=1e-5)
    assert np.allclose(w[:, ~refl], (T_AT / (1 - p_r))[:, None], rtol=1e-5)
    a_r, a_t = (w * refl).mean(axis=1), (w * ~refl).mean(axis=1)
    tol = 5 * np.sqrt(p_r * (1 - p_r) / n) * np.maximum(R_AT / p_r, T_AT / (1 - p_r))
    assert np.all(np.abs(a_r - R_AT) < tol) and np.all(np.abs(a_t - T_AT) < tol)


def test_eval_integrates_to_r_and_t():
    """Quadrature of f |cos| over each hemisphere (independent of sampling) gives r and t."""
    n_t, n_p = 400, 64
    ct = (np.arange(n_t) + 0.5) / n_t            # uniform in cos(theta): d omega = dcos dphi
    ph = (np.arange(n_p) + 0.5) / n_p * 2 * np.pi
    c, p = np.meshgrid(ct, ph, indexing="ij")
    s = np.sqrt(1 - c * c)
    b = OneBSDF(_dt(), lam=LAM)
    wi = direction(30, 10)
    for sign, expect in ((1, R_AT), (-1, T_AT)):
        wo = mi.Vector3f(mi.Float((s * np.cos(p)).ravel()), mi.Float((s * np.sin(p)).ravel()),
                         mi.Float((sign * c).ravel()))
        f, pdf = b.eval_pdf(wi, wo)
        integral = np.array(f).mean(axis=1) * 2 * np.pi
        assert np.allclose(integral, expect, rtol=1e-5)
        # The density integrates to the lobe probability.
        p_r = R_AT.max() / (R_AT.max() + T_AT.max())
        assert np.array(pdf).mean() * 2 * np.pi == pytest.approx(p_r if sign > 0 else 1 - p_r, rel=1e-5)


def test_reciprocity_and_symmetry():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(2, 3, 5000))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    a, b = (mi.Vector3f(*[mi.Float(x) for x in vv]) for vv in v)
    bsdf = OneBSDF(_dt())
    f_ab = np.array(bsdf.bsdfs.eval_pdf(mi.UInt32(bsdf.id) + dr.zeros(mi.UInt32, 5000), bsdf.ctx(a, 5000), b,
                                        mi.Bool(True))[0])
    f_ba = np.array(bsdf.bsdfs.eval_pdf(mi.UInt32(bsdf.id) + dr.zeros(mi.UInt32, 5000), bsdf.ctx(b, 5000), a,
                                        mi.Bool(True))[0])
    # f(a, b) |cos b| / |cos b| == f(b, a) |cos a| / |cos a|
    za, zb = np.abs(v[0, 2]), np.abs(v[1, 2])
    assert np.allclose(f_ab / zb, f_ba / za, rtol=1e-5)


# -------------------------------------------------------------- parameters, errors

def test_defaults_and_scale_with_clamping():
    wi, down, up = direction(20), mi.Vector3f(0, 0, -1), mi.Vector3f(0, 0, 1)
    f_up, _ = OneBSDF({"type": "diffusetransmission"}).eval_pdf(wi, up)
    f_dn, _ = OneBSDF({"type": "diffusetransmission"}).eval_pdf(wi, down)
    assert np.allclose(np.array(f_up) * math.pi, 0.25) and np.allclose(np.array(f_dn) * math.pi, 0.25)
    # scale multiplies both, then each is clamped to [0, 1] (pbrt-v4).
    b = OneBSDF({"type": "diffusetransmission", "reflectance": 0.7, "transmittance": 0.2, "scale": 2.0})
    assert np.allclose(np.array(b.eval_pdf(wi, up)[0]) * math.pi, 1.0)
    assert np.allclose(np.array(b.eval_pdf(wi, down)[0]) * math.pi, 0.4)


def test_black_bsdf_samples_nothing():
    bs = OneBSDF(_dt(0.0, 0.0)).sample(direction(30), *_u(1000))
    assert np.all(np.array(bs.pdf) == 0) and np.all(np.array(bs.weight) == 0)
    f, pdf = OneBSDF(_dt(0.0, 0.0)).eval_pdf(direction(30), direction(150))
    assert np.all(np.array(f) == 0) and np.all(np.array(pdf) == 0)


def test_textured_transmittance():
    """Textures reach both albedos (a checkerboard transmittance)."""
    d = _dt(0.2, {"type": "checkerboard", "color0": 0.1, "color1": 0.7})
    f, _ = OneBSDF(d).eval_pdf(direction(20), mi.Vector3f(0, 0, -1))   # harness uv = (0.5, 0.5): color0
    assert np.allclose(np.array(f) * math.pi, 0.1)


@pytest.mark.parametrize("bad, match", [
    ({"reflectence": 0.3}, r"scene\.bsdf\.reflectence: unknown parameter"),
    ({"scale": -1.0}, r"scene\.bsdf\.scale: must be >= 0"),
    ({"transmittance": {"type": "rgb", "value": [1.5, 0, 0]}}, r"scene\.bsdf\.transmittance\.value: must be in \[0, 1\]"),
    ({"transmittance": {"type": "nosuch"}}, r"scene\.bsdf\.transmittance: unsupported texture"),
])
def test_errors_name_the_key(bad, match):
    with pytest.raises(pbr.SceneError, match=match):
        OneBSDF({"type": "diffusetransmission", **bad})


def test_traverse_keys():
    d = material_box(_dt({"type": "rgb", "value": [0.3, 0.5, 0.7]}, 0.2))
    keys = set(pbr.traverse(pbr.load_dict(d)).keys())
    assert {"small-box.bsdf.reflectance.value", "small-box.bsdf.transmittance.value"} <= keys


# ------------------------------------------------------------------------- renders

def test_without_transmission_matches_mitsuba_twosided_diffuse(scale):
    """t = 0: the same image as Mitsuba's twosided diffuse; one box's faces are flipped so
    that the camera sees their back sides."""
    rgb_s, rgb_l = [0.2, 0.5, 0.8], [0.7, 0.6, 0.2]
    d_pbr = material_box(_dt({"type": "rgb", "value": rgb_s}, 0.0), _dt({"type": "rgb", "value": rgb_l}, 0.0), scale)
    d_mi = material_box({"type": "twosided", "b": {"type": "diffuse", "reflectance": {"type": "rgb", "value": rgb_s}}},
                        {"type": "twosided", "b": {"type": "diffuse", "reflectance": {"type": "rgb", "value": rgb_l}}},
                        scale)
    for d in (d_pbr, d_mi):
        d["large-box"]["flip_normals"] = True
    scene = pbr.load_dict(d_pbr)
    res = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp)),
                                   validate.mitsuba_render_fn(d_mi), spp=SPP * scale, batches=BATCHES,
                                   seed_a=31, seed_b=32)
    print(res.summary())
    assert res.passed, res.summary()


RES_SHEET, H, A_EM = 32, 0.5, 1.5


def _view(spp):
    return {
        "type": "perspective", "fov": 30.0,
        "to_world": T().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0]),
        "sampler": {"type": "independent", "sample_count": spp},
        "film": {"type": "hdrfilm", "width": RES_SHEET, "height": RES_SHEET, "rfilter": {"type": "box"}},
    }


def T():
    return mi.ScalarTransform4f()


def _render_batches(d, spp, batches, seed=0):
    scene = pbr.load_dict(d)
    return np.stack([np.asarray(pbr.render(scene, seed=seed + i, spp=spp), np.float64) for i in range(batches)])


def _corner_ff(a, b):
    """Form factor from a point to a parallel a x b rectangle (lengths in units of the
    distance) with one corner opposite the point."""
    fa, fb = a / math.sqrt(1 + a * a), b / math.sqrt(1 + b * b)
    return (fa * math.atan(b / math.sqrt(1 + a * a)) + fb * math.atan(a / math.sqrt(1 + b * b))) / (2 * math.pi)


def _form_factor(x, y):
    """From (x, y, 0) to the emitter square [-A_EM, A_EM]^2 at distance H."""
    return sum(_corner_ff((A_EM + sx * x) / H, (A_EM + sy * y) / H) for sx in (-1, 1) for sy in (-1, 1))


# Pixels wholly on the sheet (|x|, |y| < 0.5 at z = 0 is pixels 6..25 of 32 for a 30 degree
# field of view from distance 3) and pixels wholly off it, showing the emitter.
_PIX = 1.6077 / RES_SHEET   # 2 * 3 * tan(15 deg) / 32
_SHEET = (slice(8, 24), slice(8, 24))


@pytest.mark.parametrize("r, t, flip", [(0.0, 0.4, False), (0.5, 0.3, False), (0.8, 0.1, True)])
def test_sheet_lit_from_behind_transmits_t(r, t, flip):
    """A sheet (1 x 1) in front of an emitter (3 x 3 at distance 0.5, black, facing it): the
    camera sees t F L on the sheet, F the form factor to the emitter (0.90 to 0.92 over the
    pixels tested), and L around it. Light the sheet reflects back is absorbed by the black emitter, so r only changes
    the lobe probability. ``flip`` turns the sheet around (the camera sees its back side)."""
    spp, batches = 32, 16
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 4}, "sensor": _view(spp),
         "sheet": {"type": "rectangle", "flip_normals": flip, "to_world": T().scale([0.5, 0.5, 1]),
                   "bsdf": _dt(r, t)},
         "emitter": {"type": "rectangle", "to_world": T().translate([0, 0, -H]).scale([A_EM, A_EM, 1]),
                     "bsdf": {"type": "diffuse", "reflectance": 0.0},
                     "emitter": {"type": "area", "radiance": 3.0}}}
    imgs = _render_batches(d, spp, batches)
    sheet = imgs[:, _SHEET[0], _SHEET[1]].mean(axis=(1, 2))             # (batches, 3)
    ring = np.ones((RES_SHEET, RES_SHEET), bool)
    ring[3:29, 3:29] = False
    em = imgs[:, ring].mean(axis=1)
    ratio = sheet.mean(axis=0) / em.mean(axis=0)
    # Per-batch ratio scatter as the standard error.
    se = (sheet / em).std(axis=0, ddof=1) / math.sqrt(batches)
    c = (np.arange(RES_SHEET) + 0.5 - RES_SHEET / 2) * _PIX
    F = np.mean([_form_factor(x, y) for x in c[_SHEET[1]] for y in c[_SHEET[0]]])
    print(f"ratio {ratio} +- {se}, expected t F = {t * F:.5f} (F = {F:.5f})")
    assert 0.9 < F < 0.92
    assert np.all(np.abs(ratio - t * F) < 5 * se + 1e-4), (ratio, se, t * F)
    assert np.all(se < 0.01 * t)   # the test resolves a 2-3% error


@pytest.mark.parametrize("r, t", [(0.3, 0.5), (0.6, 0.0), (0.1, 0.85)])
def test_sheet_inside_uniform_emitter_shows_r_plus_t(r, t):
    """A sheet inside a uniformly emitting (black) sphere receives L from every direction on
    both sides, so it shows (r + t) L from either side, and the sphere shows L."""
    spp, batches = 32, 16
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 4}, "sensor": _view(spp),
         "sheet": {"type": "rectangle", "to_world": T().rotate([0, 1, 0], 30).scale([0.5, 0.5, 1]),
                   "bsdf": _dt(r, t)},
         "sphere": {"type": "sphere", "radius": 10.0, "flip_normals": True,
                    "bsdf": {"type": "diffuse", "reflectance": 0.0},
                    "emitter": {"type": "area", "radiance": 2.0}}}
    imgs = _render_batches(d, spp, batches, seed=100)
    sheet = imgs[:, 12:20, 13:19].mean(axis=(1, 2))
    ring = np.ones((RES_SHEET, RES_SHEET), bool)
    ring[2:30, 2:30] = False
    em = imgs[:, ring].mean(axis=1)
    ratio = sheet.mean(axis=0) / em.mean(axis=0)
    se = (sheet / em).std(axis=0, ddof=1) / math.sqrt(batches)
    print(f"ratio {ratio} +- {se}, expected {r + t}")
    assert np.all(np.abs(ratio - (r + t)) < 5 * se + 1e-4), (ratio, se)
    assert np.all(se < 0.01 * (r + t))
