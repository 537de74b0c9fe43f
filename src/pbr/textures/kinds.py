"""The kinds of texture slots: what one texture of a scene holds before its kind's table
is built (see :mod:`.tables`).

Every kind has ``params`` (its differentiable parameters, exposed by :func:`pbr.traverse`
under ``<path>.<name>``) and ``path``, its key path without the leading ``scene.``.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from .. import spectrum as spec

# Slot kinds.
CONSTANT, CHECKERBOARD, BITMAP, COMPOSITE, MESH_ATTRIBUTE, PROCEDURAL, MIPMAP, VOLUME = 0, 1, 2, 3, 4, 5, 6, 7
# Composite operations.
OP_SCALE, OP_MIX, OP_CHECKER, OP_SQRT = 0, 1, 2, 3
# Base spectrum of a constant.
BASE_ONE, BASE_SIGMOID, BASE_TABLE = 0, 1, 2

TAB_N = int(spec.LAMBDA_MAX - spec.LAMBDA_MIN) + 1  # tabulated spectra: 1 nm resolution


def key_path(path: str) -> str:
    """A parameter owner's key: the key path without its leading ``scene.``."""
    return path.split(".", 1)[1] if path.startswith("scene.") else path


class ConstantSpectrum:
    """A spatially constant spectrum: ``scale * base(lambda) * (D65(lambda) if
    illuminant)``, base 1 (``BASE_ONE``, times the ``value`` parameter when given), a
    sigmoid polynomial of the RGB ``value`` (``BASE_SIGMOID``) or a 1 nm ``table``
    (``BASE_TABLE``). ``form``: 'albedo', 'unbounded' or 'illuminant' (how RGB is
    upsampled; illuminants are multiplied by D65)."""

    kind = CONSTANT

    def __init__(self, path: str, base: int, form: str = "albedo", value=None, table=None, scale: float = 1.0):
        self.path = key_path(path)
        self.base, self.form, self.table, self.scale = base, form, table, scale
        self.params = {}
        if value is not None:
            self.params["value"] = value

    def coeffs_scale(self):
        """(sigmoid coefficients, scale), differentiable in the ``value`` parameter."""
        v = self.params.get("value")
        if self.base == BASE_SIGMOID:
            if self.form == "albedo":
                return spec.rgb_to_coeffs(v), mi.Float(self.scale)
            c, s = spec.rgb_unbounded(v)
            return c, s * self.scale
        s = mi.Float(self.scale) if v is None else mi.Float(v) * self.scale
        return mi.Array3f(0.0), s


class Checkerboard:
    """Mitsuba's ``checkerboard`` of two constant slots ``color0``/``color1`` over the
    texture coordinates ``to_uv`` (a 4x4 matrix) maps."""

    kind = CHECKERBOARD

    def __init__(self, path: str, color0: int, color1: int, to_uv: np.ndarray):
        self.path = key_path(path)
        self.color0, self.color1, self.to_uv = color0, color1, to_uv
        self.params = {}


class Bitmap:
    """An image texture: ``data`` (H, W, C) is the parameter (colours upsampled per texel
    in ``form``); ``raw_values`` the stored values before clamping (normal and bump maps
    read them when ``needs_raw`` is set)."""

    kind = BITMAP

    def __init__(self, path: str, rgb: np.ndarray, filter_type: str, wrap_mode: str, to_uv: np.ndarray, form: str,
                 raw_values: np.ndarray | None = None):
        self.path = key_path(path)
        self.height, self.width = rgb.shape[:2]
        self.filter_type, self.wrap_mode, self.to_uv, self.form = filter_type, wrap_mode, to_uv, form
        self.params = {"data": mi.TensorXf(np.ascontiguousarray(rgb, dtype=np.float32))}
        self.raw_values = raw_values
        self.needs_raw = False


class Composite:
    """A combinator node over other slots: ``scale`` (x * m), ``mix`` (x + m (y - x)), a
    ``checkerboard`` with non-constant colours (x where the checker pattern of ``to_uv``
    is even, y elsewhere) or ``sqrt`` (sqrt(max(x, 0)): pbrt-v4's ``remaproughness`` of a
    roughness texture). Its own parameters are its children's."""

    kind = COMPOSITE

    def __init__(self, path: str, op: int, x: int, y: int | None = None, m: int | None = None, to_uv=None):
        self.path = key_path(path)
        self.op, self.x = op, x
        self.y = x if y is None else y      # unused children point at a valid slot
        self.m = x if m is None else m
        self.to_uv = np.eye(4) if to_uv is None else to_uv
        self.params = {}

    @property
    def children(self) -> tuple:
        """The slots the operation reads."""
        return {OP_SCALE: (self.x, self.m), OP_MIX: (self.x, self.y, self.m), OP_CHECKER: (self.x, self.y),
                OP_SQRT: (self.x,)}[self.op]


class MeshAttribute:
    """Mitsuba's ``mesh_attribute``: attribute ``name`` of the hit mesh times ``scale``
    (the parameter), upsampled in ``form`` ('albedo' or 'unbounded')."""

    kind = MESH_ATTRIBUTE

    def __init__(self, path: str, name: str, scale: float, form: str):
        self.path = key_path(path)
        self.key = path
        self.name, self.form = name, form
        self.params = {"scale": mi.Float(scale)}
