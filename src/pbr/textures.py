"""Spectral textures: constant spectra, ``checkerboard``, ``bitmap``, and pbrt-v4's
``scale`` and ``mix`` combinators.

Every texture of a scene lives in one :class:`TextureSet`. An instance is addressed by a
*slot*; the set keeps one structure-of-arrays table per kind and a slot -> (kind, index)
map, so a kernel evaluates any texture with a few gathers, and only the kinds a scene
uses are traced into it.

Constant spectra cover Mitsuba's ``rgb`` (albedo / unbounded / illuminant forms),
``spectrum`` (a constant, ``wavelength:value`` pairs or a file), ``blackbody``, ``d65``
and plain floats:  value(l) = scale * base(l) * (D65(l) if illuminant), where base is 1,
a sigmoid polynomial, or a table resampled at 1 nm (piecewise linear, as Mitsuba's
``regular``/``irregular`` spectra). Bitmap texels are upsampled per texel and the
spectra of the 4 nearest texels are interpolated, as in Mitsuba's spectral variants.

Combinators (:class:`Composite`) nest arbitrarily over every kind: pbrt-v4's ``scale``
(``tex * scale``), ``mix`` (``(1 - amount) tex1 + amount tex2``) and Mitsuba's
``checkerboard`` whose colours are not constants. A composite is a node of one more table
(operation and child slots); a kernel evaluates a slot by an unrolled descent of fixed
depth (the deepest nesting in the scene), where each level evaluates at most three
children, masked per lane: a scene without composites traces exactly the leaf code.

Parameters (``.value`` of constants, ``.data`` of bitmaps) are Dr.Jit arrays exposed to
:func:`pbr.traverse`; tables are rebuilt from them, differentiably, on ``update()``.
Children of combinators get key paths below their parent (``mat.reflectance.tex.data``,
``mat.reflectance.amount.value``), as nested textures do in ``mi.traverse``.
"""

from __future__ import annotations

import os

import numpy as np
import drjit as dr
import mitsuba as mi

from . import dispatch, meshattr
from . import spectrum as spec
from .meshattr import MeshAttribute
from .plugins.props import Props, SceneError

# Slot kinds.
CONSTANT, CHECKERBOARD, BITMAP, COMPOSITE, MESH_ATTRIBUTE = 0, 1, 2, 3, 4
# Composite operations.
OP_SCALE, OP_MIX, OP_CHECKER = 0, 1, 2
# Base spectrum of a constant.
BASE_ONE, BASE_SIGMOID, BASE_TABLE = 0, 1, 2

# Texture/spectrum plugin types (``mix`` is also a BSDF: see the loader).
TEXTURE_TYPES = frozenset({"rgb", "spectrum", "blackbody", "d65", "uniform", "checkerboard", "bitmap", "scale",
                           "mix", "mesh_attribute"})

_TAB_N = int(spec.LAMBDA_MAX - spec.LAMBDA_MIN) + 1  # 1 nm resolution


class ConstantSpectrum:
    """A spatially constant spectrum. ``form``: 'albedo', 'unbounded' or 'illuminant'."""

    def __init__(self, base: int, form: str = "albedo", value=None, table=None, scale: float = 1.0):
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
    def __init__(self, color0: int, color1: int, to_uv: np.ndarray):
        self.color0, self.color1, self.to_uv = color0, color1, to_uv
        self.params = {}


class Bitmap:
    def __init__(self, rgb: np.ndarray, filter_type: str, wrap_mode: str, to_uv: np.ndarray, form: str):
        self.height, self.width = rgb.shape[:2]
        self.filter_type, self.wrap_mode, self.to_uv, self.form = filter_type, wrap_mode, to_uv, form
        self.params = {"data": mi.TensorXf(np.ascontiguousarray(rgb, dtype=np.float32))}


class Composite:
    """A combinator node over other slots: ``scale`` (x * m), ``mix`` (x + m (y - x)) or a
    ``checkerboard`` with non-constant colours (x where the checker pattern of ``to_uv``
    is even, y elsewhere). Its own parameters are its children's."""

    def __init__(self, op: int, x: int, y: int | None = None, m: int | None = None, to_uv=None):
        self.op, self.x = op, x
        self.y = x if y is None else y      # unused children point at a valid slot
        self.m = x if m is None else m
        self.to_uv = np.eye(4) if to_uv is None else to_uv
        self.params = {}


class TextureSet:
    """All textures of a scene and their Dr.Jit tables."""

    def __init__(self):
        self.items: list = []          # slot -> instance
        self.constants: list[int] = []  # slots of each kind, in table order
        self.checkers: list[int] = []
        self.bitmaps: list[int] = []
        self.composites: list[int] = []
        self.mesh_attrs: list[int] = []
        self.mesh_data: list = []       # meshes read by mesh_attrs, their slots and
        self.mesh_uses: list = []       # triangles (set by meshattr.bind)
        self.mesh_geometry: dict = {}
        self._cache: dict = {}

    # -- building -------------------------------------------------------------------
    def add(self, tex) -> int:
        slot = len(self.items)
        self.items.append(tex)
        kind = {ConstantSpectrum: self.constants, Checkerboard: self.checkers, Bitmap: self.bitmaps,
                Composite: self.composites, MeshAttribute: self.mesh_attrs}[type(tex)]
        kind.append(slot)
        return slot

    def param_owners(self) -> list:
        """Objects whose ``params`` are scene parameters (under ``<path>.<name>``): the
        textures and the meshes whose attributes textures read."""
        return self.items + self.mesh_data

    def kind_of(self, slot: int) -> int:
        t = type(self.items[slot])
        return {ConstantSpectrum: CONSTANT, Checkerboard: CHECKERBOARD, Bitmap: BITMAP, Composite: COMPOSITE,
                MeshAttribute: MESH_ATTRIBUTE}[t]

    def depth_of(self, slot: int) -> int:
        """Nesting depth of combinators below ``slot`` (0 for the plain kinds)."""
        t = self.items[slot]
        if not isinstance(t, Composite):
            return 0
        kids = {OP_SCALE: (t.x, t.m), OP_MIX: (t.x, t.y, t.m), OP_CHECKER: (t.x, t.y)}[t.op]
        return 1 + max(self.depth_of(k) for k in kids)

    def constant_value(self, slot: int) -> float:
        """A rough scalar magnitude of a constant (for light power estimates)."""
        t = self.items[slot]
        if isinstance(t, ConstantSpectrum):
            v = t.params.get("value")
            if t.base == BASE_SIGMOID:
                rgb = np.array(v, dtype=np.float64).reshape(-1)
                return float(spec.luminance_rgb(np.maximum(rgb, 0))) * t.scale
            if t.base == BASE_TABLE:
                return float(np.mean(t.table)) * t.scale * (1.0 if v is None else float(np.asarray(v).reshape(-1)[0]))
            return t.scale * (1.0 if v is None else float(np.asarray(v).reshape(-1)[0]))
        if isinstance(t, Checkerboard):
            return 0.5 * (self.constant_value(t.color0) + self.constant_value(t.color1))
        if isinstance(t, Composite):
            x = self.constant_value(t.x)
            if t.op == OP_SCALE:
                return x * self.constant_value(t.m)
            if t.op == OP_MIX:
                m = self.constant_value(t.m)
                return (1.0 - m) * x + m * self.constant_value(t.y)
            return 0.5 * (x + self.constant_value(t.y))
        if isinstance(t, MeshAttribute):   # data unknown at load time: a mid-range guess
            return 0.5 * float(t.params["scale"][0])
        return float(np.mean(spec.luminance_rgb(np.moveaxis(np.array(t.params["data"]), -1, 0)[:3])))

    def build(self) -> None:
        """(Re)build the Dr.Jit tables from the instances' current parameter values."""
        n = len(self.items)
        kinds = [self.kind_of(s) for s in range(n)]
        index = [0] * n
        for lst in (self.constants, self.checkers, self.bitmaps, self.composites, self.mesh_attrs):
            for i, s in enumerate(lst):
                index[s] = i
        T = {"slot_kind": mi.UInt32(kinds), "slot_index": mi.UInt32(index)}
        T.update(self._value_tables())
        # Constants.
        consts = [self.items[s] for s in self.constants]
        if consts:
            T["c_base"] = mi.UInt32([c.base for c in consts])
            T["c_d65"] = mi.Bool([c.form == "illuminant" for c in consts])
            tabs = [c for c in consts if c.base == BASE_TABLE]
            offs, pool = [], []
            for c in consts:
                if c.base == BASE_TABLE:
                    offs.append(len(pool) * _TAB_N)
                    pool.append(np.asarray(c.table, dtype=np.float32))
                else:
                    offs.append(0)
            T["c_tab_offset"] = mi.UInt32(offs)
            if tabs:
                T["c_tab"] = mi.Float(np.concatenate(pool))
        # Checkerboards.
        if self.checkers:
            ch = [self.items[s] for s in self.checkers]
            T["k_color0"] = mi.UInt32([index[c.color0] for c in ch])
            T["k_color1"] = mi.UInt32([index[c.color1] for c in ch])
            T["k_to_uv"] = [mi.Float([c.to_uv[r, k] for c in ch]) for r in range(2) for k in (0, 1, 3)]
        # Bitmaps: addressing of the texel pool.
        if self.bitmaps:
            bm = [self.items[s] for s in self.bitmaps]
            sizes = [b.width * b.height for b in bm]
            offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.uint32)
            T["b_offset"] = mi.UInt32(offsets)
            T["b_size"] = mi.Array2u([b.width for b in bm], [b.height for b in bm])
            T["b_bilinear"] = mi.Bool([b.filter_type == "bilinear" for b in bm])
            T["b_wrap"] = mi.UInt32([("repeat", "mirror", "clamp").index(b.wrap_mode) for b in bm])
            T["b_d65"] = mi.Bool([b.form == "illuminant" for b in bm])
            T["b_to_uv"] = [mi.Float([b.to_uv[r, k] for b in bm]) for r in range(2) for k in (0, 1, 3)]
            if any(getattr(b, "needs_raw", False) for b in bm):
                # Raw texel values (normal and bump maps), 3 channels (grey replicated).
                raws = []
                for b in bm:
                    r = getattr(b, "raw_values", None)
                    r = np.asarray(b.params["data"] if r is None else r, np.float32).reshape(b.height, b.width, -1)
                    if r.shape[2] == 1:
                        r = np.repeat(r, 3, axis=2)
                    raws.append(r[..., :3].reshape(-1, 3))
                raw = np.concatenate(raws)
                T["b_raw"] = mi.Array3f(raw[:, 0], raw[:, 1], raw[:, 2])
        # Composites: operation and child slots (and the pattern transform of checkers).
        self.ops, self.depth = set(), 0
        if self.composites:
            cp = [self.items[s] for s in self.composites]
            T["n_op"] = mi.UInt32([c.op for c in cp])
            T["n_x"] = mi.UInt32([c.x for c in cp])
            T["n_y"] = mi.UInt32([c.y for c in cp])
            T["n_m"] = mi.UInt32([c.m for c in cp])
            self.ops = {c.op for c in cp}
            if OP_CHECKER in self.ops:
                T["n_to_uv"] = [mi.Float([c.to_uv[r, k] for c in cp]) for r in range(2) for k in (0, 1, 3)]
            self.depth = max(self.depth_of(s) for s in self.composites)
            # Per level d of the descent: the operations of composites of depth <= d and
            # how deep each child role (x, y, m) nests below them, so that a kernel only
            # descends where the scene's trees do (one deep chain costs one extra leaf
            # evaluation per level, not three).
            self._levels = {}
            for d in range(1, self.depth + 1):
                cs = [self.items[s] for s in self.composites if self.depth_of(s) <= d]
                role = lambda r, ops: max([self.depth_of(getattr(c, r)) for c in cs if c.op in ops],  # noqa: E731
                                          default=0)
                self._levels[d] = ({c.op for c in cs}, role("x", (OP_SCALE, OP_MIX, OP_CHECKER)),
                                   role("y", (OP_MIX, OP_CHECKER)), role("m", (OP_SCALE, OP_MIX)))
        meshattr.build_tables(self, index, T)
        dr.eval(T)
        self.T = T
        self.bases = {c.base for c in consts}
        self.has_sigmoid = any(c.base == BASE_SIGMOID for c in consts)
        self.has_table = any(c.base == BASE_TABLE for c in consts)
        self.has_d65 = any(c.form == "illuminant" for c in consts) or any(
            self.items[s].form == "illuminant" for s in self.bitmaps)

    def _value_tables(self) -> dict:
        """The tables that hold parameter values, built differentiably from them: 4 floats
        per constant and per bitmap texel (3 sigmoid coefficients, scale), read with one
        packet gather (and, in adjoint passes, scatter-added as one packet)."""
        T = {}
        consts = [self.items[s] for s in self.constants]
        if consts:
            packed = dr.zeros(mi.Float, 4 * len(consts))
            for i, c in enumerate(consts):
                cf, sc = c.coeffs_scale()
                dr.scatter(packed, mi.Array4f(cf[0], cf[1], cf[2], sc), mi.UInt32(i))
            T["c_packed"] = packed
        if self.bitmaps:
            bm = [self.items[s] for s in self.bitmaps]
            texels = dr.zeros(mi.Float, 4 * sum(b.width * b.height for b in bm))
            off = 0
            for b in bm:
                data = b.params["data"]
                ch = data.shape[2] if len(data.shape) == 3 else 1
                npx = b.width * b.height
                idx = dr.arange(mi.UInt32, npx)
                if ch >= 3:
                    rgb = mi.Color3f(*[dr.gather(mi.Float, data.array, idx * ch + k) for k in range(3)])
                else:
                    g = dr.gather(mi.Float, data.array, idx * ch)
                    rgb = mi.Color3f(g, g, g)
                if b.form == "albedo":
                    cf, sc = spec.rgb_to_coeffs(rgb), mi.Float(1.0)
                else:
                    cf, sc = spec.rgb_unbounded(rgb)
                dr.scatter(texels, mi.Array4f(cf[0], cf[1], cf[2], sc), idx + off)
                off += npx
            T["b_texel"] = texels
        return T

    def refreshable(self, tex) -> bool:
        """Whether :meth:`refresh` suffices after ``tex``'s parameters change (constants
        and colour bitmaps; not the raw texels of normal and bump maps)."""
        return isinstance(tex, ConstantSpectrum) or (isinstance(tex, Bitmap) and not getattr(tex, "needs_raw", False))

    def refresh(self) -> None:
        """Recompute the value tables from the current parameters, keeping everything else
        :meth:`build` made (slots, kinds, sizes, addressing). Dr.Jit operations only: it
        can run inside ``dr.freeze``."""
        T = self._value_tables()
        dr.eval(T)
        self.T.update(T)

    # -- evaluation (inside kernels) ---------------------------------------------------
    @staticmethod
    def _apply_uv(M, uv, i):
        m = [dr.gather(mi.Float, a, i) for a in M]
        return mi.Point2f(m[0] * uv[0] + m[1] * uv[1] + m[2], m[3] * uv[0] + m[4] * uv[1] + m[5])

    def _eval_constant(self, ci, lam, active, illuminant=True):
        T = self.T
        v = mi.Spectrum(1.0)
        t = dr.gather(mi.Array4f, T["c_packed"], ci, active)
        if self.has_sigmoid:
            c = mi.Array3f(t[0], t[1], t[2])
            if self.bases == {BASE_SIGMOID}:
                v = spec.sigmoid_polynomial(c, lam)
            else:
                base = dr.gather(mi.UInt32, T["c_base"], ci, active)
                v = dr.select(base == BASE_SIGMOID, spec.sigmoid_polynomial(c, lam), v)
        if self.has_table:
            base = dr.gather(mi.UInt32, T["c_base"], ci, active)
            off = dr.gather(mi.UInt32, T["c_tab_offset"], ci, active)
            tab = mi.Spectrum([self._lerp_1nm(T["c_tab"], off, lam[k], active & (base == BASE_TABLE))
                               for k in range(spec.N_WAVELENGTHS)])
            v = dr.select(base == BASE_TABLE, tab, v)
        if illuminant and self.has_d65 and self.constants:
            v = dr.select(dr.gather(mi.Bool, T["c_d65"], ci, active), v * spec.d65(lam), v)
        return v * t[3]

    @staticmethod
    def _lerp_1nm(table, off, l, active):
        t = dr.clip(l - spec.LAMBDA_MIN, 0.0, _TAB_N - 1.0)
        i0 = dr.minimum(mi.UInt32(t), _TAB_N - 2)
        w = t - mi.Float(i0)
        a = dr.gather(mi.Float, table, off + i0, active)
        b = dr.gather(mi.Float, table, off + i0 + 1, active)
        return dr.fma(w, b - a, a)

    def _bitmap_lookup(self, bi, uv, active):
        """Addressing shared by bitmap lookups: (texel index function (dx, dy) -> index into
        the texel pools, bilinear weights, bilinear mask, resolution, to_uv coefficients)."""
        T = self.T
        size = dr.gather(mi.Array2u, T["b_size"], bi, active)
        off = dr.gather(mi.UInt32, T["b_offset"], bi, active)
        wrap = dr.gather(mi.UInt32, T["b_wrap"], bi, active)
        bil = dr.gather(mi.Bool, T["b_bilinear"], bi, active)
        A = [dr.gather(mi.Float, a, bi, active) for a in T["b_to_uv"]]
        st = mi.Point2f(A[0] * uv[0] + A[1] * uv[1] + A[2], A[3] * uv[0] + A[4] * uv[1] + A[5])
        res = mi.Vector2f(size)
        p = st * res - dr.select(bil, 0.5, 0.0)
        p0 = dr.floor(p)
        w = dr.select(bil, p - p0, 0.0)
        ip = mi.Vector2i(p0)

        def index(dx, dy):
            q = _wrap(mi.Vector2i(ip.x + dx, ip.y + dy), mi.Vector2i(size), wrap)
            return off + mi.UInt32(q.y) * size.x + mi.UInt32(q.x)

        return index, w, bil, res, A

    def _eval_bitmap(self, bi, uv, lam, active, illuminant=True):
        T = self.T
        index, w1, bil, _, _ = self._bitmap_lookup(bi, uv, active)

        def texel(dx, dy):
            k = index(dx, dy)
            t = dr.gather(mi.Array4f, T["b_texel"], k, active)
            return spec.sigmoid_polynomial(mi.Array3f(t[0], t[1], t[2]), lam) * t[3]

        v = texel(0, 0)
        if any(self.items[s].filter_type == "bilinear" for s in self.bitmaps):
            v10, v01, v11 = texel(1, 0), texel(0, 1), texel(1, 1)
            v0 = dr.fma(w1.x, v10 - v, v)
            v1 = dr.fma(w1.x, v11 - v01, v01)
            v = dr.select(bil, dr.fma(w1.y, v1 - v0, v0), v)
        if illuminant and self.has_d65:
            v = dr.select(dr.gather(mi.Bool, T["b_d65"], bi, active), v * spec.d65(lam), v)
        return v

    def eval_raw(self, slot, uv, active=True):
        """Raw 3-channel value of bitmap ``slot`` (no colour processing; normal and bump
        maps) and its derivatives w.r.t. u and v: (value, d/du, d/dv)."""
        T = self.T
        bi = dr.gather(mi.UInt32, T["slot_index"], mi.UInt32(slot), active)
        index, w, bil, res, A = self._bitmap_lookup(bi, uv, active)

        def texel(dx, dy):
            return dr.gather(mi.Array3f, T["b_raw"], index(dx, dy), active)

        v00, v10, v01, v11 = texel(0, 0), texel(1, 0), texel(0, 1), texel(1, 1)
        v0 = dr.fma(w.x, v10 - v00, v00)
        v1 = dr.fma(w.x, v11 - v01, v01)
        v = dr.select(bil, dr.fma(w.y, v1 - v0, v0), v00)
        gs = dr.select(bil, ((1.0 - w.y) * (v10 - v00) + w.y * (v11 - v01)) * res.x, 0.0)
        gt = dr.select(bil, ((1.0 - w.x) * (v01 - v00) + w.x * (v11 - v10)) * res.y, 0.0)
        # Chain rule through to_uv (st = A uv + b).
        return v, A[0] * gs + A[3] * gt, A[1] * gs + A[4] * gt

    def eval(self, slot, uv, lam: mi.Spectrum, active=True, illuminant=True) -> mi.Spectrum:
        """Spectrum of texture ``slot`` at ``uv``: surface coordinates, or the surface
        interaction (BSDFs pass ``ctx.si``: ``mesh_attribute`` textures need the hit; they
        are 0 at plain coordinates). Callers that can only reach non-illuminant textures
        (reflectances) pass ``illuminant=False`` to keep the D65 lookup out of their kernels."""
        slot = mi.UInt32(slot)
        si = uv if isinstance(uv, mi.SurfaceInteraction3f) else None
        uv = si.uv if si is not None else uv
        if not self.composites:
            return self._eval_leaf(slot, uv, lam, active, illuminant, si)
        return self._eval_node(slot, uv, lam, mi.Bool(active), illuminant, self.depth, si)

    def _eval_node(self, slot, uv, lam, active, illuminant, depth, si=None):
        """Evaluate ``slot`` whose combinator nesting is at most ``depth`` levels: at each
        level a composite lane evaluates its children one level down, any other lane
        passes its own (leaf) slot down as the first child."""
        if depth == 0:
            return self._eval_leaf(slot, uv, lam, active, illuminant, si)
        T = self.T
        ops, dx, dy, dm = self._levels[depth]
        comp = active & (dr.gather(mi.UInt32, T["slot_kind"], slot, active) == COMPOSITE)
        ni = dr.gather(mi.UInt32, T["slot_index"], slot, comp)
        op = dr.gather(mi.UInt32, T["n_op"], ni, comp) if len(ops) > 1 else mi.UInt32(next(iter(ops)))
        x_slot = dr.select(comp, dr.gather(mi.UInt32, T["n_x"], ni, comp), slot)
        x = self._eval_node(x_slot, uv, lam, active, illuminant, dx, si)
        result = x
        if ops & {OP_SCALE, OP_MIX}:
            uses_m = comp & (op != OP_CHECKER)
            m = self._eval_node(dr.gather(mi.UInt32, T["n_m"], ni, uses_m), uv, lam, uses_m, illuminant, dm, si)
        if ops & {OP_MIX, OP_CHECKER}:
            uses_y = comp & (op != OP_SCALE)
            y = self._eval_node(dr.gather(mi.UInt32, T["n_y"], ni, uses_y), uv, lam, uses_y, illuminant, dy, si)
        if OP_SCALE in ops:
            result = dr.select(comp & (op == OP_SCALE), x * m, result)
        if OP_MIX in ops:
            result = dr.select(comp & (op == OP_MIX), dr.fma(m, y - x, x), result)
        if OP_CHECKER in ops:
            is_ck = comp & (op == OP_CHECKER)
            st = self._apply_uv(T["n_to_uv"], uv, ni)
            frac = st - dr.floor(st)
            second = (frac.x > 0.5) != (frac.y > 0.5)
            result = dr.select(is_ck & second, y, result)
        return result

    def _eval_leaf(self, slot, uv, lam, active, illuminant, si=None):
        """A constant, checkerboard (of constants), bitmap or mesh-attribute slot."""
        T = self.T
        if len(self.items) == 1 or not (self.checkers or self.bitmaps or self.mesh_attrs):
            kind = mi.UInt32(self.kind_of(0)) if len(self.items) == 1 else mi.UInt32(CONSTANT)
        else:
            kind = dr.gather(mi.UInt32, T["slot_kind"], slot, active)
        # With constants only, slots are constant-table indices already.
        only_constants = not (self.checkers or self.bitmaps or self.composites or self.mesh_attrs)
        idx = slot if only_constants else dr.gather(mi.UInt32, T["slot_index"], slot, active)
        result = mi.Spectrum(0.0)
        if self.constants:
            ci = idx
            if self.checkers:
                is_ck = active & (kind == CHECKERBOARD)
                st = self._apply_uv(T["k_to_uv"], uv, idx)
                frac = st - dr.floor(st)
                same = (frac.x > 0.5) == (frac.y > 0.5)
                c0 = dr.gather(mi.UInt32, T["k_color0"], idx, is_ck)
                c1 = dr.gather(mi.UInt32, T["k_color1"], idx, is_ck)
                ci = dr.select(is_ck, dr.select(same, c0, c1), idx)
            on = active & (kind != BITMAP)
            if self.mesh_attrs:
                on &= kind != MESH_ATTRIBUTE
            result = self._eval_constant(ci, lam, on, illuminant)
        if self.bitmaps:
            is_bm = active & (kind == BITMAP)
            if len(self.bitmaps) < len(self.items) and dispatch.branching():
                # A symbolic conditional: vector packets with no bitmap lane skip the
                # lookup (four texel spectra), instead of computing and discarding it.
                result = dr.if_stmt(
                    (idx, uv, lam, is_bm, result), is_bm,
                    lambda i, u, l, m, r: mi.Spectrum(self._eval_bitmap(i, u, l, m, illuminant)),
                    lambda i, u, l, m, r: r, label="bitmap texture")
            else:
                result = dr.select(is_bm, self._eval_bitmap(idx, uv, lam, is_bm, illuminant), result)
        if self.mesh_data and si is not None:   # elsewhere mesh attributes are 0
            is_ma = active & (kind == MESH_ATTRIBUTE)
            result = dr.select(is_ma, meshattr.evaluate(self, idx, si, lam, is_ma), result)
        return result


def _wrap(q: mi.Vector2i, size: mi.Vector2i, mode: mi.UInt32) -> mi.Vector2i:
    """Texel wrap modes: 0 repeat, 1 mirror, 2 clamp."""
    rep = q - size * mi.Vector2i(dr.floor(mi.Vector2f(q) / mi.Vector2f(size)))
    per = q - 2 * size * mi.Vector2i(dr.floor(mi.Vector2f(q) / mi.Vector2f(2 * size)))
    mir = dr.select(per >= size, 2 * size - 1 - per, per)
    clp = dr.clip(q, 0, size - 1)
    return dr.select(mode == 0, rep, dr.select(mode == 1, mir, clp))


# ------------------------------------------------------------------------ loading

def _table_from_pairs(wl: np.ndarray, vals: np.ndarray, where: str) -> np.ndarray:
    wl = np.asarray(wl, np.float64)
    vals = np.asarray(vals, np.float64)
    if wl.size < 2 or np.any(np.diff(wl) <= 0):
        raise SceneError(f"{where}: wavelengths must be at least two strictly increasing values")
    grid = spec.LAMBDA_MIN + np.arange(_TAB_N)
    # Zero outside the given range, as Mitsuba's irregular/regular spectra.
    return np.where((grid >= wl[0]) & (grid <= wl[-1]), np.interp(grid, wl, vals), 0.0)


def add_tabulated(loader, wavelengths, values, path: str) -> int:
    """A texture slot for a tabulated spectrum (piecewise linear between samples)."""
    slot = loader.textures.add(ConstantSpectrum(BASE_TABLE, table=_table_from_pairs(wavelengths, values, path)))
    loader.textures.items[slot].path = path.split(".", 1)[1] if path.startswith("scene.") else path
    return slot


def load_spectrum(loader, value, path: str, emitter: bool, unbounded: bool = False) -> int:
    """Turn a Mitsuba spectrum-valued parameter into a texture slot (see ``_load``); the
    texture remembers its key path for :func:`pbr.traverse` (``red.reflectance``)."""
    slot = _load(loader, value, path, emitter, unbounded)
    tex = loader.textures.items[slot]
    if not hasattr(tex, "path"):
        tex.path = path.split(".", 1)[1] if path.startswith("scene.") else path
    return slot


def _load(loader, value, path: str, emitter: bool, unbounded: bool = False) -> int:
    """Turn a Mitsuba spectrum-valued parameter into a texture slot.

    ``value`` is a float, a dict ``{'type': 'rgb'|'spectrum'|'blackbody'|'d65'|
    'checkerboard'|'bitmap'|'ref', ...}`` as in Mitsuba dicts. Emitters use the
    illuminant (D65) form for RGB and floats, as Mitsuba's spectral variants do."""
    texs: TextureSet = loader.textures
    form_rgb = "illuminant" if emitter else ("unbounded" if unbounded else "albedo")
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        v = float(value)
        if emitter:
            return texs.add(ConstantSpectrum(BASE_SIGMOID, "illuminant", mi.Color3f(v)))
        return texs.add(ConstantSpectrum(BASE_ONE, value=mi.Float(v)))
    if not isinstance(value, dict) or "type" not in value:
        raise SceneError(f"{path}: expected a float or a texture/spectrum dict with a 'type', got {value!r}")
    p = Props(value, path, loader)
    t = p.type
    if t == "ref":
        obj = loader.resolve_ref(p.string("id"), path)
        p.finish()
        return _load(loader, obj, path, emitter, unbounded)
    if t == "rgb":
        rgb = p.vector3("value")
        if form_rgb == "albedo" and (np.any(rgb < 0) or np.any(rgb > 1)):
            raise p.error("value", f"RGB reflectance must lie in [0, 1], got {rgb.tolist()}")
        p.finish()
        return texs.add(ConstantSpectrum(BASE_SIGMOID, form_rgb, mi.Color3f(*map(float, rgb))))
    if t == "spectrum":
        if p.has("filename"):
            wl, vals = spec.read_spd(loader.resolve_path(p.string("filename"), p.key("filename")))
            p.finish()
            return texs.add(ConstantSpectrum(BASE_TABLE, table=_table_from_pairs(wl, vals, path)))
        v = p.raw("value")
        p.finish()
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return texs.add(ConstantSpectrum(BASE_ONE, value=mi.Float(float(v))))
        if isinstance(v, str):
            try:
                pairs = [tuple(float(x) for x in item.split(":")) for item in v.replace(",", " ").split()]
            except ValueError:
                raise SceneError(f"{path}.value: expected 'wavelength:value' pairs, got {v!r}") from None
            v = pairs
        try:
            arr = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            arr = np.empty(0)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise SceneError(f"{path}.value: expected a float or a list of (wavelength, value) pairs, got {v!r}")
        return texs.add(ConstantSpectrum(BASE_TABLE, table=_table_from_pairs(arr[:, 0], arr[:, 1], path)))
    if t == "blackbody":
        temp = p.float("temperature", min=1.0)
        lo = p.float("wavelength_min", spec.LAMBDA_MIN)
        hi = p.float("wavelength_max", spec.LAMBDA_MAX)
        p.finish()
        grid = spec.LAMBDA_MIN + np.arange(_TAB_N)
        table = np.where((grid >= lo) & (grid <= hi), spec.blackbody(grid, temp), 0.0)
        return texs.add(ConstantSpectrum(BASE_TABLE, table=table))
    if t == "d65":
        scale = p.float("scale", 1.0)
        if p.has("color"):
            rgb = p.vector3("color")
            p.finish()
            return texs.add(ConstantSpectrum(BASE_SIGMOID, "illuminant", mi.Color3f(*map(float, rgb)), scale=scale))
        p.finish()
        return texs.add(ConstantSpectrum(BASE_ONE, "illuminant", scale=scale))
    if t == "uniform":
        v = p.float("value")
        p.finish()
        return texs.add(ConstantSpectrum(BASE_ONE, value=mi.Float(v)))
    if t == "checkerboard":
        c0 = load_spectrum(loader, p.raw("color0", 0.4), p.key("color0"), emitter, unbounded)
        c1 = load_spectrum(loader, p.raw("color1", 0.2), p.key("color1"), emitter, unbounded)
        to_uv = p.transform("to_uv")
        p.finish()
        if texs.kind_of(c0) == CONSTANT and texs.kind_of(c1) == CONSTANT:
            slot = texs.add(Checkerboard(c0, c1, to_uv))
        else:  # textured colours: a combinator node
            slot = texs.add(Composite(OP_CHECKER, c0, c1, to_uv=to_uv))
        texs.items[slot].children = {"color0": c0, "color1": c1}
        return slot
    if t == "scale":
        # pbrt-v4's ``scale``: tex * scale. The factor is a plain (unbounded, never
        # illuminant) spectrum, so that an emitter's scaled radiance carries D65 once.
        x = load_spectrum(loader, p.raw("tex", 1.0), p.key("tex"), emitter, unbounded)
        m = load_spectrum(loader, p.raw("scale", 1.0), p.key("scale"), emitter=False, unbounded=True)
        p.finish()
        slot = texs.add(Composite(OP_SCALE, x, m=m))
        texs.items[slot].children = {"tex": x, "scale": m}
        return slot
    if t == "mix":
        # pbrt-v4's ``mix``: (1 - amount) tex1 + amount tex2 (defaults 0, 1 and 0.5).
        x = load_spectrum(loader, p.raw("tex1", 0.0), p.key("tex1"), emitter, unbounded)
        y = load_spectrum(loader, p.raw("tex2", 1.0), p.key("tex2"), emitter, unbounded)
        m = load_spectrum(loader, p.raw("amount", 0.5), p.key("amount"), emitter=False)
        p.finish()
        slot = texs.add(Composite(OP_MIX, x, y, m))
        texs.items[slot].children = {"tex1": x, "tex2": y, "amount": m}
        return slot
    if t == "bitmap":
        from .image import read_image
        filter_type = p.string("filter_type", "bilinear", choices=("bilinear", "nearest"))
        wrap_mode = p.string("wrap_mode", "repeat", choices=("repeat", "mirror", "clamp"))
        raw = p.bool("raw", False)
        to_uv = p.transform("to_uv")
        p.mark("format")
        if p.has("data"):
            rgb = np.asarray(p.raw("data"), dtype=np.float32)
            if rgb.ndim == 2:
                rgb = rgb[..., None]
            if rgb.ndim != 3:
                raise p.error("data", f"expected an (H, W, C) array, got shape {rgb.shape}")
        else:
            fname = loader.resolve_path(p.string("filename"), p.key("filename"))
            try:
                rgb = read_image(fname, linearize=not raw)
            except TypeError:
                rgb = read_image(fname)
            except Exception as e:  # unreadable file
                raise p.error("filename", f"cannot read image {fname!r}: {e}") from None
        p.finish()
        if rgb.ndim == 2:
            rgb = rgb[..., None]
        rgb = rgb[..., :3] if rgb.shape[2] >= 3 else rgb[..., :1]
        if raw and not p.has("data") and os.path.splitext(fname)[1].lower() in (".png", ".jpg", ".jpeg"):
            # read_image decodes 8-bit sRGB; raw data (normal/bump maps) keeps the stored values.
            from .image import linear_to_srgb
            rgb = linear_to_srgb(rgb).astype(np.float32)
        raw_values = np.array(rgb, dtype=np.float32)
        if form_rgb == "albedo":
            rgb = np.clip(rgb, 0.0, 1.0)
        slot = texs.add(Bitmap(rgb, filter_type, wrap_mode, to_uv, form_rgb))
        texs.items[slot].raw_values = raw_values
        return slot
    if t == "mesh_attribute":
        return meshattr.load(texs, p, form_rgb)
    raise SceneError(f"{path}: unsupported texture/spectrum type {t!r} (supported: rgb, spectrum, blackbody, "
                     "d65, uniform, checkerboard, bitmap, scale, mix, mesh_attribute, ref)")
