"""roughplastic: sampling vs density (chi-square), energy, extreme parameters, the
precomputed coating tables against brute-force integration, agreement with Mitsuba 3's
plugin (BSDF values and images), and that the image comparison catches a wrong model."""

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from bsdf_harness import OneBSDF, direction, chi2_rotated, random_directions, random_samples, shared_family_results, assert_scene_error
from mitsuba_scenes import compare_with_mitsuba, material_box
from pbr.bsdfs import roughplastic as rp


def _rp(dist="beckmann", alpha=0.1, **kw):
    return {"type": "roughplastic", "distribution": dist, "alpha": alpha, **kw}


def _mi_si(wi, n):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi) + dr.zeros(mi.Vector3f, n)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wavelengths = mi.Spectrum(500.0)
    return si


# ----------------------------------------------------------------------- chi-square

def _chi2(bsdf, wi, pdf_bsdf=None, test_count=1, seed=0):
    """bsdf_harness.chi2_rotated: (passed, p-value, messages)."""
    return chi2_rotated(bsdf, wi, pdf_bsdf, test_count, seed)

_CHI2 = [(d, a, th, v) for d in ("beckmann", "ggx") for a, th in ((0.1, 0), (0.1, 60), (0.3, 30), (0.3, 85),
                                                                   (0.8, 45), (0.8, 89))
         for v in (True,)] + [("ggx", 0.2, 70, False), ("ggx", 0.5, 10, False), ("beckmann", 0.05, 40, True)]


@pytest.mark.parametrize("dist, alpha, theta, visible", _CHI2, ids=[f"{d}-a{a}-{t}deg-{'vis' if v else 'dcos'}"
                                                                   for d, a, t, v in _CHI2])
def test_sampling_matches_pdf(dist, alpha, theta, visible):
    d = _rp(dist, alpha, sample_visible=visible, int_ior=1.3 + alpha,
            diffuse_reflectance={"type": "rgb", "value": [0.8, 0.3, 0.1]})
    ok, p, msg = _chi2(d, direction(theta, 25), test_count=len(_CHI2) + 1,
                       seed=_CHI2.index((dist, alpha, theta, visible)))
    print(f"p-value {p:.4g}")
    assert ok, msg


def test_chi2_rejects_a_wrong_density():
    """The test has power: the density of a 10% rougher coating is rejected (a dark
    base, so that most samples are glossy), and so is the lobe choice of a base twice
    as bright (glossy probability 0.43 instead of 0.60)."""
    good = _rp("ggx", 0.3, diffuse_reflectance=0.05)
    assert _chi2(good, direction(40))[0]
    assert not _chi2(good, direction(40), pdf_bsdf={**good, "alpha": 0.33})[0]
    assert not _chi2(good, direction(40), pdf_bsdf={**good, "diffuse_reflectance": 0.1})[0]


def test_weights_are_eval_over_pdf():
    for d, theta in [(_rp("ggx", 0.3), 40), (_rp("beckmann", 0.1, nonlinear=True), 75)]:
        b, wi = OneBSDF(d), direction(theta, 15)
        u1, u2 = random_samples(50_000)
        bs = b.sample(wi, u1, u2)
        f, pdf = b.eval_pdf(wi, bs.wo)
        ok = np.array(bs.pdf) > 0
        assert ok.mean() > 0.95 and not np.any(np.array(bs.delta))
        assert np.allclose(np.array(pdf)[ok], np.array(bs.pdf)[ok], rtol=1e-5)
        assert np.allclose(np.array(f)[:, ok] / np.array(pdf)[ok], np.array(bs.weight)[:, ok], rtol=1e-4, atol=1e-7)


# ------------------------------------------------------------------------- energy

def _albedo(d, wi, n=1 << 19):
    u1, u2 = random_samples(n)
    w = np.array(OneBSDF(d).sample(wi, u1, u2).weight)[0].astype(np.float64)
    return w.mean(), w.std() / math.sqrt(n)


@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
@pytest.mark.parametrize("ior", [1.5, 1.05, 1 / 1.4])
def test_white_albedo_at_most_one(dist, alpha, ior):
    """A white base under the coating reflects at most all light. Slack 2e-3: the
    model's T(cos_i) is linearly interpolated over 64 nodes, which overestimates it
    where it is convex (near total internal reflection from outside, eta < 1, small
    roughness): Mitsuba's white roughplastic reaches 1.0003 there, this one 1.001."""
    for theta in (0, 50, 80, 89.9):
        mean, sigma = _albedo(_rp(dist, alpha, int_ior=ior, ext_ior=1.0, diffuse_reflectance=1.0), direction(theta))
        assert 0.05 < mean < 1.0 + 4 * sigma + 2e-3, (theta, mean, sigma)


def _quadrature_albedo(d, wi, n=1000):
    """int f |cos| dwo by the midpoint rule in (cos theta_o, phi_o)."""
    c = (np.arange(n) + 0.5) / n
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    C, P = np.meshgrid(c, ph)
    s = np.sqrt(1 - C * C)
    wo = mi.Vector3f(mi.Float((s * np.cos(P)).ravel()), mi.Float((s * np.sin(P)).ravel()), mi.Float(C.ravel()))
    f = np.array(OneBSDF(d).eval_pdf(wi, wo)[0])[0].astype(np.float64)
    return f.sum() * (1.0 / n) * (np.pi / n)


@pytest.mark.parametrize("d, theta", [(_rp("ggx", 0.3, diffuse_reflectance=0.8), 30),
                                      (_rp("beckmann", 0.2, int_ior=1.8, nonlinear=True), 70),
                                      (_rp("ggx", 0.6, sample_visible=False, specular_reflectance=0.5), 55)])
def test_sampled_albedo_equals_integral_of_eval(d, theta):
    wi = direction(theta, 10)
    mean, sigma = _albedo(d, wi)
    ref = _quadrature_albedo(d, wi)
    assert abs(mean - ref) < 4 * sigma + 1e-3 * ref, (mean, sigma, ref)


def _mitsuba_albedo(d, wi, n=1 << 19):
    u1, u2 = random_samples(n, seed=11)
    w = np.array(mi.load_dict(d).sample(mi.BSDFContext(), _mi_si(wi, n), u1, u2)[1])[0].astype(np.float64)
    return w.mean(), w.std() / math.sqrt(n)


@pytest.mark.parametrize("d", [_rp("beckmann", 0.1, diffuse_reflectance=1.0),
                               _rp("ggx", 0.8, diffuse_reflectance=1.0),
                               _rp("beckmann", 0.4, int_ior=1.9, diffuse_reflectance=0.7, nonlinear=True)])
def test_albedo_matches_mitsuba(d):
    """Mitsuba's tables carry a quadrature error up to ~3e-3 (see the table tests):
    albedos agree to 0.6%."""
    for theta in (0, 45, 80, 89):
        a, sa = _albedo(d, direction(theta))
        b, sb = _mitsuba_albedo(d, direction(theta))
        assert abs(a - b) < 4 * math.hypot(sa, sb) + 6e-3 * b, (theta, a, b)


# ------------------------------------------------------------------- Mitsuba values

@pytest.mark.parametrize("d", [_rp("ggx", 0.3), _rp("beckmann", 0.1, specular_reflectance=0.6),
                               _rp("ggx", 0.05, int_ior=1.9, nonlinear=True, diffuse_reflectance=0.9),
                               _rp("beckmann", 0.7, sample_visible=False, int_ior=1.0, ext_ior=1.4)])
@pytest.mark.parametrize("theta", [0, 40, 75, 88])
def test_eval_matches_mitsuba(d, theta):
    """The glossy lobe equals Mitsuba's to float precision; the full value (with the
    diffuse lobe and its tabulated coating terms) to 1%; GGX visible-normal densities
    (the same sampling scheme) to 2%: the glossy lobe's probability is proportional to
    1 - T(cos_i), which amplifies the table differences (0.8% at normal incidence)."""
    n = 20_000
    wi, wo = direction(theta, 30), random_directions(upper=True, n=n)
    m = mi.load_dict(d)
    f, pdf = OneBSDF(d).eval_pdf(wi, wo)
    fm, pm = m.eval_pdf(mi.BSDFContext(), _mi_si(wi, n), wo)
    f, fm = np.array(f)[0], np.array(fm)[0]
    assert np.allclose(f, fm, rtol=1e-2, atol=1e-6 * fm.max())
    g = np.array(OneBSDF({**d, "diffuse_reflectance": 0.0}).eval_pdf(wi, wo)[0])[0]
    gm = np.array(mi.load_dict({**d, "diffuse_reflectance": 0.0}).eval(mi.BSDFContext(), _mi_si(wi, n), wo))[0]
    assert np.allclose(g, gm, rtol=2e-4, atol=1e-6 * gm.max())
    if d["distribution"] == "ggx" and d.get("sample_visible", True):
        assert np.allclose(np.array(pdf), np.array(pm), rtol=2e-2, atol=1e-6)


def _mitsuba_coating(d):
    """Mitsuba's transmittance table (at its nodes) and internal reflectance, recovered
    from its diffuse lobe: with nonlinear, f = rho / (1 - rho R_int) T_i T_o mu / (eta^2 pi)."""
    mu = rp.table_cosines()
    wi = mi.Vector3f(mi.Float(np.sqrt(1 - mu ** 2)), 0.0, mi.Float(mu))
    ctx = mi.BSDFContext()
    ctx.component = 1
    fs = []
    for rho in (1.0, 0.5):
        b = mi.load_dict({**d, "diffuse_reflectance": rho, "nonlinear": True})
        si = _mi_si(mi.Vector3f(0, 0, 1), len(mu))
        si.wi = wi
        fs.append(np.array(b.eval(ctx, si, mi.Vector3f(-wi.x, 0.0, wi.z)))[0].astype(np.float64))
    r = fs[0][40] / fs[1][40]
    r_int = (2 - r) / (1 - r)
    eta = d["int_ior"] / d.get("ext_ior", 1.000277)
    return np.sqrt(fs[0] * eta ** 2 * np.pi * (1 - r_int) / mu), r_int


@pytest.mark.parametrize("dist, alpha, ior", [("ggx", 0.3, 1.49), ("beckmann", 0.1, 1.49), ("ggx", 0.01, 1.9),
                                              ("beckmann", 0.8, 1.2), ("ggx", 0.6, 1 / 1.33)])
def test_coating_tables_match_mitsuba(dist, alpha, ior):
    d = _rp(dist, alpha, int_ior=ior, ext_ior=1.0)
    t_m, r_m = _mitsuba_coating(d)
    table, r_int = rp.coating_tables(dist, alpha, ior)
    assert abs(r_int - r_m) < 1e-4
    assert np.allclose(np.array(table)[1:], t_m[1:], atol=4e-3)


# ------------------------------------------------------------ tables, brute force

def _g1(kind, a, v, m):
    tan2 = a * a * (v[0] ** 2 + v[1] ** 2) / v[2] ** 2
    if kind == "beckmann":
        b = 1 / np.sqrt(np.maximum(tan2, 1e-30))
        g = np.where(b >= 1.6, 1.0, (3.535 * b + 2.181 * b * b) / (1 + 2.276 * b + 2.577 * b * b))
    else:
        g = 2 / (1 + np.sqrt(1 + tan2))
    return np.where((v[0] * m[0] + v[1] * m[1] + v[2] * m[2]) * v[2] > 0, g, 0.0)


def _brute(kind, a, eta, mu, reflect_inside=False, n=1000):
    """Independent brute force: midpoint rule over the whole hemisphere of normals in
    (theta_m, phi_m) of D(m) G1(wi) max(0, wi.m) / mu times the transmitted (from
    outside) or internally reflected fraction, Snell and Fresnel written out."""
    th = (np.arange(n) + 0.5) / n * np.pi / 2
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    m = (np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T))
    tan2 = np.tan(T) ** 2
    c4 = np.cos(T) ** 4
    D = (np.exp(-tan2 / a ** 2) / (np.pi * a * a * c4) if kind == "beckmann"
         else 1 / (np.pi * a * a * c4 * (1 + tan2 / a ** 2) ** 2))
    wi = (np.sqrt(1 - mu * mu), 0.0, mu)
    c = wi[0] * m[0] + wi[2] * m[2]
    w = D * _g1(kind, a, wi, m) * np.maximum(c, 0) / mu * np.sin(T) * (np.pi / 2 / n) * (np.pi / n)
    c = np.clip(c, 1e-12, 1)
    e = 1 / eta if reflect_inside else eta
    sin2_t = (1 - c * c) / (e * e)
    cos_t = np.sqrt(np.maximum(0, 1 - sin2_t))
    rs = ((c - e * cos_t) / (c + e * cos_t)) ** 2
    rp_ = ((e * c - cos_t) / (e * c + cos_t)) ** 2
    F = np.where(sin2_t >= 1, 1.0, 0.5 * (rs + rp_))
    if reflect_inside:
        wo = tuple(2 * c * mc - wc for mc, wc in zip(m, wi))
        h = np.where(wo[2] > 0, F * _g1(kind, a, wo, m), 0.0)
    else:
        wo = tuple((c / e - cos_t) * mc - wc / e for mc, wc in zip(m, wi))
        h = np.where((wo[2] < 0) & (sin2_t < 1), (1 - F) * _g1(kind, a, wo, m), 0.0)
    return float((w * h).sum())


@pytest.mark.parametrize("dist, alpha, ior", [("ggx", 0.3, 1.49), ("beckmann", 0.15, 1.49),
                                              ("beckmann", 0.8, 2.2), ("ggx", 1.0, 1 / 1.5)])
def test_transmittance_table_against_brute_force(dist, alpha, ior):
    table, _ = rp.coating_tables(dist, alpha, ior)
    for k in (1, 20, 45, 63):
        mu = rp.table_cosines()[k]
        assert table[k] == pytest.approx(_brute(dist, alpha, ior, mu), abs=1e-4), k


@pytest.mark.parametrize("dist, alpha, ior", [("ggx", 0.3, 1.49), ("beckmann", 0.5, 1.2)])
def test_internal_reflectance_against_brute_force(dist, alpha, ior):
    """R_int = 2 mean(R(mu) mu) over the table's 64 cosines (Mitsuba's rule), R the
    brute-force internal reflectance (a coarser grid: 64 directions)."""
    mu = rp.table_cosines()
    ref = 2 * np.mean([_brute(dist, alpha, ior, x, reflect_inside=True, n=250) * x for x in mu])
    assert rp.coating_tables(dist, alpha, ior)[1] == pytest.approx(ref, abs=5e-4)


def test_table_interpolation_is_linear_over_64_nodes():
    """Between the nodes the diffuse lobe follows the linear interpolation of T (as
    Mitsuba's lookup), and at the nodes the tabulated values."""
    d = _rp("ggx", 0.4, int_ior=1.6, ext_ior=1.0, diffuse_reflectance=1.0, specular_reflectance=0.0)
    table, r_int = rp.coating_tables("ggx", 0.4, 1.6)
    nodes = rp.table_cosines()
    cos = np.array([1e-3, 0.3, 5.5 / 63, 0.77, 40 / 63, 0.9999])
    t = np.interp(cos, np.linspace(0, 1, 64), table)
    wi = mi.Vector3f(mi.Float(np.sqrt(1 - cos ** 2)), 0.0, mi.Float(cos))
    b = OneBSDF(d)
    ctx = b.ctx(wi, len(cos))
    f, _ = b.bsdfs.eval_pdf(mi.UInt32(b.id) + dr.zeros(mi.UInt32, len(cos)), ctx, mi.Vector3f(0, 0, 1),
                            mi.Bool(True))
    expect = t * table[-1] / (1.6 ** 2 * np.pi * (1 - r_int))
    assert np.allclose(np.array(f)[0], expect, rtol=1e-5)
    assert nodes[0] == pytest.approx(1e-6) and len(nodes) == 64


# ----------------------------------------------------------------------- extremes

@pytest.mark.parametrize("dist, visible", [("ggx", True), ("ggx", False), ("beckmann", True)])
@pytest.mark.parametrize("alpha", [1e-4, 1e-2, 1.0])
@pytest.mark.parametrize("ior", [1.0001, 4.0, 1 / 1.5])
def test_extremes_are_finite_and_bounded(dist, visible, alpha, ior):
    b = OneBSDF(_rp(dist, alpha, sample_visible=visible, int_ior=ior, ext_ior=1.0, diffuse_reflectance=1.0))
    n = 1 << 16
    u1, u2 = random_samples(n)
    wo = random_directions(upper=True, n=n)
    for c in (1e-6, 1e-3, 0.5, 1.0, -0.5):
        wi = mi.Vector3f(math.sqrt(1 - c * c), 0.0, c)
        bs = b.sample(wi, u1, u2)
        f, pdf = b.eval_pdf(wi, wo)
        for name, v in [("weight", bs.weight), ("pdf", bs.pdf), ("wo", bs.wo), ("f", f), ("pdf", pdf)]:
            assert np.all(np.isfinite(np.array(v))), (name, c)
        assert np.all(np.array(pdf) >= 0) and np.all(np.array(bs.pdf) >= 0) and np.all(np.array(f) >= 0)
        w = np.array(bs.weight)[0].astype(np.float64)
        if c < 0:
            assert np.all(w == 0) and np.all(np.array(f) == 0)
            continue
        assert w.mean() < 1.0 + 4 * w.std() / math.sqrt(n) + 1e-6, (c, w.mean())
        # Visible normals keep every weight near f/pdf <= 1 (the diffuse part adds a
        # little); D cos sampling (Beckmann here) is known for large weights at grazing.
        assert w.max() < (3.0 if dist == "ggx" and visible else 1e3), (c, w.max())


# ------------------------------------------------------------------ parameters

def test_defaults_are_mitsubas():
    fam = OneBSDF({"type": "roughplastic"}).bsdfs.families["roughplastic"]
    inst = fam.instances[0]
    assert inst["variant"] == ("beckmann", True)
    assert inst["alpha"] == pytest.approx(0.1)
    assert inst["eta"] == pytest.approx(1.49 / 1.000277)
    assert inst["nonlinear"] is False


@pytest.mark.parametrize("d, key, text", [
    (_rp(alpha_u=0.1, alpha_v=0.2), "bsdf.alpha", "either"),
    ({"type": "roughplastic", "alpha_u": 0.1, "alpha_v": 0.3}, "bsdf.alpha_u", "anisotropic"),
    ({"type": "roughplastic", "alpha_u": 0.1}, "bsdf.alpha_v", "both"),
    ({"type": "roughplastic", "alpha": -0.1}, "bsdf.alpha", ">= 0"),
    ({"type": "roughplastic", "alpha": {"type": "bitmap", "filename": "x.png"}}, "bsdf.alpha", "number"),
    ({"type": "roughplastic", "int_ior": 1.3, "ext_ior": 1.3}, "bsdf.int_ior", "differ"),
    ({"type": "roughplastic", "distribution": "phong"}, "bsdf.distribution", "ggx"),
    ({"type": "roughplastic", "specular_transmittance": 0.5}, "bsdf.specular_transmittance", "unknown"),
])
def test_invalid_parameters_name_the_key(d, key, text):
    assert_scene_error(d, key, text)


def test_isotropic_alpha_u_v_is_accepted():
    a = OneBSDF({"type": "roughplastic", "alpha_u": 0.2, "alpha_v": 0.2})
    b = OneBSDF({"type": "roughplastic", "alpha": 0.2})
    wo = random_directions(upper=True, n=1000)
    assert np.allclose(np.array(a.eval_pdf(direction(30), wo)[0]), np.array(b.eval_pdf(direction(30), wo)[0]))


def test_mixed_instances_in_one_family():
    """GGX/Beckmann, visible/D cos sampling and textured instances share one family
    table and give the values each gives alone."""
    ds = [_rp("ggx", 0.3), _rp("beckmann", 0.2, int_ior=1.7, nonlinear=True),
          _rp("ggx", 0.6, sample_visible=False, diffuse_reflectance={"type": "rgb", "value": [0.2, 0.5, 0.9]})]
    n = 4000
    for r in shared_family_results(ds, direction(50, 20), random_directions(upper=True, n=n), samples=random_samples(n)):
        assert np.allclose(r["f"], r["f_alone"], rtol=1e-5, atol=1e-7)
        assert np.allclose(r["pdf"], r["pdf_alone"], rtol=1e-5, atol=1e-7)
        bs, ba = r["bs"], r["bs_alone"]
        # (float32 rounding differs between the two kernels)
        assert np.allclose(np.array(bs.weight), np.array(ba.weight), rtol=1e-4, atol=1e-7)
        assert np.allclose(np.array(bs.wo), np.array(ba.wo), atol=1e-5)


# ------------------------------------------------------------------------ images

_SMALL = {"type": "roughplastic", "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.3, 0.8]}}
_LARGE = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3, "int_ior": 1.9, "nonlinear": True,
          "diffuse_reflectance": {"type": "rgb", "value": [0.8, 0.6, 0.2]}}


def test_matches_mitsuba(scale):
    res = compare_with_mitsuba(material_box(_SMALL, _LARGE, scale), scale)
    print(res.summary())
    assert res.passed, res.summary()


def test_wrong_internal_reflectance_fails_the_comparison(scale, monkeypatch):
    """The image comparison has power: without the internal re-reflections
    (R_int = 0) the images differ detectably."""
    real = rp.coating_tables
    monkeypatch.setattr(rp, "coating_tables", lambda *a: (real(*a)[0], 0.0))
    res = compare_with_mitsuba(material_box(_SMALL, _LARGE, scale), scale)
    print(res.summary())
    assert not res.passed, res.summary()
