"""Dielectric BSDFs (``dielectric``, ``thindielectric``, ``roughdielectric``): sampling
against densities (chi-square), energy (white furnace), reciprocity, agreement with
Mitsuba 3's plugins, extreme parameters and input validation."""

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from bsdf_harness import OneBSDF, direction, chi2_rotated, random_directions, random_samples, shared_family_results, assert_scene_error

N_FURNACE = 1 << 18


def _rough(dist="ggx", alpha=0.3, ior=1.5, **kw):
    d = {"type": "roughdielectric", "distribution": dist, **kw}
    if isinstance(alpha, tuple):
        d.update(alpha_u=alpha[0], alpha_v=alpha[1])
    else:
        d["alpha"] = alpha
    if isinstance(ior, tuple):
        d.update(int_ior=ior[0], ext_ior=ior[1])
    else:
        d.update(int_ior=ior, ext_ior=1.0)
    return d


# ----------------------------------------------------------------------- chi-square

def _chi2(bsdf, wi, pdf_bsdf=None, test_count=1):
    """(passed, messages) of bsdf_harness.chi2_rotated (see there for why directions are rotated)."""
    ok, _, msg = chi2_rotated(bsdf, wi, pdf_bsdf, test_count)
    return ok, msg

# Every distribution x roughness x incidence angle, from outside and inside, with the
# three IORs cycled through the cases (a full product would take minutes).
_IORS = [1.5, 1.33, (1.0, 1.5)]
_CASES = []
for _dist in ("ggx", "beckmann"):
    for _ia, _alpha in enumerate((0.1, 0.3, 0.8)):
        for _it, _theta in enumerate((10, 60, 85)):
            for _side, _th in (("out", _theta), ("in", 180 - _theta)):
                _CASES.append((_dist, _alpha, _IORS[(_ia + _it + (_side == "in")) % 3], _th))
_CASES += [("ggx", (0.1, 0.4), 1.5, 60), ("beckmann", (0.5, 0.15), 1.33, 120),
           ("ggx", (0.3, 0.3), (1.0, 1.5), 45)]   # isotropic given as alpha_u/alpha_v


def _case_id(c):
    dist, alpha, ior, theta = c
    a = "x".join(map(str, alpha)) if isinstance(alpha, tuple) else alpha
    i = f"{ior[0]}over{ior[1]}" if isinstance(ior, tuple) else ior
    return f"{dist}-a{a}-ior{i}-{theta}deg"


@pytest.mark.parametrize("dist, alpha, ior, theta", _CASES, ids=[_case_id(c) for c in _CASES])
def test_rough_sampling_matches_pdf(dist, alpha, ior, theta):
    ok, msg = _chi2(_rough(dist, alpha, ior), direction(theta, 30), test_count=len(_CASES) + 2)
    assert ok, msg


@pytest.mark.parametrize("dist, theta", [("ggx", 40), ("beckmann", 130)])
def test_rough_sampling_without_visible_normals_matches_pdf(dist, theta):
    ok, msg = _chi2(_rough(dist, 0.3, 1.5, sample_visible=False), direction(theta, 10), test_count=len(_CASES) + 2)
    assert ok, msg


@pytest.mark.parametrize("wrong", [{"int_ior": 1.52}, {"alpha": 0.33}])
def test_chi2_rejects_a_wrong_density(wrong):
    """The test can fail: a density for a 1.3% larger IOR (or 10% larger roughness) is rejected."""
    good = _rough("ggx", 0.3, 1.5)
    ok, _ = _chi2(good, direction(45), pdf_bsdf={**good, **wrong})
    assert not ok


# ------------------------------------------------------------------------ Mitsuba

def _mi_si(wi, n):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi) + dr.zeros(mi.Vector3f, n)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wavelengths = mi.Spectrum(500.0)
    return si


@pytest.mark.parametrize("d", [
    _rough("ggx", 0.3, 1.5), _rough("ggx", (0.1, 0.5), (1.0, 1.33), specular_reflectance=0.7),
    # Beckmann: pbr samples D cos (Mitsuba's sample_visible=False density) either way.
    _rough("beckmann", 0.2, 1.33, sample_visible=False, specular_transmittance=0.6),
    _rough("ggx", 0.8, 1.5, sample_visible=False)])
@pytest.mark.parametrize("theta", [20, 80, 110, 170])
def test_rough_eval_pdf_matches_mitsuba(d, theta):
    wi, wo = direction(theta, 30), random_directions(20_000)
    f, pdf = OneBSDF(d).eval_pdf(wi, wo)
    fm, pm = mi.load_dict(d).eval_pdf(mi.BSDFContext(), _mi_si(wi, 20_000), wo)
    f, fm = np.array(f)[0], np.array(fm)[0]
    assert np.allclose(f, fm, rtol=1e-4, atol=1e-6 * max(fm.max(), 1))
    assert np.allclose(np.array(pdf), np.array(pm), rtol=1e-4, atol=1e-6 * max(np.array(pm).max(), 1))


@pytest.mark.parametrize("d", [
    {"type": "dielectric"}, {"type": "dielectric", "int_ior": "water", "ext_ior": 1.2},
    {"type": "dielectric", "int_ior": 1.0, "ext_ior": 1.5, "specular_reflectance": 0.7, "specular_transmittance": 0.4},
    {"type": "thindielectric", "int_ior": 1.7}, {"type": "thindielectric", "specular_transmittance": 0.5}])
@pytest.mark.parametrize("theta", [0, 30, 70, 89, 100, 150])
def test_smooth_sample_matches_mitsuba(d, theta):
    n = 4096
    wi = direction(theta, 50)
    u1, u2 = random_samples(n)
    bs = OneBSDF(d).sample(wi, u1, u2)
    bm, wm = mi.load_dict(d).sample(mi.BSDFContext(), _mi_si(wi, n), u1, u2)
    assert np.all(np.array(bs.delta))
    assert np.allclose(np.array(bs.wo), np.array(bm.wo), atol=1e-5)
    assert np.allclose(np.array(bs.pdf), np.array(bm.pdf), rtol=1e-5)
    assert np.allclose(np.array(bs.eta), np.array(bm.eta), rtol=1e-6)
    assert np.allclose(np.array(bs.weight)[0], np.array(wm)[0], rtol=1e-5)


# ------------------------------------------------------------------ white furnace

def _fresnel_np(c, eta):
    """Independent unpolarised Fresnel reflectance (Snell + the two amplitude ratios)."""
    if c < 0:
        c, eta = -c, 1.0 / eta
    s2 = (1 - c * c) / (eta * eta)
    if s2 >= 1:
        return 1.0
    ct = math.sqrt(1 - s2)
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs * rs + rp * rp)


def _furnace(d, wi, n=N_FURNACE):
    u1, u2 = random_samples(n)
    bs = OneBSDF(d).sample(wi, u1, u2)
    w = np.array(bs.weight)
    eta = np.array(bs.eta)
    return w, eta, np.array(bs.wo.z), np.array(bs.pdf)


@pytest.mark.parametrize("theta", [0, 45, 80, 100, 130, 160])
@pytest.mark.parametrize("ior", [1.5, 1.33, 0.7])
def test_smooth_dielectric_furnace(theta, ior):
    """Reflected + transmitted energy is 1, split in Fresnel's proportions; transmitted
    weights carry the radiance scale 1/eta_it^2."""
    wi = direction(theta)
    w, eta, wo_z, _ = _furnace({"type": "dielectric", "int_ior": ior, "ext_ior": 1.0}, wi)
    energy = w * eta ** 2
    assert abs(energy.mean() - 1.0) < 1e-3 and np.allclose(energy, 1.0, rtol=1e-5)
    refl = wo_z * math.cos(math.radians(theta)) > 0
    r = _fresnel_np(math.cos(math.radians(theta)), ior)
    assert abs(refl.mean() - r) < 4 * math.sqrt(max(r * (1 - r), 1e-12) / len(refl)) + 1e-6
    assert np.allclose(eta[refl], 1.0)
    if not refl.all():
        inside = theta > 90
        assert np.allclose(eta[~refl], 1 / ior if inside else ior, rtol=1e-6)


@pytest.mark.parametrize("theta", [0, 60, 89, 120])
def test_thin_dielectric_conserves_energy(theta):
    w, eta, wo_z, _ = _furnace({"type": "thindielectric", "int_ior": 1.5, "ext_ior": 1.0}, direction(theta))
    assert np.all(w == 1.0) and np.all(eta == 1.0)
    r = _fresnel_np(abs(math.cos(math.radians(theta))), 1.5)
    r = 2 * r / (1 + r)
    refl = wo_z * math.cos(math.radians(theta)) > 0
    assert abs(refl.mean() - r) < 4 * math.sqrt(r * (1 - r) / len(refl)) + 1e-6


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
@pytest.mark.parametrize("theta", [0, 10, 45, 60, 135, 170])
def test_rough_furnace_smooth_limit(dist, theta):
    """At alpha 0.1 the microfacet model loses little energy (masking), never gains."""
    w, eta, _, _ = _furnace(_rough(dist, 0.1, 1.5), direction(theta))
    e = w[0].astype(np.float64) * eta ** 2
    mean, sigma = e.mean(), e.std() / math.sqrt(len(e))
    assert 0.95 < mean < 1.0 + 3 * sigma + 1e-6, (mean, sigma)


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
@pytest.mark.parametrize("alpha", [0.3, 0.8, 1.0])
@pytest.mark.parametrize("theta", [30, 80, 150])
def test_rough_furnace_never_gains(dist, alpha, theta):
    w, eta, _, _ = _furnace(_rough(dist, alpha, 1.5), direction(theta, 20))
    e = w[0].astype(np.float64) * eta ** 2
    assert e.mean() < 1.0 + 3 * e.std() / math.sqrt(len(e)) + 1e-6


def test_rough_weights_equal_eval_over_pdf():
    """sample's weight and pdf are eval_pdf's values at the sampled direction."""
    for d, theta in [(_rough("ggx", 0.3, 1.5), 40), (_rough("beckmann", (0.2, 0.4), 1.33), 140),
                     (_rough("ggx", 0.5, (1.0, 1.5), specular_transmittance=0.5), 70)]:
        b, wi = OneBSDF(d), direction(theta, 15)
        u1, u2 = random_samples(50_000)
        bs = b.sample(wi, u1, u2)
        f, pdf = b.eval_pdf(wi, bs.wo)
        ok = np.array(bs.pdf) > 0
        assert ok.mean() > 0.8
        p, ps = np.array(pdf)[ok], np.array(bs.pdf)[ok]
        assert np.allclose(p, ps, rtol=2e-3)
        assert np.allclose(np.array(f)[:, ok] / p, np.array(bs.weight)[:, ok], rtol=2e-3, atol=1e-5)
        assert not np.any(np.array(bs.delta))


# -------------------------------------------------------------------- reciprocity

def _pairs(b, reflected, n=8000):
    """(wi, wo) pairs with wo sampled from the BSDF for random wi (both sides), keeping
    reflected or transmitted ones away from grazing angles."""
    wi = random_directions(n, seed=5)
    u1, u2 = random_samples(n)
    bs = b.sample(wi, u1, u2)
    a, c = np.array(wi), np.array(bs.wo)
    keep = (np.array(bs.pdf) > 0) & ((a[2] * c[2] > 0) == reflected) & (np.abs(a[2]) > 0.05) & (np.abs(c[2]) > 0.05)
    return a[:, keep], c[:, keep]


def _eval_each(b, wi, wo):
    """eval for per-lane wi (OneBSDF takes one wi: build the context directly)."""
    n = wi.shape[1]
    ctx = b.ctx(mi.Vector3f(*[mi.Float(x) for x in wi]), n)
    f, _ = b.bsdfs.eval_pdf(mi.UInt32(b.id) + dr.zeros(mi.UInt32, n), ctx,
                            mi.Vector3f(*[mi.Float(x) for x in wo]), mi.Bool(True))
    return np.array(f)[0]


@pytest.mark.parametrize("d", [_rough("ggx", 0.3, 1.5), _rough("beckmann", (0.2, 0.5), 1.33)])
def test_rough_reflection_is_reciprocal(d):
    """f(wi, wo) = f(wo, wi), f being eval / |cos theta_o|."""
    b = OneBSDF(d)
    a, c = _pairs(b, reflected=True)
    f_ac = _eval_each(b, a, c) / np.abs(c[2])
    f_ca = _eval_each(b, c, a) / np.abs(a[2])
    assert len(f_ac) > 500 and np.all(f_ac > 0)
    assert np.allclose(f_ac, f_ca, rtol=2e-3, atol=1e-6 * f_ac.max())


@pytest.mark.parametrize("d", [_rough("ggx", 0.3, 1.5), _rough("beckmann", 0.4, (1.0, 1.33))])
def test_rough_transmission_generalised_reciprocity(d):
    """With the radiance scale 1/eta_it^2: f(wi -> wo) eta_it^2 = f(wo -> wi)."""
    eta = d["int_ior"] / d["ext_ior"]
    b = OneBSDF(d)
    a, c = _pairs(b, reflected=False)
    f_ac = _eval_each(b, a, c) / np.abs(c[2])
    f_ca = _eval_each(b, c, a) / np.abs(a[2])
    eta_it = np.where(a[2] > 0, eta, 1 / eta)
    assert len(f_ac) > 2000 and np.all(f_ac > 0)
    assert np.allclose(f_ac * eta_it ** 2, f_ca, rtol=2e-3, atol=1e-6 * f_ca.max())


# ----------------------------------------------------------------------- extremes

_EXTREME_COS = [1e-6, -1e-6, 1e-3, -1e-3, 0.5, -0.5, 1.0, -1.0]


@pytest.mark.parametrize("family, alpha", [("dielectric", None), ("thindielectric", None)] + [
    (f, a) for f in ("ggx", "beckmann", "ggx_no_vndf") for a in (1e-4, 1.0)])
@pytest.mark.parametrize("ior", [1.0001, 4.0, 1 / 1.5])
def test_extremes_are_finite_and_bounded(family, alpha, ior):
    if alpha is None:
        d = {"type": family, "int_ior": ior, "ext_ior": 1.0}
    else:
        d = _rough(family[:-8] if family.endswith("_no_vndf") else family, alpha, ior,
                   sample_visible=not family.endswith("_no_vndf"))
    b = OneBSDF(d)
    u1, u2 = random_samples(1 << 14)
    wo = random_directions(1 << 14)
    for c in _EXTREME_COS:
        wi = mi.Vector3f(math.sqrt(1 - c * c), 0.0, c)
        bs = b.sample(wi, u1, u2)
        f, pdf = b.eval_pdf(wi, wo)
        for name, v in [("weight", bs.weight), ("pdf", bs.pdf), ("eta", bs.eta), ("wo", bs.wo), ("f", f), ("pdf", pdf)]:
            v = np.array(v)
            assert np.all(np.isfinite(v)), (name, c)
        assert np.all(np.array(pdf) >= 0) and np.all(np.array(bs.pdf) >= 0)
        ok = np.array(bs.pdf) > 0
        wo_n = np.linalg.norm(np.array(bs.wo)[:, ok], axis=0)
        assert np.allclose(wo_n, 1.0, atol=1e-3)
        # Energy weight (radiance scale undone); D cos sampling of GGX (sample_visible
        # false) is known for large weights at grazing incidence, as in Mitsuba.
        energy = np.array(bs.weight)[0] * np.array(bs.eta) ** 2
        if not family.endswith("_no_vndf"):
            assert energy.max() < 10, (c, energy.max())


def test_tiny_roughness_gains_no_energy_with_vndf():
    """GGX with visible normals stays energy-bounded at alpha 1e-4 (a smooth interface)."""
    for c in (1.0, 0.5, 1e-3, -0.5):
        w, eta, _, _ = _furnace(_rough("ggx", 1e-4, 1.5), mi.Vector3f(math.sqrt(1 - c * c), 0.0, c))
        e = w[0].astype(np.float64) * eta ** 2
        assert 0.98 < e.mean() < 1.0 + 3 * e.std() / math.sqrt(len(e)) + 1e-6


def test_tiny_roughness_gains_no_energy_beckmann():
    w, eta, _, _ = _furnace(_rough("beckmann", 1e-4, 1.5), direction(60))
    e = w[0].astype(np.float64) * eta ** 2
    assert e.mean() < 1.0 + 3 * e.std() / math.sqrt(len(e)) + 1e-6


# ------------------------------------------------------------- several instances

def test_mixed_instances_in_one_family():
    """GGX/Beckmann, textured/untextured, isotropic/anisotropic instances share one
    family table and give the values each gives alone."""
    ds = [_rough("ggx", 0.3, 1.5), _rough("beckmann", (0.2, 0.5), 1.33, specular_transmittance=0.5),
          _rough("ggx", 0.6, 1.2, sample_visible=False, specular_reflectance=0.3)]
    n = 5000
    for r in shared_family_results(ds, direction(50, 20), random_directions(n), samples=random_samples(n)):
        assert np.allclose(r["f"], r["f_alone"], rtol=1e-5, atol=1e-7)
        assert np.allclose(r["pdf"], r["pdf_alone"], rtol=1e-5, atol=1e-7)
        bs, ba = r["bs"], r["bs_alone"]
        assert np.allclose(np.array(bs.weight), np.array(ba.weight), rtol=1e-5, atol=1e-7)
        assert np.allclose(np.array(bs.wo), np.array(ba.wo), atol=1e-6)


# --------------------------------------------------------------------- validation

@pytest.mark.parametrize("d, key, text", [
    ({"type": "dielectric", "int_ior": -1.5}, "bsdf.int_ior", "positive"),
    ({"type": "thindielectric", "ext_ior": 0.0}, "bsdf.ext_ior", "positive"),
    ({"type": "dielectric", "int_ior": "glas"}, "bsdf.int_ior", "bk7"),
    ({"type": "roughdielectric", "int_ior": 1.3, "ext_ior": 1.3}, "bsdf.int_ior", "differ"),
    ({"type": "roughdielectric", "distribution": "phong"}, "bsdf.distribution", "ggx"),
    ({"type": "roughdielectric", "alpha_u": 0.1}, "bsdf.alpha_v", "both"),
    ({"type": "roughdielectric", "alpha": 0.1, "alpha_u": 0.1, "alpha_v": 0.2}, "bsdf.alpha", "either"),
    ({"type": "roughdielectric", "alpha": -0.1}, "bsdf.alpha", ">= 0"),
    ({"type": "dielectric", "alpha": 0.1}, "bsdf.alpha", "unknown parameter"),
])
def test_invalid_parameters_name_the_key(d, key, text):
    assert_scene_error(d, key, text)


def test_named_iors_are_case_insensitive():
    b = OneBSDF({"type": "dielectric", "int_ior": "Water", "ext_ior": "vacuum"})
    assert float(np.array(b.bsdfs.families["dielectric"].eta)[0]) == pytest.approx(1.333)


@pytest.mark.parametrize("small, large", [
    ({"type": "dielectric"}, {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.3, "int_ior": 1.33}),
    ({"type": "thindielectric", "int_ior": 1.5},
     {"type": "roughdielectric", "alpha": 0.2,
      "specular_transmittance": {"type": "rgb", "value": [0.9, 0.6, 0.3]}}),
])
def test_matches_mitsuba(small, large, scale):
    from mitsuba_scenes import material_box, compare_with_mitsuba
    res = compare_with_mitsuba(material_box(small, large, scale), scale)
    print(res.summary())
    assert res.passed, res.summary()
