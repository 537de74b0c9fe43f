import pytest
import numpy as np
import drjit as dr
import mitsuba as mi

from pbr import spectrum as S


def test_rgb_coefficients_match_mitsuba_table():
    rng = np.random.default_rng(1)
    cols = np.concatenate([rng.random((200, 3)), [[0, 0, 0], [1, 1, 1], [0.3, 0.3, 0.3], [0, 0, 0.2], [1, 0, 0]]])
    c = np.array(S.rgb_to_coeffs(mi.Color3f(cols.T.astype(np.float32)))).T
    ref = np.array([np.array(mi.srgb_model_fetch(mi.ScalarColor3f(x))) for x in cols])
    grey = (cols[:, 0] == cols[:, 1]) & (cols[:, 1] == cols[:, 2])
    # The table lookup itself, compared in coefficient space: 8 float32 ulps of each colour's
    # largest coefficient (bit-identical on LLVM; CUDA's compiler fuses the trilinear sums
    # into FMAs). Its spectra are no fit measure of that: the polynomial cancels (terms of
    # ~300 summing to ~1), so one ulp in one coefficient moves a value by up to 1.2e-5.
    err = np.abs(c - ref)[~grey].max(1) / np.abs(ref[~grey]).max(1)
    assert err.max() < 8 * 2.0 ** -24, err.max()
    # Greys: pbr solves them exactly, Mitsuba clamps them at +-8192 like pbr: compare spectra.
    lam = mi.Spectrum(400, 500, 600, 700)
    a = np.array(S.sigmoid_polynomial(mi.Array3f(c[grey].T), lam))
    b = np.array(S.sigmoid_polynomial(mi.Array3f(ref[grey].T.astype(np.float32)), lam))
    assert np.abs(a - b).max() < 1e-5


def test_upsampled_rgb_roundtrips_through_xyz():
    """The spectrum of an rgb albedo under D65 integrates back to that rgb."""
    lam = np.linspace(360, 830, 4701)
    xyz, d65 = S.cie_tables_np()
    grid = np.arange(95) * 5.0 + 360
    cmf = np.stack([np.interp(lam, grid, xyz[:, k]) for k in range(3)], 1)
    illum = np.interp(lam, grid, d65)
    for rgb in ([0.57, 0.043, 0.044], [0.1, 0.8, 0.3], [0.5, 0.5, 0.5]):
        c = S.rgb_to_coeffs(mi.Color3f(*rgb))
        L = mi.Float(lam.astype(np.float32))
        spec = np.array(S.sigmoid_polynomial(mi.Array3f(*[dr.gather(mi.Float, c[k], dr.zeros(mi.UInt32, len(lam)))
                                                          for k in range(3)]), mi.Spectrum(L, L, L, L)))[0]
        XYZ = (cmf * (spec * illum)[:, None]).sum(0) * (lam[1] - lam[0]) / S.CIE_Y_INTEGRAL
        out = S.XYZ_TO_SRGB @ XYZ
        assert np.allclose(out, rgb, atol=0.01), (rgb, out)


def test_d65_has_unit_luminance():
    xyz, d65 = S.cie_tables_np()
    Y = np.trapezoid(d65 * xyz[:, 1], dx=5.0) / S.CIE_Y_INTEGRAL
    assert abs(Y - 1) < 1e-6


def test_visible_wavelength_pdf_is_normalised_and_consistent():
    u = dr.linspace(mi.Float, 0, 1, 100001, endpoint=False) + 0.5 / 100001
    wl = S.SampledWavelengths.sample_visible(u)
    lam = np.array(wl.lambda_)[0]
    pdf = np.array(wl.pdf)[0]
    assert lam.min() >= 359.9 and lam.max() <= 830.1
    # Histogram of samples vs the density.
    hist, edges = np.histogram(lam, bins=47, range=(360, 830), density=True)
    mid = 0.5 * (edges[1:] + edges[:-1])
    dens = np.interp(mid, np.sort(lam), pdf[np.argsort(lam)])
    assert np.allclose(hist, dens, rtol=0.02)
    order = np.argsort(lam)
    assert abs(np.trapezoid(pdf[order], lam[order]) - 1) < 1e-3


def test_to_xyz_of_unit_spectrum():
    u = dr.linspace(mi.Float, 0, 1, 65536, endpoint=False)
    wl = S.SampledWavelengths.sample_visible(u)
    xyz = np.array(S.to_xyz(mi.Spectrum(1.0), wl)).mean(axis=1)
    xyz_t, _ = S.cie_tables_np()
    expect = np.trapezoid(xyz_t, dx=5.0, axis=0) / S.CIE_Y_INTEGRAL
    assert np.allclose(xyz, expect, rtol=2e-3)


def test_shipped_cmfs_are_colour_sciences():
    """data/cie1931_2deg_5nm.spd (read at run time, so that pbr need not import
    colour-science and its matplotlib) holds colour-science's CIE 1931 2-degree table."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    grid = np.arange(95) * 5.0 + 360
    xyz, _ = S.cie_tables_np()
    assert xyz.shape == (95, 3)
    assert np.allclose(xyz, np.asarray(cmfs[grid]), rtol=1e-9, atol=0)


def test_spectrum_files_bad_input_names_file_and_line(tmp_path):
    f = tmp_path / "eta.spd"
    f.write_text("# wavelength value\n400 1.5  # a comment\n500 x\n")
    with pytest.raises(ValueError, match=r"eta\.spd:3: expected numbers"):
        S.read_spd(str(f))
    f.write_text("400 1.5\n500 1.4 9\n")
    with pytest.raises(ValueError, match=r"eta\.spd:2: 3 columns"):
        S.read_spd(str(f))
    f.write_text("400 1.5  # a comment\n\n700 1.4\n")
    wl, v = S.read_spd(str(f))
    assert wl.tolist() == [400, 700] and v.tolist() == [1.5, 1.4]
