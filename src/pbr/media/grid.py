"""The coarse majorant grid of heterogeneous media over their voxel grids (the grids
themselves, ``.vol`` files and lookups: :mod:`pbr.textures.grid`, whose names are
re-exported here).
"""

from __future__ import annotations

import numpy as np

from ..textures.grid import GridTable, as_grid, read_vol, write_vol  # noqa: F401

MAJORANT_RES = 16
"""Cells per axis of the majorant grid (pbrt-v4 uses 16^3)."""


def cell_maxima(bound: np.ndarray, m: int = MAJORANT_RES, affine=None) -> np.ndarray:
    """Maximum of a trilinearly interpolated voxel grid over each cell of an m^3 grid
    covering the unit cube: the max over every voxel whose interpolation support
    overlaps the cell (separable: one axis at a time). ``affine``: the grid's map from
    the cube to array indices (see :meth:`GridTable.add`). Returns (m, m, m) [z, y, x]."""
    out = bound
    for axis in range(3):
        n = out.shape[axis]
        c = np.arange(m)
        sc, off = (n, -0.5) if affine is None else (affine[0][2 - axis], affine[1][2 - axis])
        a, b = c / m * sc + off, (c + 1) / m * sc + off
        lo = np.clip(np.floor(np.minimum(a, b)).astype(np.int64), 0, n - 1)
        hi = np.clip(np.floor(np.maximum(a, b)).astype(np.int64) + 1, 0, n - 1)
        moved = np.moveaxis(out, axis, 0)
        red = np.stack([moved[a:b + 1].max(axis=0) for a, b in zip(lo, hi)])
        out = np.moveaxis(red, 0, axis)
    return out
