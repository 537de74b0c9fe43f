"""Voxel grids (Mitsuba's ``gridvolume``): ``.vol`` files, the ``gridvolume`` parameters, and
trilinear lookups. Heterogeneous media read their coefficients from them
(:mod:`pbr.media`, which also builds their coarse majorant grids: :mod:`pbr.media.grid`),
the ``volume`` texture its values (:mod:`.volume`).

Grid convention (Mitsuba's ``gridvolume`` and pbrt-v4's ``SampledGrid``): an array of
shape (nz, ny, nx[, channels]) covers the unit cube of the medium's local space, voxel
``(x, y, z)`` sits at ``((x + 0.5) / nx, (y + 0.5) / ny, (z + 0.5) / nz)``, and lookups
interpolate trilinearly with clamped addressing. Outside the unit cube a medium's grid
is zero (pbrt-v4: the medium is bounded by its grid); a texture's keeps its clamped
value there (Mitsuba's ``gridvolume`` lookup with ``wrap_mode`` 'clamp'). A grid may
instead carry its own affine map from the unit cube to array indices (``u * scale +
offset`` per axis, voxel k at index k): NanoVDB grids, whose voxels sit at integer index coordinates (:mod:`pbr.media.nanovdb`).

RGB grids are stored as Mitsuba's spectral ``gridvolume`` stores them: per voxel, three
sigmoid coefficients of rgb / (2 max(rgb)) and the scale 2 max(rgb) (for albedos too).
A lookup interpolates the eight neighbouring voxels' spectra (evaluated at the sampled
wavelengths) and, separately, their scales, and multiplies the two, as Mitsuba does
(which differs from interpolating scale times spectrum where the scales vary).
"""

from __future__ import annotations

import struct

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..plugins.params import ParamOwner, check_params
from ..plugins.props import ALBEDO, NONNEGATIVE, SceneError

# ---------------------------------------------------------------------- .vol files
def read_vol(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Read a Mitsuba binary ``.vol`` grid: (data (nz, ny, nx, channels) float32, bbox
    (2, 3)). Format: 'VOL', version 3, int32 encoding (1 = float32), int32 nx, ny, nz,
    int32 channels, 6 float32 bounding box, then float32 data with x varying fastest."""
    with open(path, "rb") as f:
        head = f.read(48)
        if len(head) < 48 or head[:3] != b"VOL" or head[3] != 3:
            raise SceneError(f"{path}: not a Mitsuba .vol file (expected the 'VOL' header, version 3)")
        enc, nx, ny, nz, ch = struct.unpack("<5i", head[4:24])
        if enc != 1:
            raise SceneError(f"{path}: unsupported .vol encoding {enc} (only 1 = float32)")
        if min(nx, ny, nz) < 1 or ch not in (1, 3):
            raise SceneError(f"{path}: invalid grid {nx}x{ny}x{nz} with {ch} channels (expected 1 or 3)")
        bbox = np.array(struct.unpack("<6f", head[24:48]), np.float64).reshape(2, 3)
        n = nx * ny * nz * ch
        data = np.frombuffer(f.read(4 * n), dtype="<f4")
    if data.size != n:
        raise SceneError(f"{path}: truncated .vol file ({data.size} of {n} values)")
    return data.reshape(nz, ny, nx, ch).astype(np.float32), bbox


def write_vol(path: str, data, bbox=((0, 0, 0), (1, 1, 1))) -> None:
    """Write ``data`` (nz, ny, nx[, channels]) as a Mitsuba ``.vol`` file."""
    a = np.asarray(data, np.float32)
    if a.ndim == 3:
        a = a[..., None]
    nz, ny, nx, ch = a.shape
    with open(path, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<5i", 1, nx, ny, nz, ch))
        f.write(struct.pack("<6f", *np.asarray(bbox, np.float64).ravel()))
        f.write(a.astype("<f4").tobytes())


def as_grid(value, where: str) -> np.ndarray:
    """A numpy array (nz, ny, nx) or (nz, ny, nx, 1|3) as a float32 (nz, ny, nx, c) grid."""
    a = np.asarray(value, np.float32)
    if a.ndim == 3:
        a = a[..., None]
    if a.ndim != 4 or a.shape[3] not in (1, 3) or min(a.shape[:3]) < 1:
        raise SceneError(f"{where}: expected a grid array of shape (nz, ny, nx) or (nz, ny, nx, 3), "
                         f"got shape {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise SceneError(f"{where}: grid values must be finite and non-negative")
    return a


def load_gridvolume(loader, p) -> tuple[np.ndarray, np.ndarray]:
    """A ``gridvolume`` plugin's parameters (``p``: its :class:`Props`): (data (nz, ny, nx,
    c) float32, to_world 4x4 of the unit cube). ``use_grid_bbox`` puts the file's bounding
    box into ``to_world``; only Mitsuba's defaults of ``filter_type`` ('trilinear') and
    ``wrap_mode`` ('clamp') are supported, and RGB grids are always upsampled (no ``raw``)."""
    name = "filename" if p.has("filename") else "data" if p.has("data") else "grid"
    if p.has("filename"):
        data, bbox = read_vol(loader.resolve_path(p.string("filename"), p.key("filename")))
    elif p.has("data") or p.has("grid"):
        # 'grid': Mitsuba's form, an mi.VolumeGrid (numpy reads it as (nz, ny, nx[, c]))
        data, bbox = as_grid(np.asarray(p.raw(name)), p.key(name)), np.array([[0, 0, 0], [1, 1, 1.0]])
    else:
        raise p.error(None, "a gridvolume needs 'filename', 'grid' (an mi.VolumeGrid) or 'data' (an array)")
    if not np.all(np.isfinite(data)) or np.any(data < 0):
        raise p.error(name, "grid values must be finite and >= 0")
    p.string("filter_type", "trilinear", choices=("trilinear",))
    p.string("wrap_mode", "clamp", choices=("clamp",))
    to_world = p.transform("to_world")
    if p.bool("use_grid_bbox", False):
        lo, hi = bbox[0], bbox[1]
        box = np.diag([*(hi - lo), 1.0])
        box[:3, 3] = lo
        to_world = to_world @ box
    if p.has("raw") and p.bool("raw"):
        raise p.error("raw", "raw=true grids are not supported (RGB grids are upsampled to spectra)")
    p.mark("accel", "max_value")
    p.finish()
    return data, to_world


# ---------------------------------------------------------------------- grid tables
class GridTable:
    """All voxel grids of a scene in one flat array (``data``) with per-grid offset,
    resolution and channel count (1: scalar; 4: sigmoid coefficients + scale)."""

    def __init__(self):
        self.grids: list[tuple[np.ndarray, str]] = []
        self.owners: list = []
        self.affine: list = []

    def add(self, grid: np.ndarray, form: str, path: str | None = None, affine=None) -> int:
        """Add a (nz, ny, nx, c) grid; RGB grids are upsampled in ``form`` ('albedo' or
        'unbounded'). A single-channel grid given a ``path`` is the differentiable scene
        parameter ``<path>.data`` (Mitsuba's gridvolume key). ``affine``: (scale, offset),
        each (x, y, z), mapping the unit cube to array indices (default: the grid spans
        the cube, voxel centres at (k + 0.5) / n). Returns the grid index."""
        self.grids.append((grid, form))
        self.affine.append(affine)
        if path is not None and grid.shape[3] == 1:
            valid = {"data": ALBEDO if form == "albedo" else NONNEGATIVE}
            owner = ParamOwner(path, valid=valid, data=mi.TensorXf(grid))
            check_params(owner, path=path)
            self.owners.append((len(self.grids) - 1, owner))
        return len(self.grids) - 1

    def _sync(self) -> dict:
        """Copy the current parameter values into the numpy grids (majorants and bounds
        are built from them, detached); returns grid index -> differentiable flat data."""
        ad = {}
        for gid, owner in self.owners:
            data = owner.params["data"]
            g, form = self.grids[gid]
            if tuple(data.shape) != g.shape:
                raise ValueError(f"{owner.path}.data: shape {tuple(data.shape)} must stay {g.shape}")
            self.grids[gid] = (np.maximum(np.asarray(dr.detach(data), np.float32), 0.0), form)
            ad[gid] = spec.clamp_keep_grad(data.array, 0.0)   # an empty voxel keeps its derivative
        return ad

    def max_bound(self, gid: int) -> np.ndarray:
        """Per-voxel upper bound of the grid's value over all wavelengths (nz, ny, nx)."""
        g, form = self.grids[gid]
        if g.shape[3] == 1:
            return g[..., 0]
        # A sigmoid spectrum lies in [0, 1]: a voxel's value is at most its scale
        # (2 max(rgb)); the interpolated spectrum times the interpolated scale is at most
        # the largest scale among the voxels interpolated (cell_maxima takes it).
        return 2.0 * g.max(axis=3)

    def build(self) -> None:
        ad = self._sync()
        flat, offs, res, chans = [], [], [], []
        off = 0
        for gid, (g, form) in enumerate(self.grids):
            nz, ny, nx, c = g.shape
            if c == 3:
                g = _rgb_voxels(g.reshape(-1, 3), form).reshape(nz, ny, nx, 4)
                c = 4
            flat.append(ad[gid] if gid in ad else mi.Float(g.ravel().astype(np.float32)))
            offs.append(off)
            res.append((nx, ny, nz))
            chans.append(c)
            off += g.size
        self.has_rgb = 4 in chans
        self.has_affine = any(a is not None for a in self.affine)
        if self.has_affine:
            aff = [a if a is not None else (np.array(r, np.float64), np.full(3, -0.5))
                   for a, r in zip(self.affine, res)]
            self.aff_scale, self.aff_offset = (
                mi.Vector3f(*(np.array([a[j][k] for a in aff], np.float32) for k in range(3))) for j in (0, 1))
        self.data = dr.concat(flat) if len(flat) > 1 else (flat[0] if flat else mi.Float(0.0))
        self.offset = mi.UInt32(offs or [0])
        r = np.array(res or [(1, 1, 1)], np.int64)
        self.res = mi.Vector3i(r[:, 0].tolist(), r[:, 1].tolist(), r[:, 2].tolist())
        self.channels = mi.UInt32(chans or [1])

    def lookup(self, gid, p: mi.Point3f, wl_lambda: mi.Spectrum, active, bounded: bool = True) -> mi.Spectrum:
        """Trilinear value of grid ``gid`` at local point ``p`` (unit cube), per
        wavelength; zero outside the cube if ``bounded`` (a medium), else the clamped
        value (a texture)."""
        inside = active & dr.all((p >= 0.0) & (p <= 1.0)) if bounded else mi.Bool(active)
        res = dr.gather(mi.Vector3i, self.res, gid, inside)
        off = dr.gather(mi.UInt32, self.offset, gid, inside)
        if self.has_affine:
            x = p * dr.gather(mi.Vector3f, self.aff_scale, gid, inside) + dr.gather(mi.Vector3f, self.aff_offset,
                                                                                   gid, inside)
        else:
            x = p * mi.Vector3f(res) - 0.5
        x0 = dr.floor(x)
        f = x - x0
        i0 = mi.Vector3i(x0)
        hi = res - 1
        lo_i = dr.clip(i0, 0, hi)
        hi_i = dr.clip(i0 + 1, 0, hi)
        if self.has_rgb:
            ch = dr.gather(mi.UInt32, self.channels, gid, inside)
            rgb = inside & (ch == 4)
        out = mi.Spectrum(0.0)
        scale = mi.Float(0.0)   # interpolated scales of RGB voxels (Mitsuba's lookup)
        for dz in (0, 1):
            iz = hi_i.z if dz else lo_i.z
            wz = f.z if dz else 1.0 - f.z
            for dy in (0, 1):
                iy = hi_i.y if dy else lo_i.y
                wy = f.y if dy else 1.0 - f.y
                for dx in (0, 1):
                    ix = hi_i.x if dx else lo_i.x
                    wx = f.x if dx else 1.0 - f.x
                    vox = mi.UInt32((iz * res.y + iy) * res.x + ix)
                    w = wx * wy * wz
                    if self.has_rgb:
                        base = off + vox * dr.select(rgb, 4, 1)
                        v = dr.gather(mi.Float, self.data, base, inside)
                        c = mi.Array3f(v, dr.gather(mi.Float, self.data, base + 1, rgb),
                                       dr.gather(mi.Float, self.data, base + 2, rgb))
                        scale += w * dr.gather(mi.Float, self.data, base + 3, rgb)
                        val = dr.select(rgb, spec.sigmoid_polynomial(c, wl_lambda), mi.Spectrum(v))
                    else:
                        val = mi.Spectrum(dr.gather(mi.Float, self.data, off + vox, inside))
                    out += w * val
        if self.has_rgb:
            out = dr.select(rgb, out * scale, out)
        return dr.select(inside, out, 0.0)


def _rgb_voxels(rgb: np.ndarray, form: str) -> np.ndarray:
    """(n, 3) RGB voxels -> (n, 4) sigmoid coefficients and scale: Mitsuba's spectral
    gridvolume normalisation, rgb / (2 max(rgb)) and 2 max(rgb), in every ``form``
    (albedo grids are clamped to [0, 1] first)."""
    rgb = rgb.astype(np.float64)
    if form != "unbounded":
        rgb = np.clip(rgb, 0.0, 1.0)
    scale = 2.0 * rgb.max(axis=1)
    norm = rgb / np.maximum(scale, 1e-8)[:, None]
    c = spec.rgb_to_coeffs(mi.Color3f(*(norm[:, k].astype(np.float32) for k in range(3))))
    coeffs = np.stack([np.asarray(c[k], np.float64) for k in range(3)], axis=1)
    return np.concatenate([coeffs, scale[:, None]], axis=1).astype(np.float32)
