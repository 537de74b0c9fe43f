"""The tabulated BSSRDF of pbrt-v4's ``subsurface`` material (photon beam diffusion,
Habel et al. 2013; pbrt-v4's ``TabulatedBSSRDF`` and ``BSSRDFTable``).

A table, built once per (g, eta) on the host, holds the radial profile of a
semi-infinite medium with extinction 1 for 100 single-scattering albedos and 64 optical
radii: ``profile[rho, r] = 2 pi r (S_ss(r) + S_ms(r))`` (single scattering integrated
along the refracted beam plus the dipole multiple-scattering term), its cumulative
integral over r (Catmull-Rom splines) and the effective albedo ``rho_eff[rho]``, the
total diffuse reflectance. In kernels, a medium of extinction sigma_t and albedo rho
has the profile ``S_r(r) = sigma_t^2 profile(rho, sigma_t r) / (2 pi sigma_t r)``,
interpolated by tensor Catmull-Rom splines per wavelength; radii are sampled from the
hero wavelength's profile, and the exit direction from the normalised Fresnel lobe
``S_w`` (:func:`sw_eval`). The probe rays that find the exit point are the volumetric
path tracer's (:mod:`pbr.integrators.subsurface`).

Conventions: ``eta`` is the relative IOR interior / exterior (>= 1 in practice); a
``rho_eff`` given as a reflectance is inverted to an albedo (pbrt-v4's
``SubsurfaceFromDiffuse``) through a dense table of the inverse spline.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..phase import hg
from .fresnel import fresnel_dielectric

N_RHO, N_RADIUS = 100, 64       # pbrt-v4's table size
N_INVERSE = 2048                # samples of the inverse rho_eff -> rho (linear interpolation)
BEAM_SAMPLES = 100              # depths per beam integral (pbrt-v4's)
R_MAX_U = 0.999                 # radius quantile bounding the probe sphere (pbrt-v4's)
AXIS_PROB = (0.25, 0.25, 0.5)   # probe along the two tangents and the normal


# ------------------------------------------------------------------ host: the table

def rho_nodes() -> np.ndarray:
    """Albedo samples, denser near 1: (1 - exp(-8 i / 99)) / (1 - exp(-8))."""
    i = np.arange(N_RHO, dtype=np.float64)
    return ((1.0 - np.exp(-8.0 * i / (N_RHO - 1))) / (1.0 - math.exp(-8.0))).astype(np.float32)


def radius_nodes() -> np.ndarray:
    """Optical radii: 0, then 2.5e-3 growing by 1.2 per sample (float32 products, as pbrt-v4)."""
    r = np.zeros(N_RADIUS, dtype=np.float32)
    r[1] = np.float32(2.5e-3)
    for i in range(2, N_RADIUS):
        r[i] = r[i - 1] * np.float32(1.2)
    return r


# pbrt-v4's polynomial fits of the first Fresnel moment, for eta < 1 and eta >= 1.
_FM1 = ((0.45966, -1.73965, 3.37668, -3.904945, 2.49277, -0.68441),
        (-4.61686, 11.1136, -10.4646, 5.11455, -1.27198, 0.12746))


def _polynomial(c, x):
    v = 0.0 * x
    for ck in reversed(c):
        v = v * x + ck
    return v


def fresnel_moment1(eta):
    """pbrt-v4's fit of the first Fresnel moment, the integral of F(mu) mu over mu in
    [0, 1] (for a float or a Dr.Jit array ``eta``)."""
    lo, hi = _polynomial(_FM1[0], eta), _polynomial(_FM1[1], eta)
    if isinstance(eta, dr.ArrayBase):
        return dr.select(eta < 1, lo, hi)
    return lo if eta < 1 else hi


def fresnel_moment2(eta: float) -> float:
    """pbrt-v4's polynomial fit of the second Fresnel moment (integral of F cos^2)."""
    if eta < 1:
        c = (0.27614, -0.87350, 1.12077, -0.65095, 0.07883, 0.04860)
        return sum(ci * eta ** k for k, ci in enumerate(c))
    r = 1.0 / eta
    return (-547.033 + 45.3087 * r ** 3 - 218.725 * r ** 2 + 458.843 * r + 404.557 * eta - 189.519 * eta ** 2
            + 54.9327 * eta ** 3 - 9.00603 * eta ** 4 + 0.63942 * eta ** 5)


def _depths():
    """Midpoint quantiles of an exponential with unit rate: -log(1 - (i + 1/2) / n)."""
    return -np.log(1.0 - (np.arange(BEAM_SAMPLES) + 0.5) / BEAM_SAMPLES)


def beam_diffusion_ms(rho: np.ndarray, r: np.ndarray, g: float, eta: float) -> np.ndarray:
    """Multiple scattering of a beam entering a unit-extinction medium of albedo ``rho``
    at radius ``r`` (broadcast arrays): a dipole (Grosjean's diffusion coefficient and
    the extrapolated boundary) per point source along the beam, averaged over depths."""
    rho, r = np.broadcast_arrays(np.asarray(rho, np.float64), np.asarray(r, np.float64))
    sa, ss = 1.0 - rho, rho
    sps = ss * (1.0 - g)
    spt = sa + sps
    rhop = sps / spt
    D = (2.0 * sa + sps) / (3.0 * spt * spt)
    s_tr = np.sqrt(np.maximum(sa / D, 0.0))
    fm1, fm2 = fresnel_moment1(eta), fresnel_moment2(eta)
    ze = -2.0 * D * (1.0 + 3.0 * fm2) / (1.0 - 2.0 * fm1)
    c_phi, c_e = 0.25 * (1.0 - 2.0 * fm1), 0.5 * (1.0 - 3.0 * fm2)
    zr = _depths()[:, None] / spt.reshape(1, -1)           # (depth, point)
    rr, sr, Dd, ze_, rp, sp = (a.reshape(1, -1) for a in (r, s_tr, D, ze, rhop, spt))
    zv = 2.0 * ze_ - zr
    d_r, d_v = np.sqrt(rr * rr + zr * zr), np.sqrt(rr * rr + zv * zv)
    er, ev = np.exp(-sr * d_r), np.exp(-sr * d_v)
    phi = (er / d_r - ev / d_v) / (4.0 * math.pi * Dd)
    e_n = (zr * (1.0 + sr * d_r) * er / d_r ** 3 - zv * (1.0 + sr * d_v) * ev / d_v ** 3) / (4.0 * math.pi)
    kappa = 1.0 - np.exp(-2.0 * sp * (d_r + zr))
    return (kappa * rp * rp * (phi * c_phi + e_n * c_e)).mean(axis=0).reshape(rho.shape)


def beam_diffusion_ss(rho: np.ndarray, r: np.ndarray, g: float, eta: float) -> np.ndarray:
    """Single scattering along the refracted beam (unit extinction, albedo ``rho``) seen
    at radius ``r``, from depths beyond the critical angle's, averaged over depths."""
    rho, r = np.broadcast_arrays(np.asarray(rho, np.float64), np.asarray(r, np.float64))
    t_crit = r.reshape(1, -1) * math.sqrt(max(eta * eta - 1.0, 0.0))
    t = t_crit + _depths()[:, None]
    d = np.sqrt(r.reshape(1, -1) ** 2 + t * t)
    cos_o = t / d
    # The phase function and the Fresnel transmission (leaving the medium) are pbr's own.
    c = mi.Float(np.ravel(cos_o).astype(np.float32))
    ph = np.asarray(hg(c, g), np.float64).reshape(cos_o.shape)
    tr = 1.0 - np.asarray(fresnel_dielectric(-c, eta)[0], np.float64).reshape(cos_o.shape)
    ess = rho.reshape(1, -1) * np.exp(-(d + t_crit)) / (d * d) * ph * tr * cos_o
    return ess.mean(axis=0).reshape(rho.shape)


def _hermite_slopes(x: np.ndarray, f: np.ndarray):
    """Per segment of a Catmull-Rom spline through (x, f) (f: (..., n)): (width, f0, f1,
    d0, d1), the slopes as finite differences scaled to the segment (one-sided at ends)."""
    w = np.diff(x)
    f0, f1 = f[..., :-1], f[..., 1:]
    d0 = f1 - f0
    d0[..., 1:] = w[1:] * (f[..., 2:] - f[..., :-2]) / (x[2:] - x[:-2])
    d1 = f1 - f0
    d1[..., :-1] = w[:-1] * (f[..., 2:] - f[..., :-2]) / (x[2:] - x[:-2])
    return w, f0, f1, d0, d1


def integrate_spline(x: np.ndarray, f: np.ndarray):
    """(integral, running integral at each node) of the Catmull-Rom spline through (x, f)."""
    w, f0, f1, d0, d1 = _hermite_slopes(x, f)
    seg = w * (0.5 * (f0 + f1) + (d0 - d1) / 12.0)
    cdf = np.concatenate([np.zeros(f.shape[:-1] + (1,)), np.cumsum(seg, axis=-1)], axis=-1)
    return cdf[..., -1], cdf


def invert_spline(x: np.ndarray, f: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x where the increasing Catmull-Rom spline through (x, f) takes the values ``y``
    (clamped to the ends), by bisection to float64 precision."""
    y = np.asarray(y, np.float64)
    w, f0, f1, d0, d1 = _hermite_slopes(x, f)
    i = np.clip(np.searchsorted(f, y, side="right") - 1, 0, len(x) - 2)
    lo, hi = np.zeros_like(y), np.ones_like(y)
    for _ in range(60):
        t = 0.5 * (lo + hi)
        t2, t3 = t * t, t * t * t
        v = ((2 * t3 - 3 * t2 + 1) * f0[i] + (-2 * t3 + 3 * t2) * f1[i] + (t3 - 2 * t2 + t) * d0[i]
             + (t3 - t2) * d1[i])
        up = v < y
        lo, hi = np.where(up, t, lo), np.where(up, hi, t)
    out = x[i] + 0.5 * (lo + hi) * w[i]
    return np.where(y <= f[0], x[0], np.where(y >= f[-1], x[-1], out))


class Table:
    """pbrt-v4's BSSRDFTable for asymmetry ``g`` and relative IOR ``eta`` (NumPy arrays):
    ``profile`` and ``cdf`` (N_RHO, N_RADIUS), ``rho_eff`` (N_RHO), ``inverse``
    (N_INVERSE: the albedo whose rho_eff is ``k / (N_INVERSE - 1) * rho_eff[-1]``)."""

    _cache: dict = {}

    def __init__(self, g: float, eta: float):
        self.g, self.eta = g, eta
        self.rho, self.radius = rho_nodes(), radius_nodes()
        rho = self.rho.astype(np.float64)[:, None]
        r = self.radius.astype(np.float64)[None, :]
        prof = 2.0 * math.pi * r * (beam_diffusion_ss(rho, r, g, eta) + beam_diffusion_ms(rho, r, g, eta))
        self.profile = prof.astype(np.float32)
        rho_eff, cdf = integrate_spline(self.radius.astype(np.float64), self.profile.astype(np.float64))
        self.rho_eff, self.cdf = rho_eff.astype(np.float32), cdf.astype(np.float32)
        y = np.linspace(0.0, float(self.rho_eff[-1]), N_INVERSE)
        self.inverse = invert_spline(self.rho.astype(np.float64), self.rho_eff.astype(np.float64), y).astype(
            np.float32)

    @classmethod
    def get(cls, g: float, eta: float) -> "Table":
        key = (float(g), float(eta))
        if key not in cls._cache:
            cls._cache[key] = cls(*key)
        return cls._cache[key]

    def albedo_from_reflectance(self, r: np.ndarray) -> np.ndarray:
        """NumPy SubsurfaceFromDiffuse: the albedo whose effective albedo is ``r``."""
        return invert_spline(self.rho.astype(np.float64), self.rho_eff.astype(np.float64), r)


# ------------------------------------------------------------- kernels: the profile

class Tables:
    """The tables of a scene's subsurface instances, concatenated for gathers (instance
    ``k``'s rows start at ``k * N_RHO``)."""

    def __init__(self, tables: list):
        self.rho = mi.Float(rho_nodes())
        self.radius = mi.Float(radius_nodes())
        self.profile = mi.Float(np.concatenate([t.profile.ravel() for t in tables]))
        self.cdf = mi.Float(np.concatenate([t.cdf.ravel() for t in tables]))
        self.rho_eff = mi.Float(np.concatenate([t.rho_eff for t in tables]))
        self.rho_eff_max = mi.Float([float(t.rho_eff[-1]) for t in tables])
        self.inverse = mi.Float(np.concatenate([t.inverse for t in tables]))
        self.eta = mi.Float([t.eta for t in tables])


def _interval(nodes, n: int, x, guess):
    """Index i in [0, n - 2] with nodes[i] <= x < nodes[i + 1] (the last segment for x at
    the end), from an analytic ``guess`` corrected by one step each way."""
    i = mi.UInt32(dr.clip(guess, 0, n - 2))
    below = dr.gather(mi.Float, nodes, i) > x
    i = dr.select(below & (i > 0), i - 1, i)
    above = dr.gather(mi.Float, nodes, i + 1) <= x
    i = dr.select(above & (i < n - 2), i + 1, i)
    return i


def _rho_interval(rho, x):
    g = -(N_RHO - 1) / 8.0 * dr.log(dr.maximum(1.0 - x * (1.0 - math.exp(-8.0)), 1e-30))
    return _interval(rho, N_RHO, x, mi.Int32(dr.floor(g)))


def _radius_interval(radius, x):
    g = 1.0 + dr.floor(dr.log(dr.maximum(x, 1e-30) / 2.5e-3) / math.log(1.2))
    return _interval(radius, N_RADIUS, x, mi.Int32(dr.select(x < 2.5e-3, 0.0, g)))


def spline_weights(nodes, n: int, x, i):
    """Catmull-Rom weights of nodes i - 1 .. i + 2 for x in segment i (pbrt-v4's
    ``CatmullRomWeights``: end slopes one-sided); returns (offset i - 1, [w0..w3], valid)."""
    x0, x1 = dr.gather(mi.Float, nodes, i), dr.gather(mi.Float, nodes, i + 1)
    xm = dr.gather(mi.Float, nodes, dr.maximum(mi.Int32(i) - 1, 0))
    xp = dr.gather(mi.Float, nodes, dr.minimum(i + 2, n - 1))
    w = x1 - x0
    t = (x - x0) / w
    t2 = t * t
    t3 = t2 * t
    h00, h01, h10, h11 = 2 * t3 - 3 * t2 + 1, -2 * t3 + 3 * t2, t3 - 2 * t2 + t, t3 - t2
    first, last = i == 0, i + 2 >= n
    a = dr.select(first, h10, h10 * w / (x1 - xm))         # weight of the slope at x0
    b = dr.select(last, h11, h11 * w / (xp - x0))          # weight of the slope at x1
    w0 = dr.select(first, 0.0, -a)
    w1 = h00 - dr.select(first, a, 0.0) - b
    w2 = h01 + a + dr.select(last, b, 0.0)
    w3 = dr.select(last, 0.0, b)
    valid = (x >= dr.gather(mi.Float, nodes, mi.UInt32(0))) & (x <= dr.gather(mi.Float, nodes, mi.UInt32(n - 1)))
    return mi.Int32(i) - 1, [w0, w1, w2, w3], valid


def _rows(tab, inst, rho, active):
    """(row offsets, row weights, valid) of albedo ``rho`` in instance ``inst``'s table."""
    i = _rho_interval(tab.rho, rho)
    off, w, ok = spline_weights(tab.rho, N_RHO, rho, i)
    rows = [mi.UInt32(dr.clip(off + j, 0, N_RHO - 1)) + inst * N_RHO for j in range(4)]
    return rows, w, ok & active


def _interp_rows(array, rows, w, col, active):
    """Sum_j w_j array[rows_j, col]."""
    out = mi.Float(0.0)
    for r, wj in zip(rows, w):
        out += wj * dr.gather(mi.Float, array, r * N_RADIUS + col, active)
    return out


def _profile(tab, rows, wr, r_opt, active):
    """2 pi r S(r) at optical radius ``r_opt`` (tensor spline), and whether r_opt is in range."""
    i = _radius_interval(tab.radius, r_opt)
    off, wk, ok = spline_weights(tab.radius, N_RADIUS, r_opt, i)
    ok &= active
    out = mi.Float(0.0)
    for k in range(4):
        col = mi.UInt32(dr.clip(off + k, 0, N_RADIUS - 1))
        out += wk[k] * _interp_rows(tab.profile, rows, wr, col, ok)
    return out, ok


def _spectral(fn, n=4):
    """A Spectrum from ``fn(k)`` per wavelength k."""
    return mi.Spectrum(*[fn(k) for k in range(n)])


class Profile:
    """The BSSRDF profile of a medium at a hit (per lane: instance ``inst``'s table,
    ``sigma_t`` and albedo ``rho`` per wavelength): each wavelength's table rows and
    effective albedo are looked up once and shared by every evaluation."""

    def __init__(self, tab, inst, sigma_t, rho, active):
        self.tab, self.inst, self.sigma_t, self.rho = tab, inst, sigma_t, rho
        self.rows = [_rows(tab, inst, rho[k], active) for k in range(4)]
        self.rho_eff = []
        for rows, wr, ok in self.rows:
            re = mi.Float(0.0)
            for rj, wj in zip(rows, wr):
                re += wj * dr.gather(mi.Float, tab.rho_eff, rj, ok)
            self.rho_eff.append(re)

    def sr(self, r, active, pdf: bool = False):
        """S_r(r) per wavelength (world units), or with ``pdf`` its density as a
        distribution over the plane (S_r / rho_eff)."""
        def one(k):
            rows, wr, ok = self.rows[k]
            st = self.sigma_t[k]
            r_opt = r * st
            p, ok2 = _profile(self.tab, rows, wr, r_opt, ok & active)
            v = dr.select(r_opt > 0, p / (2.0 * math.pi * dr.maximum(r_opt, 1e-30)), p) * st * st
            if pdf:
                re = self.rho_eff[k]
                v = v / dr.select(re > 0, re, 1.0)
            return dr.select(ok2, dr.maximum(v, 0.0), 0.0)
        return _spectral(one)


@dr.syntax
def _newton_bisection(F, target, active):
    """t in [0, 1] with F(t) = target (F increasing): Newton steps, bisection where a step
    leaves the bracket; returns t."""
    lo = mi.Float(0.0)
    hi = mi.Float(1.0)
    t = mi.Float(0.5)
    it = mi.UInt32(0)
    go = mi.Bool(active)
    while go:
        v, dv = F(t)
        err = v - target
        done = (dr.abs(err) <= 1e-6) | (hi - lo <= 1e-6) | (it >= 40)
        hi = dr.select(err > 0, t, hi)
        lo = dr.select(err > 0, lo, t)
        tn = t - err / dv
        t = dr.select(done, t, dr.select((tn > lo) & (tn < hi) & (dv != 0), tn, 0.5 * (lo + hi)))
        it += 1
        go &= ~done
    return t


def sample_sr(prof: Profile, u, active):
    """An optical radius sampled from the hero wavelength's profile (pbrt-v4's
    ``SampleCatmullRom2D``): invert the interpolated running integral, then the cubic
    on its segment."""
    tab = prof.tab
    rows, wr, ok = prof.rows[0]
    ok = ok & active
    total = _interp_rows(tab.cdf, rows, wr, mi.UInt32(N_RADIUS - 1), ok)
    u = u * total
    i = mi.UInt32(0)
    step = 32
    while step >= 1:
        c = i + step
        take = (c <= N_RADIUS - 2) & (_interp_rows(tab.cdf, rows, wr, dr.minimum(c, N_RADIUS - 1), ok) <= u)
        i = dr.select(take, c, i)
        step //= 2
    x0, x1 = dr.gather(mi.Float, tab.radius, i), dr.gather(mi.Float, tab.radius, i + 1)
    w = x1 - x0
    f0 = _interp_rows(tab.profile, rows, wr, i, ok)
    f1 = _interp_rows(tab.profile, rows, wr, i + 1, ok)
    fm = _interp_rows(tab.profile, rows, wr, mi.UInt32(dr.maximum(mi.Int32(i) - 1, 0)), ok)
    fp = _interp_rows(tab.profile, rows, wr, dr.minimum(i + 2, N_RADIUS - 1), ok)
    xm = dr.gather(mi.Float, tab.radius, mi.UInt32(dr.maximum(mi.Int32(i) - 1, 0)))
    xp = dr.gather(mi.Float, tab.radius, dr.minimum(i + 2, N_RADIUS - 1))
    d0 = dr.select(i > 0, w * (f1 - fm) / (x1 - xm), f1 - f0)
    d1 = dr.select(i + 2 < N_RADIUS, w * (fp - f0) / (xp - x0), f1 - f0)
    target = (u - _interp_rows(tab.cdf, rows, wr, i, ok)) / w

    def F(t):
        # The spline's integral from the segment start, and the spline itself.
        c3 = (-2.0 * d0 - d1) / 3.0 + f1 - f0
        c4 = 0.25 * (d0 + d1) + 0.5 * (f0 - f1)
        v = t * (f0 + t * (0.5 * d0 + t * (c3 + t * c4)))
        dv = f0 + t * (d0 + t * (-2.0 * d0 - d1 + 3.0 * (f1 - f0) + t * (d0 + d1 + 2.0 * (f0 - f1))))
        return v, dv

    t = _newton_bisection(F, target, ok)
    return dr.select(ok, x0 + w * t, 0.0), ok & (total > 0)


def albedo_from_reflectance(tab, inst, r, active):
    """SubsurfaceFromDiffuse's inversion per wavelength: the albedo with effective albedo
    ``r`` (a Spectrum in [0, 1]), from the dense inverse table (linear interpolation)."""
    top = dr.gather(mi.Float, tab.rho_eff_max, inst, active)

    def one(k):
        x = dr.clip(r[k] / top, 0.0, 1.0) * (N_INVERSE - 1)
        i = mi.UInt32(dr.minimum(dr.floor(x), N_INVERSE - 2))
        f = x - mi.Float(i)
        base = inst * N_INVERSE + i
        a = dr.gather(mi.Float, tab.inverse, base, active)
        b = dr.gather(mi.Float, tab.inverse, base + 1, active)
        return dr.select(r[k] >= top, 1.0, dr.fma(f, b - a, a))
    return _spectral(one)


# ------------------------------------------------------ kernels: probes and the exit lobe

def probe_frame(n):
    """The frame of the probe axes: tangents s, t and the normal ``n`` (Mitsuba's frame)."""
    return mi.Frame3f(n)


def sample_probe(prof: Profile, po, n, u1, u2, active):
    """pbrt-v4's ``SampleSp``: a probe segment (p0, p1) through the sphere around ``po``
    bounding the profile, along a tangent (probability 1/4 each) or the normal (1/2), at
    a radius sampled from the hero wavelength's profile; and the lanes that have one."""
    fr = probe_frame(n)
    along_s, along_t = u1 < AXIS_PROB[0], (u1 >= AXIS_PROB[0]) & (u1 < AXIS_PROB[0] + AXIS_PROB[1])
    axis = dr.select(along_s, fr.s, dr.select(along_t, fr.t, fr.n))
    ex = dr.select(along_s, fr.t, dr.select(along_t, fr.n, fr.s))
    ey = dr.select(along_s, fr.n, dr.select(along_t, fr.s, fr.t))
    s0 = prof.sigma_t[0]
    ok = active & (s0 > 0)
    r, ok = sample_sr(prof, u2.x, ok)
    r_max, ok = sample_sr(prof, mi.Float(R_MAX_U), ok)
    ok &= r < r_max
    r, r_max = r / s0, r_max / s0
    l = 2.0 * dr.safe_sqrt(r_max * r_max - r * r)  # noqa: E741
    phi = 2.0 * math.pi * u2.y
    sp, cp = dr.sincos(phi)
    p0 = po + r * (ex * cp + ey * sp) - 0.5 * l * axis
    return p0, p0 + l * axis, ok


def pdf_sp(prof: Profile, po, n_o, pi, n_i, active):
    """pbrt-v4's ``PDF_Sp``: the density (per area at the exit point) of finding ``pi``
    (normal ``n_i``) with :func:`sample_probe`'s three axes, per wavelength."""
    fr = probe_frame(n_o)
    d = pi - po
    dl = mi.Vector3f(dr.dot(d, fr.s), dr.dot(d, fr.t), dr.dot(d, fr.n))
    nl = mi.Vector3f(dr.dot(n_i, fr.s), dr.dot(n_i, fr.t), dr.dot(n_i, fr.n))
    radii = (dr.sqrt(dl.y * dl.y + dl.z * dl.z), dr.sqrt(dl.z * dl.z + dl.x * dl.x),
             dr.sqrt(dl.x * dl.x + dl.y * dl.y))
    out = mi.Spectrum(0.0)
    for a in range(3):
        out += prof.sr(radii[a], active, pdf=True) * (dr.abs(nl[a]) * AXIS_PROB[a])
    return out


def sw_eval(eta, wo):
    """The exit lobe S_w (pbrt-v4's ``NormalizedFresnelBxDF``) times cos, for radiance
    transport: (1 - F(cos)) / (c pi) eta^2 cos, with c = 1 - 2 FM1(1 / eta) making it
    integrate to eta^2 over the hemisphere; 0 below the surface. ``eta``: a Python float
    or a Float per lane."""
    c = 1.0 - 2.0 * fresnel_moment1(dr.rcp(eta))
    f = (1.0 - fresnel_dielectric(wo.z, eta)[0]) * eta * eta / (c * math.pi) * wo.z
    return dr.select(wo.z > 0, f, 0.0)

