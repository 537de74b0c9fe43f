"""Mitsuba's ``volume`` texture: a voxel grid (a ``gridvolume``, :mod:`.grid`) read at the
surface point's world position, for surfaces without a useful uv parameterisation.

The grid covers the unit cube of its own space (the ``gridvolume``'s ``to_world`` places
it in the world); outside it the lookup clamps to the nearest voxels, as Mitsuba's
``gridvolume`` with its default ``wrap_mode`` 'clamp'. RGB voxels are upsampled as
Mitsuba's spectral ``gridvolume`` upsamples them (:mod:`.grid`), for reflectances and
emission alike (Mitsuba's volume texture has no D65 factor for emitters; neither has
pbr's). Without a surface point (lookups at plain texture coordinates) the point is
(u, v, 0).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from .grid import GridTable
from .kinds import VOLUME, key_path
from .procedural import xform_rows
from .tables import VolumeTable


class VolumeTexture:
    """A voxel grid ``data`` (nz, ny, nx, 1 or 3) looked up at ``grid_from_world`` (4x4)
    times the world point; RGB voxels are upsampled in ``form`` ('albedo': clipped to
    [0, 1] first, or 'unbounded')."""

    kind = VOLUME

    def __init__(self, path: str, data: np.ndarray, grid_from_world: np.ndarray, form: str):
        self.path = key_path(path)
        self.data, self.m = data, np.asarray(grid_from_world, np.float64)
        self.form = "albedo" if form == "albedo" else "unbounded"
        self.params = {}

    def mean_luminance(self) -> float:
        """The grid's mean value (luminance of RGB voxels), for light power estimates."""
        d = self.data.reshape(-1, self.data.shape[-1]).astype(np.float64)
        if self.form == "albedo":
            d = np.clip(d, 0.0, 1.0)
        return float(np.mean(d if d.shape[1] == 1 else spec.luminance_rgb(d.T)))


def build_table(items: list) -> VolumeTable:
    """The table of volume textures ``items`` (in table order): their grids, one
    :class:`~.grid.GridTable`, and their world-to-grid transforms."""
    grids = GridTable()
    for t in items:
        grids.add(t.data, t.form)
    grids.build()
    return VolumeTable(grids=grids, m=[mi.Float([float(t.m[r, c]) for t in items]) for r in range(3) for c in range(4)])


def evaluate(textures, i, uv, si, lam, active) -> mi.Spectrum:
    """Spectrum of volume texture ``i`` (index in its table) at ``si.p`` (or at the point
    (u, v, 0) without a surface interaction)."""
    T = textures.tables.volumes
    p = si.p if si is not None else mi.Point3f(uv.x, uv.y, 0.0)
    m = [dr.gather(mi.Float, a, i, active) for a in T.m]
    return T.grids.lookup(i, mi.Point3f(xform_rows(m, p, True)), lam, active, bounded=False)
