"""``measured``: Mitsuba's tabulated BRDFs from the RGL material database (Dupuy & Jakob
2018): the file reader (:class:`RGLMaterial`) and the BSDF family. Tables and
sampling: docs/materials.md.
"""

from __future__ import annotations

import math
import struct

import drjit as dr
import mitsuba as mi
import numpy as np

from .base import BSDF_TYPES, BSDFType, BSDFSample, REFLECTION, GLOSSY

# Element types of Mitsuba's tensor files (its Struct type codes).
_DTYPES = {1: np.uint8, 2: np.int8, 3: np.uint16, 4: np.int16, 5: np.uint32, 6: np.int32,
           7: np.uint64, 8: np.int64, 9: np.float16, 10: np.float32, 11: np.float64}


def read_tensor_file(path: str) -> dict[str, np.ndarray]:
    """Fields of a Mitsuba tensor file ('tensor_file\\0', version 1.0, then per field: name,
    rank, element type, data offset, shape). Raises ValueError for malformed files."""
    with open(path, "rb") as f:
        buf = f.read()
    pos = 0

    def take(fmt):
        nonlocal pos
        n = struct.calcsize(fmt)
        if pos + n > len(buf):
            raise ValueError("truncated header")
        out = struct.unpack_from(fmt, buf, pos)
        pos += n
        return out

    if len(buf) < 18 or buf[:12] != b"tensor_file\0":
        raise ValueError("not a tensor file (header 'tensor_file' missing)")
    pos = 12
    if take("<BB") != (1, 0):
        raise ValueError("unknown tensor file version")
    (count,) = take("<I")
    fields = {}
    for _ in range(count):
        (n,) = take("<H")
        name = bytes(take(f"<{n}s")[0]).decode("utf8", "replace")
        ndim, dtype, offset = take("<HBQ")
        shape = take("<" + "Q" * ndim) if ndim else ()
        if dtype not in _DTYPES:
            raise ValueError(f"field {name!r}: unknown element type {dtype}")
        dt = np.dtype(_DTYPES[dtype]).newbyteorder("<")
        size = int(np.prod(shape, dtype=np.int64)) if shape else 1
        if offset + size * dt.itemsize > len(buf):
            raise ValueError(f"field {name!r}: data beyond the end of the file (truncated?)")
        fields[name] = np.frombuffer(buf, dt, size, offset).reshape(shape).astype(dt.newbyteorder("="))
    return fields


def _shape_error(name, arr, want):
    return ValueError(f"field {name!r} has shape {tuple(arr.shape)} and type {arr.dtype}, expected {want}")


class RGLMaterial:
    """The validated tables of one RGL ``.bsdf`` file (host arrays; checks as Mitsuba's)."""

    def __init__(self, path: str):
        t = read_tensor_file(path)
        need = ["theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "description", "jacobian"]
        missing = [k for k in need if k not in t]
        if missing:
            raise ValueError(f"missing field(s) {', '.join(missing)}")
        if "wavelengths" not in t:
            if "rgb" in t:
                raise ValueError("the file holds RGB data (field 'rgb'); pbr renders spectrally: "
                                 "use the spectral version of the material")
            raise ValueError("missing fields 'wavelengths' and 'spectra'")
        if "spectra" not in t:
            raise ValueError("missing field 'spectra'")
        f32 = np.dtype(np.float32)

        def check(name, ndim, dtype=f32):
            a = t[name]
            if a.ndim != ndim or a.dtype != dtype:
                raise _shape_error(name, a, f"rank {ndim}, {np.dtype(dtype).name}")
            return a

        check("description", 1, np.uint8)
        self.theta_i = check("theta_i", 1)
        self.phi_i = check("phi_i", 1)
        self.wavelengths = check("wavelengths", 1)
        n_phi, n_theta, n_wl = len(self.phi_i), len(self.theta_i), len(self.wavelengths)
        self.ndf = check("ndf", 2)
        self.sigma = check("sigma", 2)
        self.vndf = self._dims(check("vndf", 4), "vndf", (n_phi, n_theta))
        self.luminance = self._dims(check("luminance", 4), "luminance", (n_phi, n_theta))
        self.spectra = self._dims(check("spectra", 5), "spectra", (n_phi, n_theta, n_wl))
        lum, spec = self.luminance.shape, self.spectra.shape
        if lum[2] != lum[3] or spec[3] != spec[4] or lum[2:] != spec[3:]:
            raise ValueError(f"fields 'luminance' {lum} and 'spectra' {spec} must share one square "
                             f"sample-space resolution")
        jac = check("jacobian", 1, np.uint8)
        if jac.shape != (1,):
            raise _shape_error("jacobian", jac, "shape (1,), uint8")
        for name in ("ndf", "sigma", "vndf", "luminance", "spectra"):
            a = getattr(self, name)
            if min(a.shape[-2:]) < 2:
                raise _shape_error(name, a, "a 2D table of at least 2 x 2 values")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"field {name!r} holds non-finite values")
        for name in ("theta_i", "phi_i", "wavelengths"):
            g = getattr(self, name)
            if len(g) < 1 or not np.all(np.diff(g) > 0) or not np.all(np.isfinite(g)):
                raise ValueError(f"field {name!r} must be a non-empty increasing grid")
        self.jacobian = bool(jac[0])
        self.description = bytes(t["description"]).decode("utf8", "replace")
        self.isotropic = n_phi <= 2
        # Anisotropic files may cover 1/2 or 1/4 of the azimuths (mirror symmetries).
        self.reduction = 1
        if not self.isotropic:
            span = float(self.phi_i[-1] - self.phi_i[0])
            self.reduction = int(round(2.0 * math.pi / span)) if span > 0 else 0
            if self.reduction not in (1, 2, 4):
                raise ValueError(f"field 'phi_i' spans {span:.4g} rad: expected 2 pi, pi or pi/2")

    @staticmethod
    def _dims(a, name, lead):
        if a.shape[:len(lead)] != tuple(lead):
            raise _shape_error(name, a, f"leading dimensions {tuple(lead)} (phi_i, theta_i"
                                        f"{', wavelengths' if len(lead) == 3 else ''})")
        return a


class _Tables:
    """Mitsuba warps over one file's tables (built for the active variant)."""

    def __init__(self, m: RGLMaterial):
        params = [m.phi_i.tolist(), m.theta_i.tolist()]
        c = np.ascontiguousarray
        self.ndf = mi.MarginalContinuous2D0(c(m.ndf), [], False, False)
        self.sigma = mi.MarginalContinuous2D0(c(m.sigma), [], False, False)
        self.vndf = mi.MarginalContinuous2D2(c(m.vndf), params)
        self.luminance = mi.MarginalContinuous2D2(c(m.luminance), params)
        self.spectra = mi.MarginalContinuous2D3(c(m.spectra), params + [m.wavelengths.tolist()], False, False)
        self.isotropic, self.jacobian, self.reduction = m.isotropic, m.jacobian, m.reduction


# -- the RGL parameterization of directions ---------------------------------------------
def _theta_to_u(theta):
    return dr.sqrt(theta * (2.0 / dr.pi))


def _u_to_theta(u):
    return dr.square(u) * (0.5 * dr.pi)


def _phi_to_u(phi):
    return (phi + dr.pi) * dr.inv_two_pi


def _u_to_phi(u):
    return (2.0 * u - 1.0) * dr.pi


def _elevation(d):
    """theta of a unit vector, accurate near the pole (2 asin(|d - z| / 2))."""
    dist = dr.sqrt(dr.square(d.x) + dr.square(d.y) + dr.square(d.z - 1.0))
    return 2.0 * dr.safe_asin(0.5 * dist)


def _mulsign_neg(a, s):
    """a * -sign(s) (sign bit of s)."""
    return dr.select(dr.copysign(1.0, s) > 0, -a, a)


def _fold(T, wi):
    """Signs (sx, sy) that fold wi into the azimuth range of a reduced file, or None."""
    if T.reduction < 2:
        return None
    sy = wi.y
    sx = wi.x if T.reduction == 4 else sy
    return sx, sy


def _apply_fold(v, signs):
    if signs is None:
        return v
    return mi.Vector3f(_mulsign_neg(v.x, signs[0]), _mulsign_neg(v.y, signs[1]), v.z)


def _jacobian(u_x, sin_theta_m, wi_dot_m):
    """d(wo) / d(u) of u -> m (theta = u_x^2 pi/2, phi = (2 u_y - 1) pi) -> reflected wo."""
    return dr.maximum(2.0 * dr.square(dr.pi) * u_x * sin_theta_m, 1e-6) * 4.0 * wi_dot_m


@BSDF_TYPES.register("measured")
class Measured(BSDFType):
    """``measured`` (Mitsuba's): a tabulated BRDF from the RGL material database (Dupuy &
    Jakob 2018, spectral files), one-sided.

    ========  ======  =======  =========================
    name      type    default  meaning
    ========  ======  =======  =========================
    filename  string  -        the .bsdf file (required)
    ========  ======  =======  =========================
    """

    name = "measured"
    flags = REFLECTION | GLOSSY

    def __init__(self):
        super().__init__()
        self._files: dict[str, RGLMaterial] = {}
        self._tables: dict[tuple[str, str], _Tables] = {}

    def add(self, loader, props) -> int:
        fname = props.string("filename")
        path = loader.resolve_path(fname, props.key("filename"))
        props.finish()
        if path not in self._files:
            try:
                self._files[path] = RGLMaterial(path)
            except (OSError, ValueError) as e:
                where = f"{fname!r}" + (f" ({path})" if path != fname else "")
                raise props.error("filename", f"cannot read RGL material file {where}: {e}") from None
        self.instances.append(path)
        return len(self.instances) - 1

    def build(self) -> None:
        # The tables never change: build each file's warps once per variant.
        files = list(dict.fromkeys(self.instances))
        for p in files:
            if (p, mi.variant()) not in self._tables:
                self._tables[p, mi.variant()] = _Tables(self._files[p])
        self.tables = [self._tables[p, mi.variant()] for p in files]
        self.file_of = mi.UInt32([files.index(p) for p in self.instances])

    # -- per-file evaluation ---------------------------------------------------------------
    @staticmethod
    def _spectrum(T, sample, phi_i, theta_i, u_m, u_wi, lam, active):
        """S(sample) at the 4 wavelengths, times D(m) / (4 sigma(wi)) if the file says so."""
        spec = mi.Spectrum([T.spectra.eval(sample, mi.Vector3f(phi_i, theta_i, lam[k]), active)
                            for k in range(dr.size_v(mi.Spectrum))])
        spec = dr.maximum(spec, 0.0)
        if T.jacobian:
            spec *= T.ndf.eval(u_m, active=active) / (4.0 * T.sigma.eval(u_wi, active=active))
        return spec

    def _eval_pdf_file(self, T, wi, wo, lam, active):
        ok = active & (wi.z > 0) & (wo.z > 0)
        signs = _fold(T, wi)
        wi, wo = _apply_fold(wi, signs), _apply_fold(wo, signs)
        m = dr.normalize(wi + wo)
        theta_i, phi_i = _elevation(wi), dr.atan2(wi.y, wi.x)
        theta_m, phi_m = _elevation(m), dr.atan2(m.y, m.x)
        u_wi = mi.Point2f(_theta_to_u(theta_i), _phi_to_u(phi_i))
        u_m = mi.Point2f(_theta_to_u(theta_m), _phi_to_u(phi_m - phi_i if T.isotropic else phi_m))
        u_m.y = u_m.y - dr.floor(u_m.y)
        params = mi.Vector2f(phi_i, theta_i)
        sample, vndf_pdf = T.vndf.invert(u_m, params, ok)
        spec = self._spectrum(T, sample, phi_i, theta_i, u_m, u_wi, lam, ok)
        pdf = vndf_pdf * T.luminance.eval(sample, params, ok)
        sin_theta_m = dr.safe_sqrt(dr.square(m.x) + dr.square(m.y))
        pdf = pdf / _jacobian(u_m.x, sin_theta_m, dr.dot(wi, m))
        ok &= dr.isfinite(pdf) & (pdf >= 0)
        return dr.select(ok, spec, 0.0), dr.select(ok, pdf, 0.0)

    def _sample_file(self, T, wi, lam, u2, active) -> BSDFSample:
        ok = active & (wi.z > 0)
        signs = _fold(T, wi)
        wi = _apply_fold(wi, signs)
        theta_i, phi_i = _elevation(wi), dr.atan2(wi.y, wi.x)
        params = mi.Vector2f(phi_i, theta_i)
        # Mitsuba's order: the luminance warp first, then the VNDF warp (swapped sample axes).
        sample, lum_pdf = T.luminance.sample(mi.Point2f(u2.y, u2.x), params, ok)
        u_m, vndf_pdf = T.vndf.sample(sample, params, ok)
        phi_m, theta_m = _u_to_phi(u_m.y), _u_to_theta(u_m.x)
        if T.isotropic:
            phi_m += phi_i
        sin_phi, cos_phi = dr.sincos(phi_m)
        sin_theta, cos_theta = dr.sincos(theta_m)
        m = mi.Vector3f(cos_phi * sin_theta, sin_phi * sin_theta, cos_theta)
        wi_dot_m = dr.dot(wi, m)
        wo = dr.fma(m, 2.0 * wi_dot_m, -wi)
        pdf = vndf_pdf * lum_pdf / _jacobian(u_m.x, sin_theta, wi_dot_m)
        u_wi = mi.Point2f(_theta_to_u(theta_i), _phi_to_u(phi_i))
        spec = self._spectrum(T, sample, phi_i, theta_i, u_m, u_wi, lam, ok)
        wo = _apply_fold(wo, signs)
        ok &= (wo.z > 0) & (pdf > 0) & dr.isfinite(pdf)
        weight = spec / dr.select(ok, pdf, 1.0)
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), mi.Float(1.0), mi.Bool(False), dr.select(ok, weight, 0.0))

    # -- the family interface: each instance reads one file ------------------------------
    def _per_file(self, idx, active, fn):
        """``fn(tables, active)`` on the lanes of each file (a single call for one file)."""
        if len(self.tables) == 1:
            return fn(self.tables[0], active)
        file = dr.gather(mi.UInt32, self.file_of, idx, active)
        out = None
        for i, T in enumerate(self.tables):
            mine = active & (file == i)
            r = fn(T, mine)
            if out is None:
                out = r
            elif isinstance(r, tuple):
                out = tuple(dr.select(mine, a, b) for a, b in zip(r, out))
            else:
                out = dr.select(mine, r, out)
        return out

    def eval_pdf(self, ctx, idx, wo, active):
        wi, lam = ctx.si.wi, ctx.wl.lambda_
        return self._per_file(idx, active, lambda T, a: self._eval_pdf_file(T, wi, wo, lam, a))

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        wi, lam = ctx.si.wi, ctx.wl.lambda_
        return self._per_file(idx, active, lambda T, a: self._sample_file(T, wi, lam, u2, a))
