"""Infinite lights: ``constant``, ``envmap`` (Mitsuba's latitude-longitude map, sampled by
luminance) and ``portalenvmap`` (pbrt-v4's portal light). They are evaluated on rays
that leave the scene; every convention follows Mitsuba 3.9: docs/lights.md.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..image import read_image
from ..plugins.params import ParamOwner, param_table
from ..plugins.props import FINITE, NONNEGATIVE, RADIANCE
from ..textures import load_spectrum
from .base import LIGHT_TYPES, LeSample, LightSample, LightType, ReferencePoint

INV_4PI = 1.0 / (4.0 * math.pi)


# --------------------------------------------------------------------------- helpers

def bounding_sphere(scene) -> tuple[np.ndarray, float]:
    """Centre and radius of the scene's bounding-box sphere (Mitsuba's ``set_scene``)."""
    bbox = scene.bbox()
    if not bbox.valid():
        return np.zeros(3), 1.0
    c = np.array(bbox.center(), dtype=np.float64)
    r = float(np.linalg.norm(np.array(bbox.max, dtype=np.float64) - c))
    return c, max(r * (1.0 + 1e-4), 1e-4)


def _far_point(ref_p, wi, center, radius):
    """The light's point along ``wi``: twice the larger of the scene radius and the
    reference point's distance from the centre (so shadow rays cross the whole scene)."""
    c = mi.Point3f(*[float(x) for x in center])
    dist = 2.0 * dr.maximum(radius, dr.norm(ref_p - c))
    return dr.fma(wi, dist, ref_p)


def _uniform_sphere(u: mi.Point2f) -> mi.Vector3f:
    z = dr.fma(-2.0, u.x, 1.0)
    r = dr.safe_sqrt(1.0 - z * z)
    s, c = dr.sincos(dr.two_pi * u.y)
    return mi.Vector3f(r * c, r * s, z)


def _rotation(props, name="to_world") -> np.ndarray:
    """The linear part of ``to_world`` as a rotation (a uniform scale is divided out)."""
    M = props.transform(name)
    A = M[:3, :3]
    det = float(np.linalg.det(A))
    if abs(det) < 1e-12:
        raise props.error(name, "the transform is singular")
    Q = A / abs(det) ** (1.0 / 3.0)
    if not np.allclose(Q.T @ Q, np.eye(3), atol=1e-4):
        raise props.error(name, "an environment map's to_world must be a rotation (optionally with a "
                                "uniform scale); shear and non-uniform scales are not supported")
    return Q


def _env_image(loader, props) -> np.ndarray:
    """The environment image as linear float32 RGB (H, W, 3), padded to at least 2x3."""
    given = [k for k in ("filename", "bitmap", "data") if props.has(k)]
    if len(given) != 1:
        raise props.error(None, "give exactly one of 'filename', 'bitmap' or 'data' "
                                f"(got {', '.join(given) if given else 'none'})")
    key = given[0]
    if key == "filename":
        fname = loader.resolve_path(props.string("filename"), props.key("filename"))
        try:
            img = read_image(fname)
        except Exception as e:
            raise props.error("filename", f"cannot read image {fname!r}: {e}") from None
    else:
        v = props.raw(key)
        if isinstance(v, mi.Bitmap):
            # Mitsuba's own conversion (linearises sRGB-encoded 8-bit data), as envmap does.
            v = v.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False)
        try:
            img = np.array(v, dtype=np.float32)
        except (TypeError, ValueError):
            raise props.error(key, f"expected an (H, W, C) image array or mi.Bitmap, got {type(v).__name__}") from None
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise props.error(key, f"expected an (H, W, C) image, got shape {img.shape}")
    img = np.repeat(img[..., :1], 3, axis=2) if img.shape[2] < 3 else img[..., :3]
    FINITE.check(img, props.key(key))
    img = np.maximum(img, 0.0)      # negative texels (an EXR's ringing) are black
    H, W = img.shape[:2]
    if W < 2:
        img = np.concatenate([img, np.repeat(img[:, -1:], 2 - W, axis=1)], axis=1)
    if H < 3:
        img = np.concatenate([img, np.repeat(img[-1:], 3 - H, axis=0)], axis=0)
    return np.ascontiguousarray(img, dtype=np.float32)


def _luminance(img: np.ndarray) -> np.ndarray:
    return np.maximum(np.asarray(spec.luminance_rgb(np.moveaxis(img.astype(np.float64), -1, 0))), 0.0)


def _lum_bilinear_np(lum: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear luminance at (u, v) with the envmap's texel conventions (numpy)."""
    H, W = lum.shape
    x = (u - np.floor(u)) * W - 0.5
    x0 = np.floor(x)
    wx = x - x0
    i0 = x0.astype(np.int64) % W
    i1 = (i0 + 1) % W
    y = np.clip(v, 0.0, 1.0) * (H - 1)
    j0 = np.minimum(np.floor(y).astype(np.int64), H - 2)
    wy = y - j0
    j1 = j0 + 1
    top = (1 - wx) * lum[j0, i0] + wx * lum[j0, i1]
    bot = (1 - wx) * lum[j1, i0] + wx * lum[j1, i1]
    return (1 - wy) * top + wy * bot


def _dir_to_uv(d: mi.Vector3f) -> mi.Point2f:
    u = dr.atan2(d.x, -d.z) * dr.inv_two_pi
    return mi.Point2f(u - dr.floor(u), dr.safe_acos(d.y) * dr.inv_pi)


def _infinite_sample_Le(self, idx, u_pos, u_dir, wl, active) -> LeSample:
    """Emission of an infinite light (pbrt-v4's ``SampleLe``): the direction toward the
    light as ``sample_Li`` picks it (independent of the reference point for ``constant``
    and ``envmap``), the ray starting on the disk of the scene's bounding sphere that faces
    the light, uniformly: ``pdf_pos = 1 / (pi r^2)``, ``pdf_dir`` = the density of the
    direction toward the light."""
    c = mi.Point3f(*[float(x) for x in self.center])
    ls = self.sample_Li(idx, ReferencePoint(c), u_dir, wl, active)
    d = -ls.wi
    disk = mi.warp.square_to_uniform_disk_concentric(u_pos)
    fr = mi.Frame3f(d)
    o = c + (fr.s * disk.x + fr.t * disk.y - d) * self.radius
    ok = active & (ls.pdf > 0)
    return LeSample(o=o, d=d, L=dr.select(ok, ls.L, 0.0),
                    pdf_pos=dr.select(ok, 1.0 / (math.pi * self.radius ** 2), 0.0),
                    pdf_dir=dr.select(ok, ls.pdf, 0.0), n=mi.Normal3f(d), infinite=mi.Bool(True))


def _infinite_pdf_Le(self, idx, p, n, d, active):
    """(1 / (pi r^2), density of the direction -d toward the light) for a ray along ``d``."""
    return (dr.select(active, 1.0 / (math.pi * self.radius ** 2), 0.0), self.pdf_Le_dir(idx, -d, active))


# --------------------------------------------------------------------------- constant

@LIGHT_TYPES.register("constant")
class ConstantLight(LightType):
    """``constant`` (Mitsuba's): the same radiance from every direction.

    ========  ========  =======  ================================
    name      type      default  meaning
    ========  ========  =======  ================================
    radiance  spectrum  1        radiance (not spatially varying)
    ========  ========  =======  ================================
    """

    name = "constant"
    infinite = True

    def add(self, loader, props, shape_index=None) -> int:
        slot = load_spectrum(loader, props.raw("radiance", 1.0), props.key("radiance"), emitter=True)
        if loader.textures.spatially_varying(slot):
            raise props.error("radiance", "a constant emitter needs a spatially constant radiance")
        props.finish()
        self.instances.append({"radiance": slot})
        return len(self.instances) - 1

    def build(self, scene) -> None:
        self.radiance = mi.UInt32([i["radiance"] for i in self.instances])
        self.center, self.radius = bounding_sphere(scene)

    def power(self, i: int, scene) -> float:
        _, r = bounding_sphere(scene)
        return 4.0 * math.pi * math.pi * r * r * scene.textures.constant_value(self.instances[i]["radiance"])

    def _L(self, idx, lam, active):
        slot = dr.gather(mi.UInt32, self.radiance, idx, active)
        return self.textures.eval(slot, mi.Point2f(0.0), lam, active,
                                  reach=tuple(int(i["radiance"]) for i in self.instances))

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        wi = _uniform_sphere(u)
        L = dr.select(active, self._L(idx, wl.lambda_, active), 0.0)
        return LightSample(L, wi, dr.select(active, INV_4PI, 0.0), _far_point(ref.p, wi, self.center, self.radius),
                           mi.Bool(False))

    def Le(self, idx, d, wl, active):
        return dr.select(active, self._L(idx, wl.lambda_, active), 0.0)

    def pdf_Le_dir(self, idx, d, active):
        return dr.select(active, INV_4PI, 0.0)

    # emission (light tracing)
    emits_rays = True
    sample_Le = _infinite_sample_Le
    pdf_Le = _infinite_pdf_Le


# --------------------------------------------------------------------------- envmap

@LIGHT_TYPES.register("envmap")
class EnvMapLight(LightType):
    """``envmap`` (Mitsuba's): an environment map (latitude-longitude, linear RGB), sampled
    in proportion to its luminance.

    ================  =========  ========  =====================================================
    name              type       default   meaning
    ================  =========  ========  =====================================================
    filename          string     -         the image (one of filename, bitmap, data)
    bitmap            mi.Bitmap  -         an image in memory
    data              array      -         an (H, W, C) array
    scale             float      1         factor on the radiance
    to_world          transform  identity  rotation of the map (Mitsuba's convention: +y up)
    mis_compensation  bool       false     sample a map with its mean subtracted (Karlik et al.)
    ================  =========  ========  =====================================================
    """

    name = "envmap"
    infinite = True
    emits_rays = True                  # light tracing: sample_Le / pdf_Le
    sample_Le = _infinite_sample_Le
    pdf_Le = _infinite_pdf_Le

    def add(self, loader, props, shape_index=None) -> int:
        inst = self._parse(loader, props)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def _parse(self, loader, props) -> dict:
        img = _env_image(loader, props)
        scale = props.float("scale", 1.0, min=0.0)
        inst = {"rgb": img, "scale": scale, "rot": _rotation(props),
                # Mitsuba's keys: ``<id>.data`` (H, W, 3 linear RGB texels) and ``<id>.scale``.
                "owner": ParamOwner(props.path, valid={"data": RADIANCE, "scale": NONNEGATIVE},
                                    data=mi.TensorXf(img), scale=mi.Float(scale)),
                "mis_compensation": props.bool("mis_compensation", False) if self.name == "envmap" else False,
                "id": props.id}
        return inst

    def param_owners(self) -> list:
        return [i["owner"] for i in self.instances]

    # -- tables ---------------------------------------------------------------------------
    def _build_texels(self) -> None:
        """Per-texel (sigmoid coefficients, scale) of every instance, and the per-instance
        constants: size, texel offset, scale and rotation. The texels come from the
        ``data`` parameters (differentiable); the sampling tables use their detached values."""
        for i in self.instances:
            data = i["owner"].params["data"]
            if data.shape != i["rgb"].shape:
                raise ValueError(f"{i['owner'].path}.data: shape {data.shape} must stay {i['rgb'].shape}")
            i["rgb"] = np.maximum(np.asarray(dr.detach(data), np.float32), 0.0)
            i["scale"] = float(dr.detach(i["owner"].params["scale"])[0])
        sizes = [(i["rgb"].shape[1], i["rgb"].shape[0]) for i in self.instances]
        offs = np.concatenate([[0], np.cumsum([w * h for w, h in sizes])[:-1]]).astype(np.uint32)
        flat = dr.concat([i["owner"].params["data"].array for i in self.instances])
        k = dr.arange(mi.UInt32, dr.width(flat) // 3) * 3
        rgb = mi.Color3f(*(spec.clamp_keep_grad(dr.gather(mi.Float, flat, k + c), 0.0) for c in range(3)))
        coeffs, sc = spec.rgb_unbounded(rgb)
        self.coeffs, self.tscale = mi.Array3f(coeffs), mi.Float(sc)
        self.size = mi.Array2u([w for w, _ in sizes], [h for _, h in sizes])
        self.tex_off = mi.UInt32(offs)
        self.scale = param_table([i["owner"].params["scale"] for i in self.instances])
        # Rotation rows (world -> local is R^T: local_k = sum_m R[m, k] d_m).
        self.rot = [mi.Float([i["rot"][m, k] for i in self.instances]) for m in range(3) for k in range(3)]
        self.max_w = max(w for w, _ in sizes)
        self.max_h = max(h for _, h in sizes)
        self.single = len(self.instances) == 1
        dr.eval(self.coeffs, self.tscale)

    def build(self, scene) -> None:
        self.center, self.radius = bounding_sphere(scene)
        self._build_texels()
        margs, conds, pdfs, self._power = [], [], [], []
        for inst in self.instances:
            m, c, p, pw = self._distribution(inst)
            margs.append(m), conds.append(c), pdfs.append(p), self._power.append(pw)
        moff = np.concatenate([[0], np.cumsum([len(m) for m in margs])[:-1]]).astype(np.uint32)
        coff = np.concatenate([[0], np.cumsum([len(c) for c in conds])[:-1]]).astype(np.uint32)
        self.marg = mi.Float(np.concatenate(margs).astype(np.float32))
        self.cond = mi.Float(np.concatenate(conds).astype(np.float32))
        self.cell_pdf = mi.Float(np.concatenate(pdfs).astype(np.float32))
        self.marg_off, self.cond_off = mi.UInt32(moff), mi.UInt32(coff)
        dr.eval(self.marg, self.cond, self.cell_pdf)

    @staticmethod
    def _distribution(inst):
        """(marginal CDF over the H-1 cell rows, per-row conditional CDFs, per-cell
        solid-angle density, power factor) for one image."""
        img = inst["rgb"]
        H, W = img.shape[:2]
        lum = _luminance(img)
        if inst["mis_compensation"]:
            # Karlik et al. 2019, as Mitsuba's option: subtract the mean luminance.
            mean, lo = float(lum.mean()), float(lum.min())
            if mean - lo > 0.01 * mean:
                lum = np.maximum(lum - mean, 0.0)
        # Mean of the bilinear luminance over each cell: columns are texel-centred
        # (weights 1/8, 3/4, 1/8 of the neighbours), rows lie between texel rows.
        lu = 0.125 * np.roll(lum, 1, axis=1) + 0.75 * lum + 0.125 * np.roll(lum, -1, axis=1)
        cell = 0.5 * (lu[:-1] + lu[1:])
        cos_t = np.cos(np.arange(H) * (math.pi / (H - 1)))
        omega = (2.0 * math.pi / W) * (cos_t[:-1] - cos_t[1:])          # (H-1,)
        P = cell * omega[:, None]
        if not P.sum() > 0:
            P = np.broadcast_to(omega[:, None], cell.shape).copy()
        P /= P.sum()
        row = P.sum(axis=1)
        marg = np.cumsum(row)
        marg /= marg[-1]
        cond = np.where(row[:, None] > 0, P / np.where(row > 0, row, 1.0)[:, None], 1.0 / W)
        cond = np.cumsum(cond, axis=1)
        cond /= cond[:, -1:]
        pdf = P / omega[:, None]
        # Power factor: integral of the luminance over the sphere (times pi r^2 later).
        lum_true = _luminance(img)
        lu_t = 0.125 * np.roll(lum_true, 1, axis=1) + 0.75 * lum_true + 0.125 * np.roll(lum_true, -1, axis=1)
        power = float((0.5 * (lu_t[:-1] + lu_t[1:]) * omega[:, None]).sum()) * inst["scale"]
        return marg, cond.reshape(-1), pdf.reshape(-1), power

    def power(self, i: int, scene) -> float:
        _, r = bounding_sphere(scene)
        if not hasattr(self, "_power"):
            self.build(scene)
        return math.pi * r * r * self._power[i]

    # -- kernels --------------------------------------------------------------------------
    def _R(self, idx, active):
        if self.single:
            return [float(v) for v in self.instances[0]["rot"].reshape(-1)]
        return [dr.gather(mi.Float, a, idx, active) for a in self.rot]

    def _to_local(self, idx, d, active):
        R = self._R(idx, active)
        v = mi.Vector3f(R[0] * d.x + R[3] * d.y + R[6] * d.z,
                        R[1] * d.x + R[4] * d.y + R[7] * d.z,
                        R[2] * d.x + R[5] * d.y + R[8] * d.z)
        return dr.normalize(v)

    def _to_world(self, idx, v, active):
        R = self._R(idx, active)
        return dr.normalize(mi.Vector3f(R[0] * v.x + R[1] * v.y + R[2] * v.z,
                                        R[3] * v.x + R[4] * v.y + R[5] * v.z,
                                        R[6] * v.x + R[7] * v.y + R[8] * v.z))

    def _dims(self, idx, active):
        if self.single:
            w, h = self.instances[0]["rgb"].shape[1], self.instances[0]["rgb"].shape[0]
            return mi.UInt32(w), mi.UInt32(h)
        s = dr.gather(mi.Array2u, self.size, idx, active)
        return s.x, s.y

    def _lookup(self, idx, uv, lam, active):
        """Radiance at image coordinates ``uv`` (Mitsuba's envmap interpolation)."""
        W, H = self._dims(idx, active)
        off = mi.UInt32(0) if self.single else dr.gather(mi.UInt32, self.tex_off, idx, active)
        Wf, Hf = mi.Float(W), mi.Float(H)
        u = uv.x - dr.floor(uv.x)
        v = dr.clip(uv.y, 0.0, 1.0)
        x = dr.fma(u, Wf, -0.5)
        x0 = dr.floor(x)
        wx = x - x0
        i0 = mi.Int32(x0)
        i0 = mi.UInt32(dr.select(i0 < 0, i0 + mi.Int32(W), i0))
        i1 = dr.select(i0 + 1 >= W, 0, i0 + 1)
        y = v * (Hf - 1.0)
        j0 = dr.minimum(mi.UInt32(y), H - 2)
        wy = y - mi.Float(j0)
        r0, r1 = off + j0 * W, off + (j0 + 1) * W

        def texel(k):
            return (spec.sigmoid_polynomial(dr.gather(mi.Array3f, self.coeffs, k, active), lam),
                    dr.gather(mi.Float, self.tscale, k, active))

        (s00, f00), (s10, f10) = texel(r0 + i0), texel(r0 + i1)
        (s01, f01), (s11, f11) = texel(r1 + i0), texel(r1 + i1)
        s = dr.lerp(dr.lerp(s00, s10, wx), dr.lerp(s01, s11, wx), wy)
        f = dr.lerp(dr.lerp(f00, f10, wx), dr.lerp(f01, f11, wx), wy)
        sc = dr.gather(mi.Float, self.scale, idx if not self.single else mi.UInt32(0), active)
        return dr.select(active, s * (f * sc) * spec.d65(lam), 0.0)

    def Le(self, idx, d, wl, active):
        return self._lookup(idx, _dir_to_uv(self._to_local(idx, d, active)), wl.lambda_, active)

    def pdf_Le_dir(self, idx, d, active):
        uv = _dir_to_uv(self._to_local(idx, d, active))
        W, H = self._dims(idx, active)
        i = dr.minimum(mi.UInt32(uv.x * mi.Float(W)), W - 1)
        k = dr.minimum(mi.UInt32(uv.y * mi.Float(H - 1)), H - 2)
        coff = mi.UInt32(0) if self.single else dr.gather(mi.UInt32, self.cond_off, idx, active)
        return dr.select(active, dr.gather(mi.Float, self.cell_pdf, coff + k * W + i, active), 0.0)

    @staticmethod
    def _search(n_max: int, n, cdf, off, x, active):
        """First index ``i < n`` with ``cdf[off + i] > x`` (cdf nondecreasing, last 1) and
        the position of ``x`` inside that entry's interval, in [0, 1)."""
        i = dr.binary_search(0, n_max - 1, lambda k: (k < n) & (dr.gather(mi.Float, cdf, off + dr.minimum(k, n - 1),
                                                                              active) <= x))
        i = dr.minimum(i, n - 1)
        hi = dr.gather(mi.Float, cdf, off + i, active)
        lo = dr.select(i > 0, dr.gather(mi.Float, cdf, off + dr.maximum(i, 1) - 1, active & (i > 0)), 0.0)
        t = dr.select(hi > lo, (x - lo) / (hi - lo), 0.5)
        return i, dr.clip(t, 0.0, 0.99999994)

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        W, H = self._dims(idx, active)
        moff = mi.UInt32(0) if self.single else dr.gather(mi.UInt32, self.marg_off, idx, active)
        coff = mi.UInt32(0) if self.single else dr.gather(mi.UInt32, self.cond_off, idx, active)
        k, tv = self._search(self.max_h - 1, H - 1, self.marg, moff, u.y, active)
        i, tu = self._search(self.max_w, W, self.cond, coff + k * W, u.x, active)
        pdf = dr.gather(mi.Float, self.cell_pdf, coff + k * W + i, active)
        # Uniform in phi and in cos(theta) inside the cell.
        dtheta = dr.pi / mi.Float(H - 1)
        c0 = dr.cos(mi.Float(k) * dtheta)
        c1 = dr.cos(mi.Float(k + 1) * dtheta)
        cos_t = dr.lerp(c0, c1, tv)
        sin_t = dr.safe_sqrt(1.0 - cos_t * cos_t)
        uu = (mi.Float(i) + tu) / mi.Float(W)
        sp, cp = dr.sincos(dr.two_pi * uu)
        local = mi.Vector3f(sp * sin_t, cos_t, -cp * sin_t)
        wi = self._to_world(idx, local, active)
        ok = active & (pdf > 0)
        uv = mi.Point2f(uu, dr.safe_acos(cos_t) * dr.inv_pi)
        L = self._lookup(idx, uv, wl.lambda_, ok)
        return LightSample(dr.select(ok, L, 0.0), wi, dr.select(ok, pdf, 0.0),
                           _far_point(ref.p, wi, self.center, self.radius), mi.Bool(False))


# --------------------------------------------------------------------------- portal

@LIGHT_TYPES.register("portalenvmap")
class PortalEnvMapLight(EnvMapLight):
    """``portalenvmap`` (pbrt-v4's ``portal``): an environment map seen through a rectangular
    portal, sampled within the portal's solid angle.

    ========  =========  ========  ======================================================
    name      type       default   meaning
    ========  =========  ========  ======================================================
    portal    array      -         the rectangle's corners p0, p1, p2, p3 (4x3, required)
    filename  string     -         the image (or bitmap, data), as envmap's
    scale     float      1         factor on the radiance
    to_world  transform  identity  rotation of the map
    ========  =========  ========  ======================================================
    """

    name = "portalenvmap"
    needs_ref = True   # Le and pdf_Le_dir depend on the ray origin
    emits_rays = False  # no sample_Le: its emission depends on the ray origin

    def add(self, loader, props, shape_index=None) -> int:
        inst = self._parse(loader, props)
        raw = props.raw("portal")
        try:
            P = np.asarray(raw, dtype=np.float64).reshape(4, 3)
        except (TypeError, ValueError):
            raise props.error("portal", f"expected 4 points (a 4x3 array), got {raw!r}") from None
        if not np.all(np.isfinite(P)):
            raise props.error("portal", "non-finite portal coordinates")
        e_x, e_y = P[3] - P[0], P[1] - P[0]
        lx, ly = np.linalg.norm(e_x), np.linalg.norm(e_y)
        if lx <= 0 or ly <= 0:
            raise props.error("portal", "degenerate portal")
        x, y = e_x / lx, e_y / ly
        d12, d32 = P[2] - P[1], P[2] - P[3]
        ok = (abs(np.dot(x, y)) < 1e-3 and np.allclose(d12, e_x, atol=1e-3 * max(lx, ly))
              and np.allclose(d32, e_y, atol=1e-3 * max(lx, ly)))
        if not ok:
            raise props.error("portal", "the portal must be a rectangle p0, p1, p2, p3 (p1 - p0 and "
                                        "p3 - p0 perpendicular, p2 = p1 + p3 - p0)")
        inst["portal"] = (P[0], x, y, np.cross(x, y), lx, ly)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self, scene) -> None:
        self.center, self.radius = bounding_sphere(scene)
        self._build_texels()
        fs, sats, rows, self._power, ns = [], [], [], [], []
        for inst in self.instances:
            f, sat, rp, pw = self._grid(inst)
            fs.append(f), sats.append(sat), rows.append(rp), self._power.append(pw), ns.append(f.shape[0])
        self.n = mi.UInt32(ns)
        self.max_n = max(ns)
        self.f = mi.Float(np.concatenate([f.reshape(-1) for f in fs]).astype(np.float32))
        self.sat = mi.Float64(np.concatenate([s.reshape(-1) for s in sats]))
        self.rowsum = mi.Float64(np.concatenate([r.reshape(-1) for r in rows]))
        self.f_off = mi.UInt32(np.concatenate([[0], np.cumsum([f.size for f in fs])[:-1]]).astype(np.uint32))
        self.sat_off = mi.UInt32(np.concatenate([[0], np.cumsum([s.size for s in sats])[:-1]]).astype(np.uint32))
        self.row_off = mi.UInt32(np.concatenate([[0], np.cumsum([r.size for r in rows])[:-1]]).astype(np.uint32))
        pf = [inst["portal"] for inst in self.instances]
        self.frame = [mi.Float([p[a][k] for p in pf]) for a in range(4) for k in range(3)]
        self.extent = mi.Array2f([p[4] for p in pf], [p[5] for p in pf])
        dr.eval(self.f, self.sat, self.rowsum)

    def _grid(self, inst):
        """Piecewise-constant density over the rectified (a, b) grid: cell values, the
        float64 summed-area table ((N+1)^2: integral over [0, i/N] x [0, j/N]), per-row
        prefix integrals (N x (N+1)), and the power factor."""
        img = inst["rgb"]
        H = img.shape[0]
        lum = _luminance(img)
        n = int(np.clip(H, 64, 1024))
        ss = 4 if n <= 256 else 2
        g = (np.arange(n * ss) + 0.5) / (n * ss)
        a, b = np.meshgrid(g, g)                               # a along columns, b along rows
        s, t = np.tan(math.pi * (a - 0.5)), np.tan(math.pi * (b - 0.5))
        R = np.sqrt(1.0 + s * s + t * t)
        jac = math.pi ** 2 * (1.0 + s * s) * (1.0 + t * t) / R ** 3
        p0, x, y, z, lx, ly = inst["portal"]
        w = (s[..., None] * x + t[..., None] * y + z) / R[..., None]
        loc = w @ inst["rot"]                                  # R^T w, row-vector form
        uu = np.arctan2(loc[..., 0], -loc[..., 2]) / (2 * math.pi)
        vv = np.arccos(np.clip(loc[..., 1], -1.0, 1.0)) / math.pi
        L = _lum_bilinear_np(lum, uu, vv)
        f = (L * jac).reshape(n, ss, n, ss).mean(axis=(1, 3))
        cos_z = (L * jac / R).reshape(n, ss, n, ss).mean(axis=(1, 3))   # L cos(theta) d omega / d(a,b)
        if not f.sum() > 0:
            f = jac.reshape(n, ss, n, ss).mean(axis=(1, 3))
        sat = np.zeros((n + 1, n + 1))
        sat[1:, 1:] = np.cumsum(np.cumsum(f, axis=0), axis=1) / (n * n)
        rp = np.zeros((n, n + 1))
        rp[:, 1:] = np.cumsum(f, axis=1) / n
        power = lx * ly * float(cos_z.sum()) / (n * n) * inst["scale"]
        return f, sat, rp, power

    def power(self, i: int, scene) -> float:
        if not hasattr(self, "_power"):
            self.build(scene)
        return self._power[i]

    # -- kernels --------------------------------------------------------------------------
    def _frame(self, idx, active):
        g = [dr.gather(mi.Float, a, idx, active) for a in self.frame]
        o, x, y, z = (mi.Vector3f(g[3 * k], g[3 * k + 1], g[3 * k + 2]) for k in range(4))
        e = dr.gather(mi.Array2f, self.extent, idx, active)
        return o, x, y, z, e

    def _window(self, idx, p, active):
        """((a0, b0), (a1, b1)) of the portal seen from ``p``, and whether ``p`` is behind it."""
        o, x, y, z, e = self._frame(idx, active)
        q = p - o
        qx, qy, qz = dr.dot(q, x), dr.dot(q, y), dr.dot(q, z)
        h = -qz
        a0 = dr.atan2(-qx, h) * dr.inv_pi + 0.5
        a1 = dr.atan2(e.x - qx, h) * dr.inv_pi + 0.5
        b0 = dr.atan2(-qy, h) * dr.inv_pi + 0.5
        b1 = dr.atan2(e.y - qy, h) * dr.inv_pi + 0.5
        return mi.Point2f(a0, b0), mi.Point2f(a1, b1), active & (h > 0)

    def _dir_ab(self, idx, d, active):
        _, x, y, z, _ = self._frame(idx, active)
        wx, wy, wz = dr.dot(d, x), dr.dot(d, y), dr.dot(d, z)
        ab = mi.Point2f(dr.atan2(wx, wz) * dr.inv_pi + 0.5, dr.atan2(wy, wz) * dr.inv_pi + 0.5)
        return ab, wz > 0

    @staticmethod
    def _jacobian(ab):
        """d omega / d(a, b) at rectified coordinates ``ab``."""
        s, t = dr.tan(dr.pi * (ab.x - 0.5)), dr.tan(dr.pi * (ab.y - 0.5))
        r2 = 1.0 + s * s + t * t
        return (dr.pi * dr.pi) * (1.0 + s * s) * (1.0 + t * t) / (r2 * dr.sqrt(r2))

    def _offsets(self, idx, active):
        if len(self.instances) == 1:
            return mi.UInt32(self.max_n), mi.UInt32(0), mi.UInt32(0), mi.UInt32(0)
        return (dr.gather(mi.UInt32, self.n, idx, active), dr.gather(mi.UInt32, self.f_off, idx, active),
                dr.gather(mi.UInt32, self.sat_off, idx, active), dr.gather(mi.UInt32, self.row_off, idx, active))

    def _I(self, n, soff, a, b, active):
        """Integral of the density over [0, a] x [0, b] (bilinear in the SAT; float64)."""
        nf = mi.Float64(n)
        xa, yb = a * nf, b * nf
        i0 = dr.minimum(mi.UInt32(xa), n - 1)
        j0 = dr.minimum(mi.UInt32(yb), n - 1)
        tx, ty = xa - mi.Float64(i0), yb - mi.Float64(j0)
        k = soff + j0 * (n + 1) + i0
        s00 = dr.gather(mi.Float64, self.sat, k, active)
        s10 = dr.gather(mi.Float64, self.sat, k + 1, active)
        s01 = dr.gather(mi.Float64, self.sat, k + n + 1, active)
        s11 = dr.gather(mi.Float64, self.sat, k + n + 2, active)
        return dr.lerp(dr.lerp(s00, s10, tx), dr.lerp(s01, s11, tx), ty)

    def _row(self, n, roff, r, a, active):
        """Integral of row ``r`` of the density over [0, a] (float64)."""
        xa = a * mi.Float64(n)
        i0 = dr.minimum(mi.UInt32(xa), n - 1)
        k = roff + r * (n + 1) + i0
        v0 = dr.gather(mi.Float64, self.rowsum, k, active)
        v1 = dr.gather(mi.Float64, self.rowsum, k + 1, active)
        return dr.lerp(v0, v1, xa - mi.Float64(i0))

    def _invert(self, n, F, lo_w, hi_w, target):
        """Invert the nondecreasing, piecewise-linear (between grid lines j/n) function F on
        [lo_w, hi_w] at ``target``: (position, index of the grid cell it falls in)."""
        nf = mi.Float64(n)

        def at(j):
            return dr.clip(mi.Float64(j) / nf, lo_w, hi_w)

        k = dr.binary_search(0, self.max_n, lambda j: F(at(j)) <= target)
        k = dr.clip(k, 1, n)
        lo, hi = at(k - 1), at(k)
        f_lo, f_hi = F(lo), F(hi)
        t = dr.select(f_hi > f_lo, (target - f_lo) / (f_hi - f_lo), 0.5)
        x = dr.lerp(lo, hi, dr.clip(t, 0.0, 1.0))
        return x, k - 1

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        n, foff, soff, roff = self._offsets(idx, active)
        w0, w1, active = self._window(idx, ref.p, active)
        a0, a1 = mi.Float64(w0.x), mi.Float64(w1.x)
        b0, b1 = mi.Float64(w0.y), mi.Float64(w1.y)
        I_a0b0, I_a1b0 = self._I(n, soff, a0, b0, active), self._I(n, soff, a1, b0, active)
        total = self._I(n, soff, a1, b1, active) - self._I(n, soff, a0, b1, active) - I_a1b0 + I_a0b0
        active &= total > 0

        def G(b):  # marginal: integral over [a0, a1] x [b0, b]
            return self._I(n, soff, a1, b, active) - self._I(n, soff, a0, b, active) - I_a1b0 + I_a0b0

        b, r = self._invert(n, G, b0, b1, mi.Float64(u.y) * total)
        base = self._row(n, roff, r, a0, active)

        def Hr(a):  # conditional: integral of row r over [a0, a]
            return self._row(n, roff, r, a, active) - base

        a, c = self._invert(n, Hr, a0, a1, mi.Float64(u.x) * Hr(a1))
        fcell = dr.gather(mi.Float, self.f, foff + r * n + c, active)
        ab = mi.Point2f(mi.Float(a), mi.Float(b))
        pdf_ab = fcell / mi.Float(total)
        _, x, y, z, _ = self._frame(idx, active)
        s, t = dr.tan(dr.pi * (ab.x - 0.5)), dr.tan(dr.pi * (ab.y - 0.5))
        wi = dr.normalize(s * x + t * y + z)
        pdf = pdf_ab / self._jacobian(ab)
        ok = active & (fcell > 0) & dr.isfinite(pdf) & (pdf > 0)
        L = EnvMapLight.Le(self, idx, wi, wl, ok)
        return LightSample(dr.select(ok, L, 0.0), wi, dr.select(ok, pdf, 0.0),
                           _far_point(ref.p, wi, self.center, self.radius), mi.Bool(False))

    def _through(self, idx, d, ref_p, active):
        w0, w1, active = self._window(idx, ref_p, active)
        ab, front = self._dir_ab(idx, d, active)
        inside = active & front & (ab.x >= w0.x) & (ab.x <= w1.x) & (ab.y >= w0.y) & (ab.y <= w1.y)
        return inside, ab, w0, w1

    def Le(self, idx, d, wl, active, ref_p=None):
        if ref_p is None:
            raise ValueError("portalenvmap.Le needs the ray origin (ref_p)")
        inside, _, _, _ = self._through(idx, d, ref_p, active)
        return EnvMapLight.Le(self, idx, d, wl, inside)

    def pdf_Le_dir(self, idx, d, active, ref_p=None):
        if ref_p is None:
            raise ValueError("portalenvmap.pdf_Le_dir needs the ray origin (ref_p)")
        inside, ab, w0, w1 = self._through(idx, d, ref_p, active)
        n, foff, soff, roff = self._offsets(idx, inside)
        a0, a1 = mi.Float64(w0.x), mi.Float64(w1.x)
        b0, b1 = mi.Float64(w0.y), mi.Float64(w1.y)
        total = (self._I(n, soff, a1, b1, inside) - self._I(n, soff, a0, b1, inside)
                 - self._I(n, soff, a1, b0, inside) + self._I(n, soff, a0, b0, inside))
        nf = mi.Float(n)
        i = dr.minimum(mi.UInt32(ab.x * nf), n - 1)
        j = dr.minimum(mi.UInt32(ab.y * nf), n - 1)
        fcell = dr.gather(mi.Float, self.f, foff + j * n + i, inside)
        pdf = fcell / mi.Float(total) / self._jacobian(ab)
        return dr.select(inside & (total > 0) & dr.isfinite(pdf), pdf, 0.0)
