"""Spectral core: sampled wavelengths, RGB upsampling, CIE colour matching.

Conventions (stated once, used everywhere):

* A *sampled spectrum* is an ``mi.Spectrum`` (4 lanes), one value per wavelength of a
  :class:`SampledWavelengths` (nm, in [360, 830]), as in pbrt-v4.
* RGB inputs are upsampled with the Jakob-Hanika sigmoid-polynomial model
  ``S(l) = s(c0 l^2 + c1 l + c2)``, ``s(x) = 1/2 + x / (2 sqrt(1 + x^2))``. The coefficient
  table is the sRGB table shipped with Mitsuba (``data/srgb.coeff``, 64^3 entries per
  dominant channel); greys use the closed form. Three forms:
  *albedo* (rgb clipped to [0, 1]), *unbounded* (``2 max(rgb)`` times the albedo form of
  ``rgb / (2 max(rgb))``) and *illuminant* (unbounded times the D65 illuminant).
* CIE 1931 2-degree colour matching functions are colour-science's, tabulated at 5 nm
  (``data/cie1931_2deg_5nm.spd``, checked against colour-science by the tests; importing
  colour-science itself costs 60 MiB and 0.6 s, as it loads matplotlib) and linearly
  interpolated; D65 is the CIE 5 nm table (``data/cie_d65_5nm.spd``).
  The normalisations are Mitsuba 3's, so that images agree with Mitsuba's spectral
  variants: XYZ = mean_i(cmf(l_i) L(l_i) / pdf(l_i)) / ``CIE_Y_INTEGRAL`` and D65 is
  scaled to unit luminance.
* Films output linear sRGB (Rec. 709 primaries, D65 white).
"""

from __future__ import annotations

import contextlib
import os
from functools import lru_cache

import drjit as dr
import mitsuba as mi
import numpy as np

from . import backend

LAMBDA_MIN = 360.0
LAMBDA_MAX = 830.0
N_WAVELENGTHS = 4
# Mitsuba 3's normalisation of its 5 nm CIE tables (a unit spectrum has luminance ~1).
CIE_Y_INTEGRAL = 106.7502593994140625
_CIE_STEP = 5.0
_CIE_SAMPLES = 95

# XYZ -> linear sRGB (Rec. 709 primaries, D65 white), the matrix Mitsuba 3 uses.
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])
SRGB_TO_XYZ = np.linalg.inv(XYZ_TO_SRGB)

_DATA = os.path.join(os.path.dirname(__file__), "data")


# ----------------------------------------------------------------------------- data

def read_table(path: str) -> np.ndarray:
    """A whitespace-separated table of numbers, ``#`` starting a comment: (rows, columns).
    Parsed here, not with ``np.loadtxt``, which imports NumPy's URL/compression readers
    (1 MiB resident); errors name the file and line."""
    rows = []
    with open(path) as f:
        for n, ln in enumerate(f, 1):
            fields = ln.split("#", 1)[0].split()
            if not fields:
                continue
            try:
                rows.append([float(x) for x in fields])
            except ValueError:
                raise ValueError(f"{path}:{n}: expected numbers, got {ln.strip()!r}") from None
            if len(rows[-1]) != len(rows[0]):
                raise ValueError(f"{path}:{n}: {len(rows[-1])} columns, the first row has {len(rows[0])}")
    if not rows:
        raise ValueError(f"{path}: no data")
    return np.array(rows)


@lru_cache(maxsize=None)
def cie_tables_np() -> tuple[np.ndarray, np.ndarray]:
    """(xyz[95, 3], d65[95]) on the 5 nm grid 360..830 nm; d65 has unit luminance."""
    xyz = read_table(os.path.join(_DATA, "cie1931_2deg_5nm.spd"))[:, 1:]
    d65 = read_table(os.path.join(_DATA, "cie_d65_5nm.spd"))[:, 1]
    # Scale D65 so that it integrates to a luminance of 1 (as XYZ is computed below).
    d65 = d65 / (np.sum(d65 * xyz[:, 1]) * _CIE_STEP / CIE_Y_INTEGRAL
                 - 0.5 * _CIE_STEP * (d65[0] * xyz[0, 1] + d65[-1] * xyz[-1, 1]) / CIE_Y_INTEGRAL)
    return xyz, d65


@lru_cache(maxsize=None)
def _rgb2spec_np() -> tuple[np.ndarray, np.ndarray]:
    """The sRGB Jakob-Hanika coefficient table: (scale[res], data[3, res, res, res, 3])."""
    path = os.path.join(os.path.dirname(mi.__file__), "data", "srgb.coeff")
    with open(path, "rb") as f:
        head = f.read(8)
    if head[:4] != b"SPEC":
        raise RuntimeError(f"{path}: not an RGB-to-spectrum coefficient table")
    res = int(np.frombuffer(head[4:8], np.uint32)[0])
    # Read in place (no intermediate copy of the 9 MiB file).
    scale = np.fromfile(path, np.float32, count=res, offset=8)
    data = np.fromfile(path, np.float32, count=9 * res ** 3, offset=8 + 4 * res)
    if data.size != 9 * res ** 3:
        raise RuntimeError(f"{path}: truncated RGB-to-spectrum coefficient table")
    return scale, data


class _Tables:
    """Dr.Jit copies of the tables, one set per active variant."""
    _cache: dict = {}

    @classmethod
    def get(cls):
        v = backend.variant()
        if v not in cls._cache:
            xyz, d65 = cie_tables_np()
            scale, data = _rgb2spec_np()
            t = {
                "x": mi.Float(xyz[:, 0]), "y": mi.Float(xyz[:, 1]), "z": mi.Float(xyz[:, 2]),
                "d65": mi.Float(d65),
                "scale": mi.Float(scale), "coeffs": mi.Float(data), "res": len(scale),
            }
            cls._cache[v] = t
        return cls._cache[v]


def tables() -> dict:
    """The Dr.Jit spectral tables of the active variant (CIE, D65, RGB coefficients)."""
    return _Tables.get()


def _lerp_table(table, lam):
    """Linear interpolation of a 5 nm table at wavelengths ``lam`` (one ``mi.Float``; 0
    outside 360-830 nm). Per wavelength: Dr.Jit traces these operations faster on flat
    arrays than on a whole Spectrum."""
    t = (lam - LAMBDA_MIN) * (1.0 / _CIE_STEP)
    inside = (lam >= LAMBDA_MIN) & (lam <= LAMBDA_MAX)
    i0 = dr.clip(mi.UInt32(dr.maximum(t, 0)), 0, _CIE_SAMPLES - 2)
    w1 = t - mi.Float(i0)
    v0 = dr.gather(mi.Float, table, i0, inside)
    v1 = dr.gather(mi.Float, table, i0 + 1, inside)
    return dr.select(inside, dr.fma(w1, v1 - v0, v0), 0.0)


def _per_lambda(table, lam: mi.Spectrum) -> mi.Spectrum:
    return mi.Spectrum([_lerp_table(table, lam[i]) for i in range(N_WAVELENGTHS)])


def cie_xyz(lam: mi.Spectrum):
    """CIE 1931 colour matching functions (x, y, z) at each wavelength."""
    t = _Tables.get()
    return tuple(_per_lambda(t[k], lam) for k in "xyz")


# ------------------------------------------------------------------ values fixed per sample
# A path keeps its camera sample's wavelengths at every vertex, so what depends on them
# alone is computed once per sample and looked up by the wavelengths' Dr.Jit variables:
# (those wavelengths, kept alive so that their variable indices cannot be reused; the
# indices; name -> value). D65 is named :data:`D65` (set by
# SampledWavelengths.sample_visible), the lights' constant spectra by their texture slots
# (TextureSet.fix_per_sample, for a pass).
_PER_SAMPLE: list = []
D65 = "d65"


def wavelength_key(lam) -> tuple:
    """Identity of the wavelength variables ``lam`` (their Dr.Jit variable indices): what
    the values fixed once per camera sample are looked up by."""
    return tuple(c.index for c in lam)


def fixed_for(lam) -> dict | None:
    """name -> value fixed once per camera sample at wavelengths ``lam``, or None."""
    return _PER_SAMPLE[2] if _PER_SAMPLE and _PER_SAMPLE[1] == wavelength_key(lam) else None


def fix(lam, values: dict) -> None:
    """Fix ``values`` (name -> value) at wavelengths ``lam``, next to those already fixed
    there; what was fixed at other wavelengths is dropped."""
    _PER_SAMPLE[:] = [lam, wavelength_key(lam), {**(fixed_for(lam) or {}), **values}]


def release(keep=(D65,)) -> None:
    """Drop the fixed values but those named in ``keep`` (a pass's emitter spectra go,
    the sample's D65 stays)."""
    if _PER_SAMPLE:
        _PER_SAMPLE[2] = {k: v for k, v in _PER_SAMPLE[2].items() if k in keep}


@contextlib.contextmanager
def fixed_as(lam, values: dict):
    """Within the block, ``values`` (name -> value) are the values fixed at wavelengths
    ``lam``: those passed into a symbolic call (``LightSet``'s dispatch), whose wavelengths
    and values are the call's own variables."""
    prev = list(_PER_SAMPLE)
    _PER_SAMPLE[:] = [lam, wavelength_key(lam), values]
    try:
        yield
    finally:
        _PER_SAMPLE[:] = prev


def d65(lam: mi.Spectrum) -> mi.Spectrum:
    """The D65 illuminant, scaled to unit luminance. At the wavelengths a camera sample
    drew (``SampledWavelengths.sample_visible``) it is the value computed there, once per
    sample: emitters look it up at every path vertex, inside loops that would otherwise
    repeat the table lookups at each bounce."""
    fixed = fixed_for(lam)
    if fixed is not None and D65 in fixed:
        return fixed[D65]
    return _per_lambda(_Tables.get()["d65"], lam)


# ------------------------------------------------------------------ wavelengths

class SampledWavelengths(metaclass=backend.VariantStruct):
    """Four wavelengths (nm) and their sampling densities (1/nm), as in pbrt-v4."""

    _fields = {"lambda_": "Spectrum", "pdf": "Spectrum"}

    def __init__(self, lambda_=None, pdf=None):
        self.lambda_ = lambda_ if lambda_ is not None else mi.Spectrum(0)
        self.pdf = pdf if pdf is not None else mi.Spectrum(0)

    @staticmethod
    def sample_visible(u: mi.Float) -> "SampledWavelengths":
        """Importance-sample the visible range with stratified lanes (pbrt-v4's
        ``SampleVisibleWavelengths``: density ~ 1/cosh^2(0.0072 (l - 538)))."""
        # (per wavelength: Dr.Jit's atanh and cosh trace faster on flat arrays)
        lam, pdf = [], []
        for i in range(N_WAVELENGTHS):
            up = u + i / N_WAVELENGTHS
            up = dr.select(up >= 1.0, up - 1.0, up)
            l = 538.0 - 138.888889 * dr.atanh(0.85691062 - 1.82750197 * up)
            c = dr.cosh(0.0072 * (l - 538.0))
            lam.append(l)
            pdf.append(dr.select((l >= LAMBDA_MIN) & (l <= LAMBDA_MAX), 0.0039398042 / (c * c), 0.0))
        lam, pdf = mi.Spectrum(lam), mi.Spectrum(pdf)
        fix(lam, {D65: _per_lambda(_Tables.get()["d65"], lam)})
        return SampledWavelengths(lam, pdf)

    def secondary_terminated(self) -> mi.Bool:
        return self.pdf[1] == 0

    def terminate_secondary(self) -> "SampledWavelengths":
        """Keep only the first wavelength (after wavelength-dependent refraction). The
        film averages over the lanes, so the survivor's density is divided by their number."""
        pdf = mi.Spectrum(self.pdf[0] / N_WAVELENGTHS, 0, 0, 0)
        return SampledWavelengths(self.lambda_, dr.select(self.secondary_terminated(), self.pdf, pdf))


def first_only(s) -> mi.Spectrum:
    """``(N s[0], 0, .., 0)``: the first wavelength's value standing for all ``N``; pbrt-v4's
    TerminateSecondary applied to a radiance or throughput instead of the densities."""
    return mi.Spectrum(s[0] * N_WAVELENGTHS, 0.0, 0.0, 0.0)


def to_xyz(L: mi.Spectrum, wl: SampledWavelengths) -> mi.Array3f:
    """Monte Carlo estimate of the XYZ tristimulus values of the spectrum ``L``."""
    x, y, z = cie_xyz(wl.lambda_)
    inv = dr.select(wl.pdf != 0, dr.rcp(wl.pdf), 0.0) * (1.0 / (N_WAVELENGTHS * CIE_Y_INTEGRAL))
    Lw = L * inv
    return mi.Array3f(dr.sum(x * Lw), dr.sum(y * Lw), dr.sum(z * Lw))


def to_xyz_adjoint(g_xyz: mi.Array3f, wl: SampledWavelengths) -> mi.Spectrum:
    """Transpose of :func:`to_xyz`: the adjoint radiance for an XYZ adjoint ``g_xyz``."""
    x, y, z = cie_xyz(wl.lambda_)
    inv = dr.select(wl.pdf != 0, dr.rcp(wl.pdf), 0.0) * (1.0 / (N_WAVELENGTHS * CIE_Y_INTEGRAL))
    return (g_xyz[0] * x + g_xyz[1] * y + g_xyz[2] * z) * inv


def srgb_to_xyz_adjoint(g_rgb: mi.Array3f) -> mi.Array3f:
    """Transpose of :func:`xyz_to_srgb` (maps an sRGB adjoint to an XYZ adjoint)."""
    m = XYZ_TO_SRGB.tolist()
    return mi.Array3f(*[m[0][c] * g_rgb[0] + m[1][c] * g_rgb[1] + m[2][c] * g_rgb[2] for c in range(3)])


def xyz_to_srgb(xyz):
    """XYZ -> linear sRGB; works on Dr.Jit Array3f and on numpy (..., 3) arrays."""
    if isinstance(xyz, np.ndarray):
        return xyz @ XYZ_TO_SRGB.T
    m = XYZ_TO_SRGB.tolist()  # Python floats (numpy scalars would convert Dr.Jit arrays)
    return type(xyz)(*[m[r][0] * xyz[0] + m[r][1] * xyz[1] + m[r][2] * xyz[2] for r in range(3)])


def luminance_rgb(rgb):
    """Luminance (Y) of linear sRGB values."""
    m = SRGB_TO_XYZ[1].tolist()
    return m[0] * rgb[0] + m[1] * rgb[1] + m[2] * rgb[2]


# ---------------------------------------------------------------- RGB upsampling

_GREY_LIMIT = 8192.0
# The wavelength at which a table derivative is carried over to a grey's coefficients.
_LAMBDA_REF = 555.0
# Black has no table derivative (the table divides by the brightest channel): it takes
# the one-sided derivative of this grey, where they have converged (d/dr of an albedo's
# image under D65: 0.989 at 1e-3, 0.988 at 1e-2).
_BLACK_PROBE = 1e-3


def clamp_keep_grad(x, lo=None, hi=None):
    """``x`` clamped to [lo, hi] (either bound may be None) with the derivative of ``x``
    itself. For clamps that are numerical safety, not part of the model: a roughness
    floor, the RGB upsampling's [0, 1]. Dr.Jit's ``dr.maximum(x, lo)`` has derivative 0
    for ``x <= lo``, so a parameter at or below such a bound (an albedo of 0, a roughness
    of 0) got no gradient at all; here it gets the derivative at the bound, the
    one-sided derivative an optimisation starting there needs."""
    c = x
    if lo is not None:
        c = dr.maximum(c, lo)
    if hi is not None:
        c = dr.minimum(c, hi)
    return dr.replace_grad(c, x) if dr.grad_enabled(x) else c


def _dsigmoid(x):
    """Derivative of the sigmoid ``s(x) = 1/2 + x / (2 sqrt(1 + x^2))``: ``(1 + x^2)^(-3/2) / 2``."""
    r = dr.rsqrt(dr.fma(x, x, 1.0))
    return 0.5 * r * r * r


def _dominant(r, g, b):
    """Index of the brightest channel (ties toward the later channel, as the table
    expects) and its value (selected, so that a tie's derivative follows the index)."""
    i = dr.select(g >= r, 1, 0)
    vi = dr.select(g >= r, g, r)
    i = mi.UInt32(dr.select(b >= vi, 2, i))
    return i, dr.select(i == 0, r, dr.select(i == 1, g, b))


def _table_lookup(r, g, b, i, z) -> mi.Array3f:
    """Trilinear lookup in the Jakob-Hanika table of dominant channel ``i`` (value ``z``):
    differentiable in the channels through the cell weights."""
    t = _Tables.get()
    res = t["res"]
    a = dr.select(i == 0, g, dr.select(i == 1, b, r))  # channel (i+1) % 3
    c = dr.select(i == 0, b, dr.select(i == 1, r, g))  # channel (i+2) % 3
    sc = (res - 1) / dr.maximum(z, 1e-30)
    x, y = a * sc, c * sc
    xi = dr.minimum(mi.UInt32(dr.detach(x)), res - 2)
    yi = dr.minimum(mi.UInt32(dr.detach(y)), res - 2)
    scale = t["scale"]
    zd = dr.detach(z)
    zi = dr.binary_search(0, res - 2, lambda k: dr.gather(mi.Float, scale, k + 1) <= zd)
    zi = dr.minimum(zi, res - 2)
    s0 = dr.gather(mi.Float, scale, zi)
    s1 = dr.gather(mi.Float, scale, zi + 1)
    x1, y1 = x - mi.Float(xi), y - mi.Float(yi)
    z1 = (z - s0) / (s1 - s0)
    x0, y0, z0 = 1.0 - x1, 1.0 - y1, 1.0 - z1
    base = (((i * res + zi) * res + yi) * res + xi) * 3
    dx, dy, dz = 3, 3 * res, 3 * res * res
    out = []
    for k in range(3):
        def tap(o, k=k):
            return dr.gather(mi.Float, t["coeffs"], base + o + k)
        out.append(
            z0 * (y0 * (x0 * tap(0) + x1 * tap(dx)) + y1 * (x0 * tap(dy) + x1 * tap(dy + dx)))
            + z1 * (y0 * (x0 * tap(dz) + x1 * tap(dz + dx))
                    + y1 * (x0 * tap(dz + dy) + x1 * tap(dz + dy + dx))))
    return mi.Array3f(out)


@lru_cache(maxsize=None)
def _white_derivative_np() -> np.ndarray:
    """Per channel (columns), the quadratic ``q`` (rows: its l^2, l, 1 coefficients)
    standing for the one-sided derivative of the albedo spectrum at white (lowering the
    channel): the secant to the table's neighbouring node, one cell (1 / (res - 1)) below
    white in that channel, as a quadratic spectrum with the same D65 tristimulus values
    (a grey's coefficients can only move by a quadratic in l). NumPy only, so that it can
    be computed anywhere (inside kernels being traced, inside ``dr.freeze``)."""
    scale, data = _rgb2spec_np()
    n = len(scale) - 1
    table = data.reshape(3, n + 1, n + 1, n + 1, 3)     # [brightest channel, z, y, x, coefficient]
    # Lowering r or g (blue brightest by the tie rule: x = r, y = g) or b (green brightest: x = b).
    c = np.array([table[2, n, n, n - 1], table[2, n, n - 1, n], table[1, n, n, n - 1]], np.float64)
    lam = np.arange(LAMBDA_MIN, LAMBDA_MAX + 1.0)
    xyz, d65 = cie_tables_np()
    grid = LAMBDA_MIN + _CIE_STEP * np.arange(_CIE_SAMPLES)
    w = np.stack([np.interp(lam, grid, xyz[:, k]) * np.interp(lam, grid, d65) for k in range(3)])
    V = np.stack([lam * lam, lam, np.ones_like(lam)], 1)
    x = c @ V.T
    S = 0.5 + x / (2.0 * np.sqrt(1.0 + x * x))                         # (3 channels, n_lambda)
    return np.linalg.solve(w @ V, w @ ((1.0 - S) * n).T)                 # white is S = 1


def _grey_coeffs(r, g, b) -> mi.Array3f:
    """Coefficients of a grey ``r = g = b = v``: the exact flat solution
    ``(0, 0, (v - 1/2) / sqrt(v (1 - v)))`` (clamped at +-8192), with a derivative.

    A grey is where the three dominant-channel tables meet, and its value is not the
    tables' (they differ from the flat solution by up to 3e-4 near white), so the
    derivative is assembled from one-sided ones:

    * lowering channel ``k`` moves into a table where ``k`` is not the brightest: that
      table's derivative ``J_k`` along its in-cell coordinate;
    * raising it makes ``k`` the brightest; that side is taken as the exact grey
      derivative ``G`` (a flat unit spectrum) minus the other two channels' ``J``, since
      raising all three is exactly the flat direction.

    Channel ``k``'s derivative is the mean of the two sides (what central differences
    measure): for a tangent ``d``, ``G sum(d) / 2 + sum_k J_k (d_k - sum(d) / 2)``. The
    table's derivative is carried to the grey's coefficients by the ratio of the sigmoid's
    slopes at :data:`_LAMBDA_REF` (exact where the table's polynomial is flat in
    wavelength: within 1% up to v = 0.99). Black has no table derivative (the table
    divides by the brightest channel): it takes the derivative of the grey
    :data:`_BLACK_PROBE`, the limit of the greys' (continuous at 0). Only raising is
    possible there, and the spectra of the darkest colours are narrower than any
    quadratic change of a grey's polynomial: they have the same colour under the colour
    space's white (D65), and the Cornell box's direct light barely tells them apart, but
    light off its coloured walls does (at max_depth 4, d mean(R) / d r at black: 0.052 vs
    one-sided differences 0.071).

    At white only lowering is possible, and there the table is no guide: within the last
    cell next to white its interpolated coefficients stay saturated (the local slope is
    2% of the slope across the cell). White's derivative is the secant across that cell
    (:func:`_white_derivative_np`), so that an optimisation that starts at 1 moves."""
    v = dr.detach(b)
    c2 = dr.clip((v - 0.5) * dr.rsqrt(dr.maximum(v * (1.0 - v), 1e-30)), -_GREY_LIMIT, _GREY_LIMIT)
    if not dr.grad_enabled((r, g, b)):
        return mi.Array3f(0.0, 0.0, c2)
    half = 0.5 * (r + g + b)
    probe = dr.maximum(v, _BLACK_PROBE)

    def tangent(x):
        """The probe's value carrying the derivative of ``x - sum / 2``."""
        d = x - half
        return probe + (d - dr.detach(d))

    # J_r and J_g from the blue table (r, g below b); J_b from the red table (b below r).
    j_rg = _table_lookup(tangent(r), tangent(g), probe, mi.UInt32(2), probe)
    j_b = _table_lookup(probe, probe, tangent(b), mi.UInt32(0), probe)
    table = dr.detach(j_rg)
    x = dr.fma(dr.fma(table[0], _LAMBDA_REF, table[1]), _LAMBDA_REF, table[2])
    dS = _dsigmoid(x) * ((j_rg - table) + (j_b - dr.detach(j_b)))
    dS[2] += half - dr.detach(half)
    # White: the secants, as a quadratic spectrum per channel.
    d = mi.Vector3f(r - dr.detach(r), g - dr.detach(g), b - dr.detach(b))
    dS = dr.select(v >= 1.0, mi.Matrix3f(_white_derivative_np().tolist()) @ d, dS)
    # d S = s'(c2) d(poly): the flat solution's coefficients move by d S / s'(c2).
    return mi.Array3f(0.0, 0.0, c2) + dS / _dsigmoid(c2)


def rgb_to_coeffs(rgb: mi.Color3f) -> mi.Array3f:
    """Sigmoid-polynomial coefficients for sRGB albedos in [0, 1] (vectorised and
    differentiable in ``rgb``: a trilinear lookup in the Jakob-Hanika table; greys, where
    the three tables meet, have the exact flat solution and the derivative of
    :func:`_grey_coeffs`). The clip to [0, 1] keeps the derivative (:func:`clamp_keep_grad`),
    so an optimisation may start at black or white (values outside [0, 1] are rejected
    where parameters are validated)."""
    rgb = mi.Color3f(rgb)
    r, g, b = (clamp_keep_grad(rgb[k], 0.0, 1.0) for k in range(3))
    i, z = _dominant(r, g, b)
    coeffs = _table_lookup(r, g, b, i, z)
    return dr.select((r == g) & (g == b), _grey_coeffs(r, g, b), coeffs)


def sigmoid_polynomial(coeffs: mi.Array3f, lam: mi.Spectrum) -> mi.Spectrum:
    """Evaluate the sigmoid polynomial (values in [0, 1]) at each wavelength.

    For negative ``x`` the sigmoid is evaluated as ``r^2 / (2 (1 - x r))``, ``r = 1 /
    sqrt(1 + x^2)`` (the same function without the cancellation of ``1/2 + x r / 2``):
    a black albedo (x = -8192) is 3.7e-9, not float32 rounding noise or 0, so that paths
    continue past it and its derivative reaches the light beyond (a zero throughput
    ends a path, and Path Replay Backpropagation divides by the BSDF value). Its
    derivative is the closed form ``r^3 / 2``: Dr.Jit's derivative of the expression
    cancels catastrophically where ``|x|`` is large (dark and bright colours)."""
    x = dr.fma(dr.fma(coeffs[0], lam, coeffs[1]), lam, coeffs[2])
    r = dr.rsqrt(dr.fma(x, x, 1.0))
    y = type(x)(dr.select(x < 0, 0.5 * r * r / dr.fma(-x, r, 1.0), dr.fma(0.5 * x, r, 0.5)))
    if dr.grad_enabled(x):
        xd = dr.detach(x)
        y = dr.detach(y) + _dsigmoid(xd) * (x - xd)
    return y


def rgb_unbounded(rgb: mi.Color3f) -> tuple[mi.Array3f, mi.Float]:
    """(coefficients, scale) of the unbounded form: scale * S(l) reproduces ``rgb``.

    At black (scale 0) the spectrum ``scale * S`` has a derivative only through the
    scale: it is taken as that of ``2 mean(rgb)`` times the flat albedo 1/2, so that
    raising all channels from 0 has the exact (flat) derivative; a single channel's gets
    a flat spectrum of a third of that (a colour needs a non-zero scale)."""
    rgb = mi.Color3f(rgb)
    m = dr.maximum(dr.maximum(rgb[0], rgb[1]), rgb[2])
    black = (rgb[0] == 0) & (rgb[1] == 0) & (rgb[2] == 0)
    scale = dr.select(black, (2.0 / 3.0) * (rgb[0] + rgb[1] + rgb[2]), 2.0 * m)
    coeffs = rgb_to_coeffs(dr.select(black, 0.5, rgb / dr.maximum(2.0 * m, 1e-30)))
    return coeffs, scale


# ------------------------------------------------------------------ named spectra

_PLANCK_C = 2.99792458e8
_PLANCK_H = 6.62607004e-34
_PLANCK_K = 1.38064852e-23


def blackbody(lam, temperature: float):
    """Planck's law in W / (m^2 sr nm) (unnormalised, as Mitsuba's ``blackbody``)."""
    l = lam * 1e-9
    c0 = 2.0 * _PLANCK_H * _PLANCK_C ** 2
    c1 = _PLANCK_H * _PLANCK_C / _PLANCK_K
    if isinstance(l, np.ndarray):
        return 1e-9 * c0 / (l ** 5 * (np.exp(c1 / (l * temperature)) - 1.0))
    return 1e-9 * c0 / (l ** 5 * (dr.exp(c1 / (l * temperature)) - 1.0))


def blackbody_normalised(lam, temperature):
    """Planck's law divided by its peak value (Wien's displacement law: the peak is at
    2.8977721e-3 / T metres), pbrt-v4's ``BlackbodySpectrum``; numpy or Dr.Jit."""
    return blackbody(lam, temperature) / blackbody(2.8977721e-3 / temperature * 1e9, temperature)


# Sellmeier coefficients (B1, B2, B3, C1, C2, C3; C in um^2) of optical glasses (Schott data).
SELLMEIER = {
    "glass-bk7": (1.03961212, 0.231792344, 1.01046945, 0.00600069867, 0.0200179144, 103.560653),
    "glass-baf10": (1.5851495, 0.143559385, 1.08521269, 0.00926681282, 0.0424489805, 105.613573),
    "glass-sf11": (1.73759695, 0.313747346, 1.89878101, 0.013188707, 0.0623068142, 155.23629),
    "fused-silica": (0.6961663, 0.4079426, 0.8974794, 0.0684043 ** 2, 0.1162414 ** 2, 9.896161 ** 2),
}


def sellmeier_ior(name: str, lam_nm: np.ndarray) -> np.ndarray:
    """Refractive index of a named glass (:data:`SELLMEIER`) at wavelengths in nm."""
    b1, b2, b3, c1, c2, c3 = SELLMEIER[name]
    l2 = (np.asarray(lam_nm, dtype=np.float64) * 1e-3) ** 2
    return np.sqrt(1.0 + b1 * l2 / (l2 - c1) + b2 * l2 / (l2 - c2) + b3 * l2 / (l2 - c3))


def read_spd(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Read a two-column ``wavelength value`` file (``#`` comments allowed)."""
    data = read_table(path)
    if data.shape[1] != 2:
        raise ValueError(f"{path}: expected two columns (wavelength value), got {data.shape[1]}")
    return data[:, 0], data[:, 1]
