"""Differentiable parameters owned by scene objects.

A :class:`ParamOwner` holds values that :func:`pbr.traverse` exposes under
``<key path>.<name>`` (a BSDF's IOR, an environment map's texels, a medium's voxel grid);
:func:`param_table` gathers per-instance scalars into one ``mi.Float`` table that stays
attached to them. Every parameter owner (these and the textures) may have ``valid``, a
dict name -> :class:`~pbr.plugins.props.Range` (default: any finite value), which
:func:`check_params` applies when it is loaded and on every ``params.update()``."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .props import FINITE


class ParamOwner:
    """Parameters owned by one scene object outside the texture table (a BSDF's IOR, an
    environment map's texels, a medium's voxel grid): ``params`` maps a name to a Dr.Jit
    value; the key is ``<path>.<name>``; ``valid`` maps a name to its range."""

    def __init__(self, path: str, valid: dict | None = None, **params):
        self.path = path.split(".", 1)[1] if path.startswith("scene.") else path
        self.params = params
        self.valid = dict(valid or {})


def check_params(owner, names=None, path: str | None = None) -> None:
    """Raise a ``SceneError`` naming ``<path>.<name>`` (``path``: the owner's key path by
    default) unless the values of the parameters ``names`` (default: all) of ``owner``
    are finite and in their ranges (``owner.valid``). Dr.Jit values are checked where
    they are (one reduction each) and read on the host only to describe a bad one; not
    inside ``dr.freeze`` (the caller skips it there)."""
    valid = getattr(owner, "valid", {})
    for name in owner.params if names is None else names:
        v, rng, key = owner.params[name], valid.get(name, FINITE), f"{path or owner.path}.{name}"
        if isinstance(v, (int, float)):
            rng.check(v, key)
            continue
        v = dr.detach(v)
        if dr.any(rng.bad(v.array if dr.is_tensor_v(v) else v), axis=None):
            values = np.asarray(v, np.float64)
            rng.check(values if dr.is_tensor_v(v) else values.ravel(), key)   # a colour: its channels


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
