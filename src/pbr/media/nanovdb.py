"""NanoVDB (``.nvdb``) float grids for pbrt-v4's ``nanovdb`` medium, read with NVIDIA
Warp (``pip install warp-lang``; an optional dependency, imported only here, on the CPU).

NanoVDB's conventions, as pbrt-v4's ``NanoVDBMedium`` uses them:

- a grid maps integer index coordinates ``ijk`` to medium space by its map,
  ``p = M ijk + t``; the value of voxel ``ijk`` belongs to the point ``p(ijk)``, and a
  lookup at ``p`` interpolates trilinearly (in index space) between the 8 voxels around
  it; voxels that are not stored give the grid's background (0 for a fog volume);
- the medium fills the grid's world bounding box as stored in the file (``worldBBox`` of
  the grid's header; NanoVDB writes the index box of the active voxels, ``min .. max +
  1``, mapped to medium space), or the union of the density and temperature grids' boxes.

pbr's grid media are dense: :func:`dense_samples` looks up every voxel the trilinear
interpolation can reach inside the medium's box (the stored voxels, tiles or background)
and returns them with the affine map from the box's unit cube to array indices, so that
pbr's trilinear lookup reproduces NanoVDB's exactly. Only maps whose linear part is
diagonal (axis-aligned voxels, any size per axis) are supported.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass

import numpy as np

from ..plugins.props import SceneError

# GridData (NanoVDB's grid header): gridClass (uint32) and worldBBox (6 doubles) offsets.
_WORLD_BBOX = 560
_GRID_CLASS = 632
_CLASS_UNKNOWN, _CLASS_FOG = 0, 2

MAX_DENSE_VOXELS = 1 << 30
"""The largest dense grid (voxels) pbr builds from a NanoVDB grid (4 GiB of float32)."""


@dataclass
class NanoGrid:
    """One float grid of a ``.nvdb`` file: its name, the diagonal of its index-to-medium
    map (voxel size per axis), the map's translation, its stored world bounding box
    (2, 3), and the Warp volume that looks values up."""

    name: str
    voxel: np.ndarray
    translation: np.ndarray
    world_bbox: np.ndarray
    volume: object


def _warp(path: str, where: str):
    try:
        from . import _nanovdb_warp
    except ImportError as e:
        raise SceneError(f"{where}: reading the NanoVDB file {path!r} needs NVIDIA Warp, which is not "
                         f"installed ({e}): pip install warp-lang") from None
    return _nanovdb_warp


def read_nvdb(path: str, names, where: str) -> tuple[dict, list]:
    """The float grids called ``names`` in the NanoVDB file ``path`` (name -> :class:`NanoGrid`,
    or None where the file has no such grid), and the names of all its grids.
    ``where``: the key path for errors."""
    if not os.path.exists(path):
        raise SceneError(f"{where}: NanoVDB file not found: {path!r}")
    wpn = _warp(path, where)
    with open(path, "rb") as f:
        data = f.read()
    try:
        volumes = wpn.load_grids(data)
    except Exception as e:          # Warp raises RuntimeError on bad signatures, codecs, layouts
        raise SceneError(f"{where}: {path!r} is not a NanoVDB file Warp can read: {e}") from None
    found, every = {}, []
    for v in volumes:
        info = v.get_grid_info()
        every.append(info.name)
        if info.name in names and info.name not in found:
            found[info.name] = (v, info)
    out = {}
    for name in names:
        if name not in found:
            out[name] = None
            continue
        v, info = found[name]
        head = wpn.grid_bytes(v)
        cls = struct.unpack_from("<I", head, _GRID_CLASS)[0]
        if info.type_str != "float":
            raise SceneError(f"{where}: {path!r}: grid {name!r} holds {info.type_str!r} values (a nanovdb "
                             "medium needs a float grid)")
        if cls not in (_CLASS_UNKNOWN, _CLASS_FOG):
            raise SceneError(f"{where}: {path!r}: grid {name!r} is not a fog volume (NanoVDB grid class {cls}; "
                             "pbrt-v4 refuses level sets and other classes too)")
        m = np.array(info.transform_matrix, np.float64).reshape(3, 3)
        d = np.diag(m).copy()
        if np.any(d == 0) or np.any(np.abs(m - np.diag(d)) > 1e-6 * np.abs(d).max()):
            raise SceneError(f"{where}: {path!r}: grid {name!r} has a rotated or sheared index map "
                             f"{m.tolist()} (pbr reads grids with axis-aligned voxels only)")
        bbox = np.array(struct.unpack_from("<6d", head, _WORLD_BBOX), np.float64).reshape(2, 3)
        if not np.all(np.isfinite(bbox)) or np.any(bbox[1] <= bbox[0]):
            raise SceneError(f"{where}: {path!r}: grid {name!r} has an empty world bounding box {bbox.tolist()}")
        out[name] = NanoGrid(name, d, np.array(info.translation, np.float64), bbox, v)
    return out, every


def dense_samples(grid: NanoGrid, bounds: np.ndarray, where: str, nonnegative: bool = True):
    """The voxels of ``grid`` that trilinear lookups inside ``bounds`` (2, 3; medium space)
    reach, as a float32 (nz, ny, nx) array, and the per-axis affine map (scale, offset;
    (x, y, z)) from the unit cube of ``bounds`` to (fractional) array indices: a point
    ``u`` of the cube is at array index ``u * scale + offset``, voxel k's value at k."""
    ia = (bounds[0] - grid.translation) / grid.voxel
    ib = (bounds[1] - grid.translation) / grid.voxel
    lo = np.floor(np.minimum(ia, ib)).astype(np.int64)
    hi = np.floor(np.maximum(ia, ib)).astype(np.int64) + 1
    shape = hi - lo + 1
    if np.prod(shape.astype(np.float64)) > MAX_DENSE_VOXELS:
        raise SceneError(f"{where}: grid {grid.name!r} spans {shape.tolist()} voxels over the medium's bounds; "
                         f"pbr's grid media are dense and take at most {MAX_DENSE_VOXELS} voxels")
    values = _warp("", where).lookup_box(grid.volume, lo, shape)
    if not np.all(np.isfinite(values)) or (nonnegative and np.any(values < 0)):
        raise SceneError(f"{where}: grid {grid.name!r} has {'negative or ' if nonnegative else ''}"
                         "non-finite values")
    scale = (bounds[1] - bounds[0]) / grid.voxel
    offset = ia - lo
    return values, scale, offset
