"""The NVIDIA Warp side of :mod:`pbr.media.nanovdb` (imported only when Warp is):
looking up a NanoVDB float grid's values over a box of index coordinates on the CPU."""

from __future__ import annotations

import contextlib

import numpy as np
import warp as wp


@contextlib.contextmanager
def _quiet():
    """Warp without its start-up banner and module-load lines (the user's log level is
    restored afterwards)."""
    level = wp.config.log_level
    wp.config.log_level = wp.LOG_ERROR
    try:
        yield
    finally:
        wp.config.log_level = level


with _quiet():
    wp.init()


@wp.kernel
def _lookup_box(volume: wp.uint64, lo: wp.vec3i, out: wp.array3d(dtype=wp.float32)):
    """out[z, y, x] = the grid's value at index (lo + (x, y, z)): the voxel's, an active
    tile's or the background (NanoVDB's accessor), with no interpolation."""
    k, j, i = wp.tid()
    out[k, j, i] = wp.volume_lookup_f(volume, lo[0] + i, lo[1] + j, lo[2] + k)


def load_grids(data: bytes) -> list:
    """Every grid of a serialised NanoVDB file (its bytes), as Warp volumes on the CPU."""
    with _quiet():
        first = wp.Volume.load_from_nvdb(data, device="cpu")
        grids = [first]
        while (nxt := grids[-1].load_next_grid()) is not None:
            grids.append(nxt)
    return grids


def grid_bytes(volume) -> np.ndarray:
    """The grid's own NanoVDB buffer (its ``GridData`` header first)."""
    return volume.array().numpy()


def lookup_box(volume, lo, shape) -> np.ndarray:
    """The grid's values at the index coordinates ``lo + (x, y, z)``, 0 <= x, y, z <
    shape (nx, ny, nz), as a float32 (nz, ny, nx) array."""
    nx, ny, nz = (int(s) for s in shape)
    with _quiet():
        out = wp.zeros((nz, ny, nx), dtype=wp.float32, device="cpu")
        wp.launch(_lookup_box, dim=(nz, ny, nx), inputs=[volume.id, wp.vec3i(*(int(v) for v in lo)), out],
                  device="cpu")
    return out.numpy()
