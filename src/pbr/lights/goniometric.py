"""``goniometric`` (pbrt-v4): a point light whose intensity over directions is an image
(equal-area or equirectangular). Mapping and units: docs/lights.md.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..image import read_image
from .base import (LIGHT_TYPES, apply_rows, DeltaPositionLight, light_frame, LightSample, load_constant_emission,
                   luminance, mat_rows, max_value, point_bounds, power_factor)

EQUAL_AREA, EQUIRECT = 0, 1


def equal_area_sphere_to_square(d):
    """Unit direction -> [0, 1]^2 (equal-area octahedral map, pole +z). Works on Dr.Jit
    and numpy arrays."""
    if isinstance(d, np.ndarray):
        x, y, z = d[..., 0], d[..., 1], d[..., 2]
        ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
        r = np.sqrt(np.maximum(1.0 - az, 0.0))
        a, b = np.maximum(ax, ay), np.minimum(ax, ay)
        q = np.where(a > 0, b / np.where(a > 0, a, 1.0), 0.0)
        phi = np.arctan(q) * (2.0 / np.pi)
        phi = np.where(ax < ay, 1.0 - phi, phi)
        v = phi * r
        u = r - v
        u, v = np.where(z < 0, 1.0 - v, u), np.where(z < 0, 1.0 - u, v)
        u, v = np.copysign(u, x), np.copysign(v, y)
        return np.stack([0.5 * (u + 1), 0.5 * (v + 1)], axis=-1)
    x, y, z = d.x, d.y, d.z
    ax, ay, az = dr.abs(x), dr.abs(y), dr.abs(z)
    r = dr.safe_sqrt(1.0 - az)
    a, b = dr.maximum(ax, ay), dr.minimum(ax, ay)
    q = dr.select(a > 0, b / a, 0.0)
    phi = dr.atan(q) * (2.0 / math.pi)
    phi = dr.select(ax < ay, 1.0 - phi, phi)
    v = phi * r
    u = r - v
    neg = z < 0
    u, v = dr.select(neg, 1.0 - v, u), dr.select(neg, 1.0 - u, v)
    u, v = dr.copysign(u, x), dr.copysign(v, y)
    return mi.Point2f(0.5 * (u + 1), 0.5 * (v + 1))


def equal_area_square_to_sphere(uv: np.ndarray) -> np.ndarray:
    """Inverse of :func:`equal_area_sphere_to_square` (numpy; for tests and tools)."""
    u = 2.0 * uv[..., 0] - 1.0
    v = 2.0 * uv[..., 1] - 1.0
    au, av = np.abs(u), np.abs(v)
    sd = 1.0 - (au + av)          # signed distance to the diagonal
    dd = np.abs(sd)
    r = 1.0 - dd
    phi = np.where(r == 0, 1.0, (av - au) / np.where(r == 0, 1.0, r) + 1.0) * (np.pi / 4)
    z = np.copysign(1.0 - r * r, sd)
    cos_phi = np.copysign(np.cos(phi), u)
    sin_phi = np.copysign(np.sin(phi), v)
    s = r * np.sqrt(np.maximum(2.0 - r * r, 0.0))
    return np.stack([cos_phi * s, sin_phi * s, z], axis=-1)


def _load_image(loader, props) -> np.ndarray:
    if props.has("data"):
        if props.has("filename"):
            raise props.error("data", "give either 'filename' or 'data', not both")
        try:
            a = np.asarray(props.raw("data"), dtype=np.float64)
        except (TypeError, ValueError):
            raise props.error("data", "expected an (H, W) or (H, W, C) array") from None
    else:
        fname = loader.resolve_path(props.string("filename"), props.key("filename"))
        try:
            a = np.asarray(read_image(fname), dtype=np.float64)
        except Exception as e:
            raise props.error("filename", f"cannot read image {fname!r}: {e}") from None
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise props.error("data" if props.has("data") else "filename", f"expected an (H, W[, C]) image, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise props.error("data" if props.has("data") else "filename", "the image has non-finite values")
    c = a.shape[2]
    y = a[..., :3].mean(axis=2) if c >= 3 else a[..., 0]
    return np.maximum(y, 0.0)


def _solid_angle_mean(img: np.ndarray, mapping: int) -> float:
    if mapping == EQUAL_AREA:
        return float(img.mean())
    h = img.shape[0]
    # Solid angle of each row of a latitude-longitude map: cos(theta0) - cos(theta1).
    th = np.linspace(0.0, np.pi, h + 1)
    w = np.cos(th[:-1]) - np.cos(th[1:])
    return float((img.mean(axis=1) * w).sum() / 2.0)


@LIGHT_TYPES.register("goniometric")
class GoniometricLight(DeltaPositionLight):
    """``goniometric`` (pbrt-v4's): a point light whose intensity over directions is an
    image.

    ========  =========  =========  ========================================================
    name      type       default    meaning
    ========  =========  =========  ========================================================
    I         spectrum   1          intensity spectrum, times the image
    filename  string     -          the image (or data: an (H, W) array)
    mapping   string     see right  'equalarea' (square images: the default) or 'equirect'
    to_world  transform  identity   light-to-world frame (the light looks down +z)
    scale     float      1          pbrt-v4's factor on the emitted spectrum
    power     float      -          pbrt-v4's total emitted power (W): rescales the spectrum
                                    (photometric: its luminance without the RGB multiplier)
    ========  =========  =========  ========================================================
    """

    name = "goniometric"

    def add(self, loader, props, shape_index=None) -> int:
        slot = load_constant_emission(loader, props, "I")
        img = _load_image(loader, props)
        h, w = img.shape
        mapping = props.string("mapping", "equalarea" if h == w else "equirect", choices=("equalarea", "equirect"))
        mapping = EQUAL_AREA if mapping == "equalarea" else EQUIRECT
        if mapping == EQUAL_AREA and h != w:
            raise props.error("mapping", f"an equal-area image must be square, got {w}x{h}")
        m = light_frame(props)
        mean = _solid_angle_mean(img, mapping)
        factor = power_factor(props, loader.textures, slot, 4.0 * math.pi * mean)
        props.finish()
        self.instances.append({"slot": slot, "to_world": m, "factor": factor, "image": img, "mapping": mapping,
                               "mean": mean})
        return len(self.instances) - 1

    def build(self, scene) -> None:
        self._base_tables()
        I = self.instances
        self.inv_rows = mat_rows([np.linalg.inv(i["to_world"][:3, :3]) for i in I])
        sizes = [i["image"].size for i in I]
        self.offset = mi.UInt32(np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.uint32))
        self.width = mi.UInt32([i["image"].shape[1] for i in I])
        self.height = mi.UInt32([i["image"].shape[0] for i in I])
        self.data = mi.Float(np.concatenate([i["image"].ravel() for i in I]).astype(np.float32))
        self.mappings = {i["mapping"] for i in I}
        self.mapping = mi.UInt32([i["mapping"] for i in I])

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        return 4.0 * math.pi * inst["factor"] * inst["mean"] * luminance(scene.textures, inst["slot"])

    def bounds(self, i: int, scene):
        inst = self.instances[i]
        phi = 4.0 * math.pi * inst["factor"] * inst["mean"] * max_value(scene.textures, inst["slot"])
        return point_bounds(self._position(i), (0, 0, 1), phi, -1.0, 0.0)

    def _uv(self, idx, w, active):
        """Image coordinates of light-frame direction ``w`` (unit)."""
        uvs = {}
        if EQUAL_AREA in self.mappings:
            # pbrt-v4 swaps y and z: local +y is the map's pole.
            uvs[EQUAL_AREA] = equal_area_sphere_to_square(mi.Vector3f(w.x, w.z, w.y))
        if EQUIRECT in self.mappings:
            phi = dr.atan2(w.z, w.x)
            phi = dr.select(phi < 0, phi + 2 * math.pi, phi)
            uvs[EQUIRECT] = mi.Point2f(phi * (0.5 / math.pi), dr.safe_acos(w.y) * (1.0 / math.pi))
        if len(uvs) == 1:
            return next(iter(uvs.values()))
        return dr.select(dr.gather(mi.UInt32, self.mapping, idx, active) == EQUAL_AREA, uvs[EQUAL_AREA], uvs[EQUIRECT])

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        p, wi, inv_dist2, ok = self._toward(idx, ref, active)
        local = dr.normalize(apply_rows(self.inv_rows, idx, -wi, ok))
        uv = self._uv(idx, local, ok)
        w = dr.gather(mi.UInt32, self.width, idx, ok)
        h = dr.gather(mi.UInt32, self.height, idx, ok)
        px = dr.minimum(mi.UInt32(dr.maximum(uv.x * mi.Float(w), 0.0)), w - 1)
        py = dr.minimum(mi.UInt32(dr.maximum(uv.y * mi.Float(h), 0.0)), h - 1)
        y = dr.gather(mi.Float, self.data, dr.gather(mi.UInt32, self.offset, idx, ok) + py * w + px, ok)
        ok &= y > 0
        L = self._intensity(idx, wl, ok) * (y * inv_dist2)
        return LightSample(dr.select(ok, L, 0.0), wi, dr.select(ok, 1.0, 0.0), p, mi.Bool(True))
