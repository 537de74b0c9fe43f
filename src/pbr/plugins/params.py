"""Differentiable parameters owned by scene objects.

A :class:`ParamOwner` holds values that :func:`pbr.traverse` exposes under
``<key path>.<name>`` (a BSDF's IOR, an environment map's texels, a medium's voxel grid);
:func:`param_table` gathers per-instance scalars into one ``mi.Float`` table that stays
attached to them."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi


class ParamOwner:
    """Parameters owned by one scene object outside the texture table (a BSDF's IOR, an
    environment map's texels, a medium's voxel grid): ``params`` maps a name to a Dr.Jit
    value; the key is ``<path>.<name>``."""

    def __init__(self, path: str, **params):
        self.path = path.split(".", 1)[1] if path.startswith("scene.") else path
        self.params = params


def param_table(values) -> "mi.Float":
    """A ``mi.Float`` table of per-instance scalars (Python floats or width-1 Dr.Jit
    arrays), built by scatters so that parameters with gradients stay attached. While
    ``dr.freeze`` records, every entry is scattered as a literal (a table copied from a
    Python list cannot be recorded). The table has at least two entries: Dr.Jit turns a
    gather from a one-entry array into a broadcast of its value, which a recording keeps
    as the value it had when recorded."""
    values = list(values) + [0.0] * (2 - len(values))
    recording = dr.flag(dr.JitFlag.FreezingScope)
    table = (dr.zeros(mi.Float, len(values)) if recording
             else mi.Float([v if isinstance(v, (int, float)) else 0.0 for v in values]))
    for i, v in enumerate(values):
        if recording or not isinstance(v, (int, float)):
            dr.scatter(table, mi.Float(v), mi.UInt32(i))
    return table
