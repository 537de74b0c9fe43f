"""Synthetic RGL material files (the ``.bsdf`` tensor format of Dupuy & Jakob 2018) made
from an analytic BRDF: a GGX rough conductor with a spectral complex IOR. No measured
file is available offline, so the tests tabulate a known BRDF on the format's grids,
write it, and check the ``measured`` BSDF (reader, warps, evaluation) against it and
against Mitsuba's ``measured`` plugin reading the same file; the materials gallery's
``measured`` sphere shows such a file (``scenes/data/make_gallery_data.py``).

What each field holds here (see pbr.bsdfs.measured for how a reader combines them):

* ``ndf`` [n_phi, n_theta]: D(m) at m(u) with u = (sqrt(2 theta/pi), (phi + pi)/(2 pi));
* ``sigma`` [n_phi, n_theta]: the projected area sigma(w) = int D(m) <w, m> dm
  = (cos + sqrt(cos^2 + alpha(phi)^2 sin^2)) / 2 for GGX;
* ``vndf`` [n_phi_i, n_theta_i, H, W]: the density of u_m (unnormalised), i.e.
  D(m) <wi, m> times the Jacobian 2 pi^2 u_x sin(theta_m) (constants dropped);
* ``spectra`` [n_phi_i, n_theta_i, n_lambda, N, N]: S at the nodes s of the sample space,
  S = F(wi.m, lambda) G1(wo) with m = VNDF warp(s) (Mitsuba's warp of the vndf table
  above) and wo the reflection of wi; then f |cos theta_o| = S D / (4 sigma);
* ``luminance`` [n_phi_i, n_theta_i, N, N]: the CIE-Y luminance of S (a sampling density);
* ``theta_i``, ``phi_i`` (radians), ``wavelengths`` (nm), ``jacobian`` = 1,
  ``isotropic``, ``description``.
"""

from __future__ import annotations

import os
import struct

import numpy as np
import mitsuba as mi

from ..spectrum import cie_tables_np, read_spd

_TYPES = {np.dtype(np.uint8): 1, np.dtype(np.float32): 10, np.dtype(np.float64): 11}


def write_tensor_file(path: str, fields: dict) -> None:
    """Write Mitsuba's tensor file format (as ``mitsuba.tensor_io.write``, without printing)."""
    arrays = {k: (np.frombuffer(v.encode("utf8"), np.uint8) if isinstance(v, str) else np.ascontiguousarray(v))
              for k, v in fields.items()}
    header = b"tensor_file\0" + struct.pack("<BBI", 1, 0, len(arrays))
    heads = []
    for k, a in arrays.items():
        name = k.encode("utf8")
        heads.append(struct.pack("<H", len(name)) + name + struct.pack("<HB", a.ndim, _TYPES[a.dtype]))
    size = len(header) + sum(len(h) + 8 + 8 * a.ndim for h, a in zip(heads, arrays.values()))
    out, blobs, offset = [header], [], size
    for h, a in zip(heads, arrays.values()):
        offset = (offset + 7) // 8 * 8
        out.append(h + struct.pack("<Q", offset) + struct.pack("<" + "Q" * a.ndim, *a.shape))
        blobs.append((offset, a.tobytes()))
        offset += a.nbytes
    data = bytearray(b"".join(out))
    for off, b in blobs:
        data.extend(b"\0" * (off - len(data)))
        data.extend(b)
    with open(path, "wb") as f:
        f.write(bytes(data))


# -- the analytic model (numpy, float64) -------------------------------------------------
class GGXConductor:
    """GGX microfacets (alpha_u along x, alpha_v along y), Smith separable masking, and the
    exact conductor Fresnel term with IOR eta + i k tabulated at ``wavelengths``."""

    def __init__(self, alpha_u, alpha_v, wavelengths, eta, k):
        self.au, self.av = float(alpha_u), float(alpha_v)
        self.wavelengths = np.asarray(wavelengths, np.float64)
        self.eta, self.k = np.asarray(eta, np.float64), np.asarray(k, np.float64)

    def _alpha2(self, x, y):
        r2 = np.maximum(x * x + y * y, 1e-30)
        return (x * x * self.au ** 2 + y * y * self.av ** 2) / r2

    def D(self, m):
        x, y, z = m
        t = (x / self.au) ** 2 + (y / self.av) ** 2 + z * z
        return np.where(z > 0, 1.0 / (np.pi * self.au * self.av * t * t), 0.0)

    def sigma(self, w):
        x, y, z = w
        return 0.5 * (z + np.sqrt(z * z + self._alpha2(x, y) * (x * x + y * y)))

    def G1(self, w):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(w[2] > 0, w[2] / self.sigma(w), 0.0)

    def fresnel(self, cos_i, lam=None):
        """Reflectance [..., n_lambda] at the file wavelengths (or at ``lam``)."""
        eta, k = self.eta, self.k
        if lam is not None:
            eta = np.interp(lam, self.wavelengths, self.eta)
            k = np.interp(lam, self.wavelengths, self.k)
        n = eta + 1j * k
        c = np.clip(np.abs(cos_i), 0, 1)[..., None]
        ct = np.sqrt(1 - (1 - c * c) / (n * n))
        rs = (c - n * ct) / (c + n * ct)
        rp = (n * c - ct) / (n * c + ct)
        return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)

    def f_cos(self, wi, wo, lam):
        """f(wi, wo) |cos theta_o| [n, n_lambda] for unit vectors wi, wo [3, n]."""
        h = wi + wo
        m = h / np.linalg.norm(h, axis=0)
        ok = (wi[2] > 0) & (wo[2] > 0)
        val = self.D(m) * self.G1(wi) * self.G1(wo) / (4 * np.maximum(wi[2], 1e-12))
        return np.where(ok[:, None], self.fresnel(np.sum(wi * m, axis=0), lam) * val[:, None], 0.0)


def _direction(theta, phi):
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)])


def _u_grid(n_y, n_x):
    """(theta, phi) at the nodes of an n_y x n_x grid over u in [0, 1]^2."""
    ux, uy = np.meshgrid(np.linspace(0, 1, n_x), np.linspace(0, 1, n_y))
    return ux, ux ** 2 * (np.pi / 2), (2 * uy - 1) * np.pi


def gold(wavelengths):
    """eta, k of gold (Mitsuba's data) at ``wavelengths``."""
    d = os.path.join(os.path.dirname(mi.__file__), "data", "ior")
    out = []
    for c in ("eta", "k"):
        wl, v = read_spd(os.path.join(d, f"Au.{c}.spd"))
        out.append(np.interp(wavelengths, wl, v))
    return out


def write_ggx(path, alpha_u=0.2, alpha_v=None, wavelengths=np.arange(360.0, 831.0, 10.0), eta=None, k=None,
              theta_i_deg=np.linspace(0.0, 85.0, 18), phi_i=None, ndf_res=(64, 128), vndf_res=(48, 64),
              sample_res=32, spectra_scale=1.0):
    """Tabulate a GGX conductor and write it as an RGL file; returns the analytic model.

    ``phi_i`` None writes an isotropic file (one phi_i; azimuths of m relative to wi's);
    otherwise the phi_i nodes in radians (covering 2 pi, pi or pi/2 for reductions 1, 2, 4).
    ``spectra_scale`` multiplies the stored spectra (a deliberately wrong file)."""
    alpha_v = alpha_u if alpha_v is None else alpha_v
    if phi_i is None and alpha_u != alpha_v:
        raise ValueError("an isotropic file needs alpha_u == alpha_v")
    if eta is None:
        eta, k = gold(wavelengths)
    model = GGXConductor(alpha_u, alpha_v, wavelengths, eta, k)
    isotropic = phi_i is None
    phi_i = np.array([0.0]) if isotropic else np.asarray(phi_i, np.float64)
    theta_i = np.radians(np.asarray(theta_i_deg, np.float64))

    # ndf and sigma over the u grid of directions.
    _, th, ph = _u_grid(*ndf_res)
    w = _direction(th, ph)
    ndf = model.D(w)
    sigma = model.sigma(w)

    # VNDF density over u_m, per incident node.
    ux, th_m, ph_m = _u_grid(*vndf_res)
    vndf = np.zeros((len(phi_i), len(theta_i)) + ux.shape)
    wis = {}
    for a, p in enumerate(phi_i):
        for b, t in enumerate(theta_i):
            wi = _direction(t, p)
            wis[a, b] = wi
            m = _direction(th_m, ph_m + (p if isotropic else 0.0))
            cos_im = np.maximum(np.einsum("i,i...->...", wi, m), 0.0)
            vndf[a, b] = model.D(m) * cos_im * ux * np.sin(th_m)
    vndf = vndf.astype(np.float32)

    # S at the sample-space nodes, through Mitsuba's warp of the table above.
    warp = mi.MarginalContinuous2D2(vndf, [phi_i.tolist(), theta_i.tolist()])
    sx, sy = np.meshgrid(np.linspace(0, 1, sample_res), np.linspace(0, 1, sample_res))
    n_s = sx.size
    A, B = np.meshgrid(np.arange(len(phi_i)), np.arange(len(theta_i)), indexing="ij")
    A, B = A.ravel(), B.ravel()
    pa, tb = np.repeat(phi_i[A], n_s), np.repeat(theta_i[B], n_s)
    s = mi.Point2f(np.tile(sx.ravel(), len(A)).astype(np.float32), np.tile(sy.ravel(), len(A)).astype(np.float32))
    u_m, _ = warp.sample(s, mi.Vector2f(pa.astype(np.float32), tb.astype(np.float32)))
    u_m = np.array(u_m, np.float64)
    m = _direction(u_m[0] ** 2 * (np.pi / 2), (2 * u_m[1] - 1) * np.pi + (pa if isotropic else 0.0))
    wi = _direction(tb, pa)
    cos_im = np.sum(wi * m, axis=0)
    wo = 2 * cos_im * m - wi
    S = model.fresnel(cos_im) * (model.G1(wo) * (cos_im > 0))[:, None]
    S = S.reshape(len(phi_i), len(theta_i), sample_res, sample_res, -1).transpose(0, 1, 4, 2, 3)
    ybar = np.interp(wavelengths, np.arange(360.0, 831.0, 5.0), cie_tables_np()[0][:, 1])
    lum = np.tensordot(S, ybar / ybar.sum(), axes=([2], [0]))

    write_tensor_file(path, {
        "description": f"synthetic GGX conductor alpha=({alpha_u}, {alpha_v}) (pbr.bsdfs.rgl_synth)",
        "phi_i": phi_i.astype(np.float32),
        "theta_i": theta_i.astype(np.float32),
        "wavelengths": np.asarray(wavelengths, np.float32),
        "ndf": ndf.astype(np.float32),
        "sigma": sigma.astype(np.float32),
        "vndf": vndf,
        "luminance": lum.astype(np.float32),
        "spectra": (S * spectra_scale).astype(np.float32),
        "jacobian": np.array([1], np.uint8),
        "isotropic": np.array([1 if isotropic else 0], np.uint8),
    })
    return model
