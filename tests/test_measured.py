"""measured (RGL material files): reader, sampling vs pdf, Mitsuba's plugin on the same
file (pointwise and images), and the analytic BRDF a synthetic file was tabulated from.

No RGL file is available offline: ``pbr.bsdfs.rgl_synth`` writes files tabulating a GGX gold
conductor (isotropic; anisotropic over all azimuths; anisotropic over a quarter of them,
Mitsuba's ``reduction`` 4)."""

import os

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

import pbr
from pbr import validate
from pbr.bsdfs.measured import RGLMaterial, read_tensor_file
from bsdf_harness import OneBSDF, assert_scene_error, chi2_rotated, direction, random_samples, shared_family_results
from mitsuba_scenes import BATCHES, SPP, compare_with_mitsuba, material_box
from pbr.bsdfs.rgl_synth import write_ggx, write_tensor_file

LAM = (450.0, 520.0, 600.0, 680.0)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """{name: (path, analytic model)} of the synthetic files."""
    d = tmp_path_factory.mktemp("rgl")
    specs = {
        "iso": dict(alpha_u=0.2),
        "aniso": dict(alpha_u=0.15, alpha_v=0.4, phi_i=np.linspace(-np.pi, np.pi, 13)),
        "quarter": dict(alpha_u=0.15, alpha_v=0.4, phi_i=np.linspace(-np.pi, -np.pi / 2, 5)),
        "iso_dim": dict(alpha_u=0.2, spectra_scale=0.8),   # a deliberately wrong file
    }
    out = {}
    for name, kw in specs.items():
        path = str(d / f"{name}.bsdf")
        out[name] = (path, write_ggx(path, **kw))
    return out


def measured(files, name):
    return {"type": "measured", "filename": files[name][0]}


def _vec(a):
    return mi.Vector3f(*[mi.Float(np.asarray(x, np.float32)) for x in a])


def _np(v):
    """A width-1 mi.Vector3f as a (3, 1) float64 array."""
    return np.array([[v.x[0]], [v.y[0]], [v.z[0]]], np.float64)


# -- the file ----------------------------------------------------------------------------
def test_reader(files):
    t = read_tensor_file(files["quarter"][0])
    assert t["spectra"].shape == (5, 18, 48, 32, 32) and t["spectra"].dtype == np.float32
    assert t["jacobian"].tolist() == [1]
    iso, quarter, full = (RGLMaterial(files[n][0]) for n in ("iso", "quarter", "aniso"))
    assert iso.isotropic and iso.reduction == 1 and iso.jacobian
    assert not quarter.isotropic and quarter.reduction == 4
    assert not full.isotropic and full.reduction == 1
    assert "GGX" in iso.description


def test_reads_files_written_by_mitsuba(files, tmp_path):
    """The same fields written by Mitsuba's own writer (mitsuba.tensor_io) read identically."""
    from mitsuba import tensor_io
    t = read_tensor_file(files["iso"][0])
    t["description"] = bytes(t["description"]).decode()
    path = str(tmp_path / "copy.bsdf")
    tensor_io.write(path, **t)
    u = read_tensor_file(path)
    assert all(np.array_equal(np.asarray(u[k]).ravel(), np.frombuffer(t[k].encode(), np.uint8)
                              if isinstance(t[k], str) else np.asarray(t[k]).ravel()) for k in u)


# -- sampling ------------------------------------------------------------------------------
@pytest.mark.parametrize("name, theta, phi", [
    ("iso", 0.5, 0), ("iso", 30, 30), ("iso", 62, -120), ("iso", 84, 200),
    ("aniso", 30, 30), ("aniso", 70, 10),
    ("quarter", 12, 60), ("quarter", 45, 100), ("quarter", 84, 200),
])
def test_chi2(files, name, theta, phi):
    ok, p, msg = chi2_rotated(measured(files, name), direction(theta, phi))
    print(f"{name} wi=({theta}, {phi}): p = {p:.3f}")
    assert ok, msg


def test_chi2_rejects_the_pdf_of_another_file(files, tmp_path):
    """Must fail: samples of the alpha = 0.2 file against the pdf of an alpha = 0.25 file."""
    other = str(tmp_path / "rougher.bsdf")
    write_ggx(other, 0.25)
    ok, p, _ = chi2_rotated(measured(files, "iso"), direction(40, 10), {"type": "measured", "filename": other})
    assert not ok, p


# -- Mitsuba's measured plugin, point by point ----------------------------------------------
def _mitsuba_si(wi, n):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi) + dr.zeros(mi.Vector3f, n)
    si.wavelengths = mi.Spectrum(*[mi.Float(l) for l in LAM]) + dr.zeros(mi.Spectrum, n)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    return si


@pytest.mark.parametrize("name", ["iso", "aniso", "quarter"])
def test_matches_mitsuba_plugin_pointwise(files, name):
    """eval, pdf and sample equal Mitsuba's ``measured`` on the same file (both use Mitsuba's
    Marginal2D warps; differences are float round-off)."""
    b = OneBSDF(measured(files, name), lam=LAM)
    mb = mi.load_dict(measured(files, name))
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(4)
    n = 4096
    worst = {"eval": 0.0, "pdf": 0.0, "wo": 0.0, "weight": 0.0}

    def rel(a, b):
        return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-3 * np.abs(b).max())))

    for theta, phi in [(3.0, 10.0), (37.0, 20.0), (63.0, 130.0), (80.0, -100.0), (88.0, 250.0)]:
        wi, si = direction(theta, phi), _mitsuba_si(direction(theta, phi), n)
        # sample(): the same directions, densities and weights
        u1, u2 = random_samples(n, seed=int(theta))
        bs, (bsm, weight_m) = b.sample(wi, u1, u2), mb.sample(ctx, si, u1, u2)
        ok = np.array(bs.pdf) > 0
        # (Mitsuba keeps the pdf of directions below the surface and zeroes their weight.)
        assert np.array_equal(ok, (np.array(bsm.pdf) > 0) & (np.array(bsm.wo.z) > 0))
        worst["wo"] = max(worst["wo"], float(np.abs(np.array(bs.wo) - np.array(bsm.wo))[:, ok].max()))
        worst["weight"] = max(worst["weight"], rel(np.array(bs.weight)[:, ok], np.array(weight_m)[:, ok]))
        # eval() and pdf() at random and at sampled directions
        v = rng.normal(size=(3, n))
        v /= np.linalg.norm(v, axis=0)
        v[2] = np.abs(v[2])
        for wo in (_vec(v), bs.wo):
            f, pdf = (np.array(x) for x in b.eval_pdf(wi, wo))
            worst["eval"] = max(worst["eval"], rel(f, np.array(mb.eval(ctx, si, wo))))
            worst["pdf"] = max(worst["pdf"], rel(pdf, np.array(mb.pdf(ctx, si, wo))))
    print(name, "max relative differences to Mitsuba:", worst)
    assert worst["eval"] < 2e-4 and worst["pdf"] < 2e-4 and worst["weight"] < 2e-4 and worst["wo"] < 1e-5, worst


# -- the analytic BRDF the files tabulate ---------------------------------------------------
def test_generator_matches_roughconductor(files):
    """The generator's analytic GGX gold equals pbr's roughconductor (checks its formulas)."""
    model = files["aniso"][1]
    b = OneBSDF({"type": "roughconductor", "distribution": "ggx", "alpha_u": 0.15, "alpha_v": 0.4,
                 "material": "Au"}, lam=LAM)
    wi = direction(35, 70)
    v = np.random.default_rng(2).normal(size=(3, 2000))
    v /= np.linalg.norm(v, axis=0)
    v[2] = np.abs(v[2])
    f = np.array(b.eval_pdf(wi, _vec(v))[0]).T
    ref = model.f_cos(np.repeat(_np(wi), 2000, 1), v, np.array(LAM))
    assert np.allclose(f, ref, rtol=2e-3, atol=1e-5 * ref.max())


@pytest.mark.parametrize("name", ["iso", "aniso", "quarter"])
def test_approximates_the_tabulated_brdf(files, name):
    """Loose: eval of a file vs the analytic BRDF it tabulates, at incident angles between
    the file's theta_i nodes (5 degree steps), over directions sampled from the lobe and
    where the value exceeds 5% of the lobe's peak: median relative error < 1%, 90th
    percentile < 5% (measured: 0.02-0.7% and 0.1-2%; the error is the bilinear
    interpolation of the 64 x 128 ndf and 32 x 32 spectra tables)."""
    path, model = files[name]
    b = OneBSDF(measured(files, name), lam=LAM)
    n = 20000
    for theta, phi in [(17.5, 20.0), (42.5, 130.0), (67.5, -100.0)]:
        wi = direction(theta, phi)
        bs = b.sample(wi, *random_samples(n, seed=9))
        ok = np.array(bs.pdf) > 0
        f = np.array(b.eval_pdf(wi, bs.wo)[0]).T
        ref = model.f_cos(np.repeat(_np(wi), n, 1), np.array(bs.wo), np.array(LAM))
        big = ok & (ref[:, 0] > 0.05 * ref[:, 0].max())
        rel = np.abs(f - ref)[big] / ref[big]
        med, p90 = np.median(rel), np.percentile(rel, 90)
        print(f"{name} wi=({theta}, {phi}): median {med:.2e}, p90 {p90:.2e}")
        assert med < 0.01 and p90 < 0.05


def test_image_approximates_roughconductor(files, scale):
    """Renders of the tabulated files vs pbr's roughconductor with the same GGX gold: the
    image means agree within 1% (loose: a tabulation is not exact)."""
    d = material_box(measured(files, "iso"), measured(files, "aniso"), scale)
    d2 = material_box({"type": "roughconductor", "distribution": "ggx", "alpha": 0.2, "material": "Au"},
                      {"type": "roughconductor", "distribution": "ggx", "alpha_u": 0.15, "alpha_v": 0.4,
                       "material": "Au"}, scale)
    sa, sb = pbr.load_dict(d), pbr.load_dict(d2)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(sa, seed=seed, spp=spp))  # noqa: E731
    fb = lambda seed=0, spp=0: np.asarray(pbr.render(sb, seed=seed, spp=spp))  # noqa: E731
    res = validate.compare_renders(fa, fb, spp=SPP * scale, batches=BATCHES, seed_a=5, seed_b=6)
    print(res.summary())
    assert abs(res.mean_ratio - 1.0) < 0.01, res.summary()


# -- images against Mitsuba -----------------------------------------------------------------
def test_image_matches_mitsuba(files, scale):
    """Two files in one scene (isotropic; anisotropic with a quarter of the azimuths)."""
    res = compare_with_mitsuba(material_box(measured(files, "iso"), measured(files, "quarter"), scale), scale)
    print(res.summary())
    assert res.passed, res.summary()


def test_image_comparison_detects_a_wrong_file(files, scale):
    """Must fail: pbr renders a copy of the small box's file with spectra 20% lower than
    Mitsuba's (measured: mean ratio 6-9 sigma off over 3 seed pairs; 10% lower was caught
    by only 1 of 3 seed pairs at this resolution)."""
    large = measured(files, "quarter")
    scene = pbr.load_dict(material_box(measured(files, "iso_dim"), large, scale))
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))  # noqa: E731
    ref = validate.mitsuba_render_fn(material_box(measured(files, "iso"), large, scale))
    res = validate.compare_renders(fa, ref, spp=SPP * scale, batches=BATCHES, seed_a=21, seed_b=22)
    print(res.summary())
    assert not res.passed


# -- scenes ------------------------------------------------------------------------------------
def test_instances_share_a_family(files):
    """Several files (and one file twice) in one scene give each instance's own values."""
    names = ["iso", "quarter", "iso", "aniso"]
    n = 2048
    wo = _vec(np.stack([np.full(n, 0.3), np.linspace(-0.5, 0.5, n), np.full(n, 0.8)]) /
              np.sqrt(0.73 + np.linspace(-0.5, 0.5, n) ** 2))
    for r in shared_family_results([measured(files, k) for k in names], direction(40, 110), wo,
                                   samples=random_samples(n)):
        assert np.allclose(r["f"], r["f_alone"], rtol=1e-6, atol=0) and np.allclose(r["pdf"], r["pdf_alone"])
        assert np.allclose(np.array(r["bs"].wo), np.array(r["bs_alone"].wo))
        assert r["f"].max() > 0


def test_one_sided_and_twosided(files):
    b = OneBSDF(measured(files, "iso"))
    below, up = direction(140, 0), _vec(np.array([[0.3], [0.1], [0.95]]))
    f, pdf = b.eval_pdf(below, up)
    assert np.array(f).max() == 0 and np.array(pdf).max() == 0
    two = OneBSDF({"type": "twosided", "bsdf": measured(files, "iso")})
    f_below = np.array(two.eval_pdf(below, _vec(np.array([[0.3], [0.1], [-0.95]])))[0])
    f_above = np.array(b.eval_pdf(direction(40, 0), up)[0])
    assert np.allclose(f_below, f_above)


def test_filename_relative_to_the_scene(files, tmp_path):
    """As Mitsuba: a relative filename is looked up next to the scene file."""
    os.makedirs(tmp_path / "scene")
    with open(files["iso"][0], "rb") as src, open(tmp_path / "scene" / "gold.bsdf", "wb") as dst:
        dst.write(src.read())
    d = material_box({"type": "measured", "filename": "gold.bsdf"})
    pbr.load_dict(d, base_dir=str(tmp_path / "scene"))
    xml = ('<scene version="3.0.0"><bsdf type="measured" id="m"><string name="filename" value="gold.bsdf"/>'
           '</bsdf><shape type="sphere"><ref id="m"/></shape></scene>')
    (tmp_path / "scene" / "s.xml").write_text(xml)
    cwd = os.getcwd()
    try:
        os.chdir(tmp_path)
        pbr.load_file(str(tmp_path / "scene" / "s.xml"))
    finally:
        os.chdir(cwd)


# -- bad input -------------------------------------------------------------------------------
def _fields(files):
    t = dict(read_tensor_file(files["iso"][0]))
    t["description"] = bytes(t["description"]).decode()
    return t


def test_errors_name_the_key_and_the_file(files, tmp_path):
    key = "scene.bsdf.filename"
    assert_scene_error({"type": "measured"}, key, "missing required string")
    assert_scene_error({"type": "measured", "filename": str(tmp_path / "none.bsdf")}, key, "file not found")
    assert_scene_error({"type": "measured", "filename": files["iso"][0], "alpha": 0.1}, "scene.bsdf.alpha",
                       "unknown parameter")

    def bad(name, fields=None, raw=None):
        path = str(tmp_path / name)
        if raw is not None:
            with open(path, "wb") as f:
                f.write(raw)
        else:
            write_tensor_file(path, fields)
        return {"type": "measured", "filename": path}

    assert_scene_error(bad("garbage.bsdf", raw=b"not a tensor file at all"), key, "garbage.bsdf")
    with open(files["iso"][0], "rb") as f:
        head = f.read(4000)
    assert_scene_error(bad("cut.bsdf", raw=head), key, "truncated")
    t = _fields(files)
    del t["vndf"]
    assert_scene_error(bad("novndf.bsdf", t), key, "missing field(s) vndf")
    t = _fields(files)
    t["luminance"] = t["luminance"][:, :3]
    assert_scene_error(bad("shape.bsdf", t), key, "'luminance'")
    t = _fields(files)
    t["rgb"] = t.pop("spectra")[:, :, :3]
    del t["wavelengths"]
    assert_scene_error(bad("rgb.bsdf", t), key, "RGB data")
    t = _fields(files)
    t["theta_i"] = t["theta_i"][::-1].copy()
    assert_scene_error(bad("order.bsdf", t), key, "'theta_i' must be a non-empty increasing grid")
    t = _fields(files)
    t["ndf"] = t["ndf"].astype(np.float64)
    assert_scene_error(bad("f64.bsdf", t), key, "'ndf'")
