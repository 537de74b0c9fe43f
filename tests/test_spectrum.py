import pytest
import numpy as np
import drjit as dr
import mitsuba as mi

from pbr import spectrum as S
from pbr import get_backend as pbr_backend


def lookup_f64(rgb: np.ndarray) -> np.ndarray:
    """The Jakob-Hanika trilinear lookup evaluated in float64 (the test's oracle for
    :func:`spectrum.rgb_to_coeffs` on non-grey colours), rows of ``rgb`` -> coefficients."""
    scale, data = S._rgb2spec_np()
    scale, data = np.asarray(scale, np.float64), np.asarray(data, np.float64)
    res = len(scale)
    out = []
    for r, g, b in np.asarray(rgb, np.float64):
        i = 2 if b >= max(r, g) else (1 if g >= r else 0)
        z = (r, g, b)[i]
        a, c = (r, g, b)[(i + 1) % 3], (r, g, b)[(i + 2) % 3]
        x, y = a * (res - 1) / z, c * (res - 1) / z
        xi, yi = min(int(x), res - 2), min(int(y), res - 2)
        zi = min(int(np.searchsorted(scale, z, side="right")) - 1, res - 2)
        x1, y1, z1 = x - xi, y - yi, (z - scale[zi]) / (scale[zi + 1] - scale[zi])
        cell = data.reshape(3, res, res, res, 3)[i, zi:zi + 2, yi:yi + 2, xi:xi + 2]
        w = np.einsum("k,j,i->kji", [1 - z1, z1], [1 - y1, y1], [1 - x1, x1])
        out.append(np.einsum("kji,kjic->c", w, cell))
    return np.array(out)


def test_rgb_coefficients_match_mitsuba_table():
    """The table lookup, compared in coefficient space with a float64 evaluation of the
    same lookup: pbr within float32's own conditioning of the colour (how far a 1-ulp change
    of its r, g, b moves the exact coefficients, which shifts the cell coordinates of
    coefficients up to ~1000 times the result) plus 8 ulps of the cell's largest node, and
    Mitsuba's ``srgb_model_fetch`` too. On LLVM pbr equals Mitsuba bit for bit; on an H100
    it differed by 3.5e-6 of the largest coefficient (FMA contraction and the division's
    rounding in the cell coordinates), over the bound that held on LLVM (8 ulps)."""
    rng = np.random.default_rng(1)
    cols = np.concatenate([rng.random((200, 3)), [[0, 0, 0], [1, 1, 1], [0.3, 0.3, 0.3], [0, 0, 0.2], [1, 0, 0]]])
    cols = cols.astype(np.float32)
    c = np.array(S.rgb_to_coeffs(mi.Color3f(cols.T))).T.astype(np.float64)
    ref = np.array([np.array(mi.srgb_model_fetch(mi.ScalarColor3f(x))) for x in cols], np.float64)
    grey = (cols[:, 0] == cols[:, 1]) & (cols[:, 1] == cols[:, 2])
    exact = lookup_f64(cols[~grey])
    spread = np.zeros_like(exact)
    for k in range(3):
        for d in (-1, 1):
            moved = cols[~grey].copy()
            moved[:, k] = np.clip(np.nextafter(moved[:, k], np.float32(d * np.inf)), 0, 1)
            spread = np.maximum(spread, np.abs(lookup_f64(moved) - exact))
    scale, data = S._rgb2spec_np()
    node = np.abs(np.asarray(data)).max()   # (an upper bound of any cell's largest node)
    bound = spread + 8 * 2.0 ** -24 * np.maximum(np.abs(exact).max(1, keepdims=True), 1e-3 * node)
    assert (np.abs(ref[~grey] - exact) <= bound).all()          # the oracle is Mitsuba's lookup
    assert (np.abs(c[~grey] - exact) <= bound).all(), np.max(np.abs(c[~grey] - exact) / bound)
    if pbr_backend() == "llvm":
        assert np.abs(c[~grey] - ref[~grey]).max() <= 8 * 2.0 ** -24 * np.abs(ref[~grey]).max()
    # Greys: pbr solves them exactly, Mitsuba clamps them at +-8192 like pbr: compare spectra.
    lam = mi.Spectrum(400, 500, 600, 700)
    a = np.array(S.sigmoid_polynomial(mi.Array3f(c[grey].T.astype(np.float32)), lam))
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
