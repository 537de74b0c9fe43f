"""``TextureSet``: every texture of a scene, addressed by *slot*, and their evaluation.

The set keeps one structure-of-arrays table per kind (:mod:`.tables`) and a slot ->
(kind, index) map, so a kernel evaluates any texture with a few gathers, and only the
kinds a scene uses are traced into it. Combinators (:class:`~.kinds.Composite`) nest
arbitrarily over every kind; a kernel evaluates a slot by an unrolled descent of fixed
depth (the deepest nesting in the scene), where each level evaluates at most three
children, masked per lane: a scene without composites traces exactly the leaf code.
Bitmap texels are upsampled per texel and the spectra of the 4 nearest texels are
interpolated, as in Mitsuba's spectral variants.

A caller that knows which slots a lookup can reach (a BSDF parameter: its instances'
slots) passes them as ``reach``: the kernel then holds only the kinds, spectrum bases
(sigmoid coefficients, tabulated spectra, D65) and combinators those slots use, not every
one the scene has (the materials gallery evaluated the tabulated-spectrum code of its
metals for every diffuse albedo).
"""

from __future__ import annotations

from types import SimpleNamespace

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import dispatch
from .. import spectrum as spec
from . import meshattr, mipmap, procedural, volume
from .kinds import (BASE_SIGMOID, BASE_TABLE, BITMAP, CHECKERBOARD, COMPOSITE, CONSTANT, MESH_ATTRIBUTE, MIPMAP,
                    OP_CHECKER, OP_MIX, OP_SCALE, OP_SQRT, PROCEDURAL, TAB_N, VOLUME, Bitmap, Checkerboard, Composite,
                    ConstantSpectrum, MeshAttribute)
from .tables import BitmapTable, CheckerTable, CompositeTable, ConstantTable, TextureTables


class TextureSet:
    """All textures of a scene (slots) and their Dr.Jit tables (:attr:`tables`)."""

    def __init__(self):
        self.items: list = []          # slot -> instance
        self.constants: list[int] = []  # slots of each kind, in table order
        self.checkers: list[int] = []
        self.bitmaps: list[int] = []
        self.composites: list[int] = []
        self.mesh_attrs: list[int] = []
        self.procedurals: list[int] = []
        self.mipmaps: list[int] = []
        self.volumes: list[int] = []
        # (camera, spp) of the render under way: the pixel footprint of procedural and
        # MIP-mapped textures (set by the integrator; None: no footprint, no filtering)
        self.footprint = None
        self.differenced: list[int] = []   # height textures that bump maps difference
        self.mesh_data: list = []       # meshes read by mesh_attrs, their slots and
        self.mesh_uses: list = []       # triangles (set by meshattr.bind)
        self.mesh_geometry: dict = {}
        self.tables = TextureTables()
        self._features: dict = {}       # reach -> what its evaluation must trace

    # -- building -------------------------------------------------------------------
    def add(self, tex) -> int:
        """A new slot holding ``tex`` (one of the kinds of :mod:`.kinds`)."""
        slot = len(self.items)
        self.items.append(tex)
        self._kind_lists()[tex.kind].append(slot)
        return slot

    def _kind_lists(self) -> tuple:
        return (self.constants, self.checkers, self.bitmaps, self.composites, self.mesh_attrs, self.procedurals,
                self.mipmaps, self.volumes)

    @property
    def needs_footprint(self) -> bool:
        """Whether a texture filters over the pixel footprint (procedural or MIP-mapped),
        or a bump map differences a texture (its step is the footprint's)."""
        return bool(self.procedurals or self.mipmaps or self.differenced)

    def param_owners(self) -> list:
        """Objects whose ``params`` are scene parameters (under ``<path>.<name>``): the
        textures and the meshes whose attributes textures read."""
        return self.items + self.mesh_data

    def kind_of(self, slot: int) -> int:
        return self.items[slot].kind

    def depth_of(self, slot: int) -> int:
        """Nesting depth of combinators below ``slot`` (0 for the plain kinds)."""
        t = self.items[slot]
        if not isinstance(t, Composite):
            return 0
        return 1 + max(self.depth_of(k) for k in t.children)

    def spatially_varying(self, slot: int) -> bool:
        """Whether texture ``slot`` depends on the surface point."""
        t = self.items[slot]
        if isinstance(t, Composite) and t.op != OP_CHECKER:
            return any(self.spatially_varying(k) for k in t.children)
        return not isinstance(t, ConstantSpectrum)

    def mark_raw(self, slot: int) -> None:
        """Bitmap ``slot`` is also read raw (a normal or bump map): build its raw texels."""
        self.items[slot].needs_raw = True

    def mark_differenced(self, slot: int) -> None:
        """``slot`` is a height field that a bump map differences (its finite-difference
        step comes from the pixel footprint)."""
        if slot not in self.differenced:
            self.differenced.append(slot)

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
            if t.op == OP_SQRT:
                return float(np.sqrt(max(x, 0.0)))
            return 0.5 * (x + self.constant_value(t.y))
        if isinstance(t, MeshAttribute):   # data unknown at load time: a mid-range guess
            return 0.5 * float(t.params["scale"][0])
        if isinstance(t, procedural.Procedural):
            return 0.5
        if isinstance(t, (mipmap.MipMap, volume.VolumeTexture)):
            return t.mean_luminance()
        return float(np.mean(spec.luminance_rgb(np.moveaxis(np.array(t.params["data"]), -1, 0)[:3])))

    def build(self) -> None:
        """(Re)build the Dr.Jit tables from the instances' current parameter values."""
        n = len(self.items)
        kinds = [self.kind_of(s) for s in range(n)]
        index = [0] * n
        for lst in self._kind_lists():
            for i, s in enumerate(lst):
                index[s] = i
        T = TextureTables(slot_kind=mi.UInt32(kinds), slot_index=mi.UInt32(index))
        T.constants, T.bitmaps = self._value_tables()
        # Constants.
        consts = [self.items[s] for s in self.constants]
        if consts:
            C = T.constants
            C.base = mi.UInt32([c.base for c in consts])
            C.d65 = mi.Bool([c.form == "illuminant" for c in consts])
            tabs = [c for c in consts if c.base == BASE_TABLE]
            offs, pool = [], []
            for c in consts:
                if c.base == BASE_TABLE:
                    offs.append(len(pool) * TAB_N)
                    pool.append(np.asarray(c.table, dtype=np.float32))
                else:
                    offs.append(0)
            C.tab_offset = mi.UInt32(offs)
            if tabs:
                C.tab = mi.Float(np.concatenate(pool))
        # Checkerboards.
        if self.checkers:
            ch = [self.items[s] for s in self.checkers]
            T.checkers = CheckerTable(mi.UInt32([index[c.color0] for c in ch]),
                                      mi.UInt32([index[c.color1] for c in ch]), _uv_rows(ch))
        # Bitmaps: addressing of the texel pool.
        if self.bitmaps:
            bm = [self.items[s] for s in self.bitmaps]
            sizes = [b.width * b.height for b in bm]
            offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.uint32)
            B = T.bitmaps
            B.offset = mi.UInt32(offsets)
            B.size = mi.Array2u([b.width for b in bm], [b.height for b in bm])
            B.bilinear = mi.Bool([b.filter_type == "bilinear" for b in bm])
            B.wrap = mi.UInt32([("repeat", "mirror", "clamp").index(b.wrap_mode) for b in bm])
            B.d65 = mi.Bool([b.form == "illuminant" for b in bm])
            B.to_uv = _uv_rows(bm)
            if any(b.needs_raw for b in bm):
                # Raw texel values (normal and bump maps), 3 channels (grey replicated).
                raws = []
                for b in bm:
                    r = b.raw_values
                    r = np.asarray(b.params["data"] if r is None else r, np.float32).reshape(b.height, b.width, -1)
                    if r.shape[2] == 1:
                        r = np.repeat(r, 3, axis=2)
                    raws.append(r[..., :3].reshape(-1, 3))
                raw = np.concatenate(raws)
                B.raw = mi.Array3f(raw[:, 0], raw[:, 1], raw[:, 2])
        # Composites: operation and child slots (and the pattern transform of checkers).
        self.ops, self.depth = set(), 0
        if self.composites:
            cp = [self.items[s] for s in self.composites]
            T.composites = CompositeTable(mi.UInt32([c.op for c in cp]), mi.UInt32([c.x for c in cp]),
                                          mi.UInt32([c.y for c in cp]), mi.UInt32([c.m for c in cp]))
            self.ops = {c.op for c in cp}
            if OP_CHECKER in self.ops:
                T.composites.to_uv = _uv_rows(cp)
            self.depth = max(self.depth_of(s) for s in self.composites)
        T.mesh_attributes = meshattr.build_tables(self, index)
        if self.procedurals:
            items = [self.items[s] for s in self.procedurals]
            T.procedurals = procedural.build_table(items)
            self.procedural_info = procedural.static_info(items)
        if self.mipmaps:
            items = [self.items[s] for s in self.mipmaps]
            T.mipmaps = mipmap.build_table(items)
            self.mipmap_info = mipmap.static_info(items)
        if self.volumes:
            T.volumes = volume.build_table([self.items[s] for s in self.volumes])
        dr.eval(T)
        self.tables = T
        self.bases = {c.base for c in consts}
        self.has_sigmoid = any(c.base == BASE_SIGMOID for c in consts)
        self.has_table = any(c.base == BASE_TABLE for c in consts)
        self.has_d65 = any(c.form == "illuminant" for c in consts) or any(
            self.items[s].form == "illuminant" for s in self.bitmaps)
        self._features = {}

    def features(self, reach=None) -> SimpleNamespace:
        """What evaluating a slot among ``reach`` (None: any slot) must trace: the slots
        it reaches through combinators and checkerboards, by kind, the leaf kinds, the
        constants' spectrum bases, whether a D65 factor or bilinear filtering occurs, and
        the combinator levels (see :meth:`_eval_node`). Cached per ``reach``."""
        key = frozenset(int(r) for r in reach) if reach else None     # () as None: no lane can be active
        f = self._features.get(key)
        if f is not None:
            return f
        if key is None:
            slots = set(range(len(self.items)))
        else:
            slots, todo = set(), list(key)
            while todo:
                s = todo.pop()
                if s in slots:
                    continue
                slots.add(s)
                t = self.items[s]
                if isinstance(t, Composite):
                    todo.extend(k for k in (t.x, t.y, t.m) if k is not None)
                elif isinstance(t, Checkerboard):
                    todo.extend((t.color0, t.color1))
        by = {k: sorted(s for s in slots if self.kind_of(s) == k)
              for k in (CONSTANT, CHECKERBOARD, BITMAP, COMPOSITE, MESH_ATTRIBUTE, PROCEDURAL, MIPMAP, VOLUME)}
        consts = [self.items[s] for s in by[CONSTANT]]
        composites = by[COMPOSITE]
        depth = max((self.depth_of(s) for s in composites), default=0)
        # Per level d of the descent: the operations of composites of depth <= d and how
        # deep each child role (x, y, m) nests below them, so that a kernel only descends
        # where the scene's trees do (one deep chain costs one extra leaf evaluation per
        # level, not three).
        levels = {}
        for d in range(1, depth + 1):
            cs = [self.items[s] for s in composites if self.depth_of(s) <= d]
            role = lambda r, ops: max([self.depth_of(getattr(c, r)) for c in cs if c.op in ops],  # noqa: E731
                                      default=0)
            levels[d] = ({c.op for c in cs}, role("x", (OP_SCALE, OP_MIX, OP_CHECKER, OP_SQRT)),
                         role("y", (OP_MIX, OP_CHECKER)), role("m", (OP_SCALE, OP_MIX)))
        bases = {c.base for c in consts}
        f = SimpleNamespace(
            leaf_kinds={self.kind_of(s) for s in slots if self.kind_of(s) != COMPOSITE},
            constants=by[CONSTANT], checkers=by[CHECKERBOARD], bitmaps=by[BITMAP], composites=composites,
            mesh_attrs=by[MESH_ATTRIBUTE], procedurals=by[PROCEDURAL], mipmaps=by[MIPMAP], volumes=by[VOLUME],
            n_leaves=len(slots) - len(composites),
            bases=bases, has_sigmoid=BASE_SIGMOID in bases, has_table=BASE_TABLE in bases,
            has_d65=any(c.form == "illuminant" for c in consts) or any(
                self.items[s].form == "illuminant" for s in by[BITMAP]),
            bilinear=any(self.items[s].filter_type == "bilinear" for s in by[BITMAP]),
            depth=depth, levels=levels)
        self._features[key] = f
        return f

    def _value_tables(self):
        """The tables that hold parameter values, built differentiably from them: 4 floats
        per constant and per bitmap texel (3 sigmoid coefficients, scale), read with one
        packet gather (and, in adjoint passes, scatter-added as one packet). Returns
        (ConstantTable or None, BitmapTable or None) with only these filled in."""
        C = B = None
        consts = [self.items[s] for s in self.constants]
        if consts:
            packed = dr.zeros(mi.Float, 4 * len(consts))
            for i, c in enumerate(consts):
                cf, sc = c.coeffs_scale()
                dr.scatter(packed, mi.Array4f(cf[0], cf[1], cf[2], sc), mi.UInt32(i))
            C = ConstantTable(packed=packed)
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
            B = BitmapTable(texel=texels)
        return C, B

    def refreshable(self, tex) -> bool:
        """Whether :meth:`refresh` suffices after ``tex``'s parameters change (constants
        and colour bitmaps; not the raw texels of normal and bump maps)."""
        return isinstance(tex, ConstantSpectrum) or (isinstance(tex, Bitmap) and not tex.needs_raw)

    def refresh(self) -> None:
        """Recompute the value tables from the current parameters, keeping everything else
        :meth:`build` made (slots, kinds, sizes, addressing). Dr.Jit operations only: it
        can run inside ``dr.freeze``."""
        C, B = self._value_tables()
        dr.eval([t for t in (C and C.packed, B and B.texel) if t is not None])
        if C is not None:
            self.tables.constants.packed = C.packed
        if B is not None:
            self.tables.bitmaps.texel = B.texel

    # -- evaluation (inside kernels) ---------------------------------------------------
    @staticmethod
    def _apply_uv(M, uv, i):
        m = [dr.gather(mi.Float, a, i) for a in M]
        return mi.Point2f(m[0] * uv[0] + m[1] * uv[1] + m[2], m[3] * uv[0] + m[4] * uv[1] + m[5])

    def _eval_constant(self, ci, lam, active, illuminant=True, f=None):
        f = f or self.features()
        T = self.tables.constants
        v = mi.Spectrum(1.0)
        t = dr.gather(mi.Array4f, T.packed, ci, active)
        if f.has_sigmoid:
            c = mi.Array3f(t[0], t[1], t[2])
            if f.bases == {BASE_SIGMOID}:
                v = spec.sigmoid_polynomial(c, lam)
            else:
                base = dr.gather(mi.UInt32, T.base, ci, active)
                v = dr.select(base == BASE_SIGMOID, spec.sigmoid_polynomial(c, lam), v)
        if f.has_table:
            base = dr.gather(mi.UInt32, T.base, ci, active)
            off = dr.gather(mi.UInt32, T.tab_offset, ci, active)
            tab = mi.Spectrum([self._lerp_1nm(T.tab, off, lam[k], active & (base == BASE_TABLE))
                               for k in range(spec.N_WAVELENGTHS)])
            v = dr.select(base == BASE_TABLE, tab, v)
        if illuminant and f.has_d65 and f.constants:
            v = dr.select(dr.gather(mi.Bool, T.d65, ci, active), v * spec.d65(lam), v)
        return v * t[3]

    @staticmethod
    def _lerp_1nm(table, off, l, active):
        t = dr.clip(l - spec.LAMBDA_MIN, 0.0, TAB_N - 1.0)
        i0 = dr.minimum(mi.UInt32(t), TAB_N - 2)
        w = t - mi.Float(i0)
        a = dr.gather(mi.Float, table, off + i0, active)
        b = dr.gather(mi.Float, table, off + i0 + 1, active)
        return dr.fma(w, b - a, a)

    def _bitmap_lookup(self, bi, uv, active):
        """Addressing shared by bitmap lookups: (texel index function (dx, dy) -> index into
        the texel pools, bilinear weights, bilinear mask, resolution, to_uv coefficients)."""
        T = self.tables.bitmaps
        size = dr.gather(mi.Array2u, T.size, bi, active)
        off = dr.gather(mi.UInt32, T.offset, bi, active)
        wrap = dr.gather(mi.UInt32, T.wrap, bi, active)
        bil = dr.gather(mi.Bool, T.bilinear, bi, active)
        A = [dr.gather(mi.Float, a, bi, active) for a in T.to_uv]
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

    def _eval_bitmap(self, bi, uv, lam, active, illuminant=True, f=None):
        f = f or self.features()
        T = self.tables.bitmaps
        index, w1, bil, _, _ = self._bitmap_lookup(bi, uv, active)

        def texel(dx, dy):
            k = index(dx, dy)
            t = dr.gather(mi.Array4f, T.texel, k, active)
            return spec.sigmoid_polynomial(mi.Array3f(t[0], t[1], t[2]), lam) * t[3]

        v = texel(0, 0)
        if f.bilinear:
            v10, v01, v11 = texel(1, 0), texel(0, 1), texel(1, 1)
            v0 = dr.fma(w1.x, v10 - v, v)
            v1 = dr.fma(w1.x, v11 - v01, v01)
            v = dr.select(bil, dr.fma(w1.y, v1 - v0, v0), v)
        if illuminant and f.has_d65:
            v = dr.select(dr.gather(mi.Bool, T.d65, bi, active), v * spec.d65(lam), v)
        return v

    def eval_raw(self, slot, uv, active=True):
        """Raw 3-channel value of bitmap ``slot`` (no colour processing; normal and bump
        maps) and its derivatives w.r.t. u and v: (value, d/du, d/dv)."""
        bi = dr.gather(mi.UInt32, self.tables.slot_index, mi.UInt32(slot), active)
        index, w, bil, res, A = self._bitmap_lookup(bi, uv, active)

        def texel(dx, dy):
            return dr.gather(mi.Array3f, self.tables.bitmaps.raw, index(dx, dy), active)

        v00, v10, v01, v11 = texel(0, 0), texel(1, 0), texel(0, 1), texel(1, 1)
        v0 = dr.fma(w.x, v10 - v00, v00)
        v1 = dr.fma(w.x, v11 - v01, v01)
        v = dr.select(bil, dr.fma(w.y, v1 - v0, v0), v00)
        gs = dr.select(bil, ((1.0 - w.y) * (v10 - v00) + w.y * (v11 - v01)) * res.x, 0.0)
        gt = dr.select(bil, ((1.0 - w.x) * (v01 - v00) + w.x * (v11 - v10)) * res.y, 0.0)
        # Chain rule through to_uv (st = A uv + b).
        return v, A[0] * gs + A[3] * gt, A[1] * gs + A[4] * gt

    # Most constant emitter spectra fixed per camera sample (more would cost more per
    # sample than their lookups per vertex save).
    MAX_FIXED = 4

    def fix_per_sample(self, lam: mi.Spectrum, slots) -> None:
        """Evaluate the constant illuminant textures among ``slots`` (the lights' emitted
        spectra) at a pass's wavelengths ``lam`` once, before the integrator's loop: they
        depend on the wavelengths only, which a path keeps at every vertex, and a light's
        spectrum is looked up at each bounce (emission found and next-event estimation),
        each time a gather and a sigmoid per wavelength. They join the values fixed per
        sample (``spectrum.fix``, under their slots), which :meth:`eval` returns for these
        wavelengths until :meth:`release_per_sample`. Not where the constants carry
        derivatives (the derivative passes evaluate them attached, inside the loop)."""
        self.release_per_sample()
        slots = sorted(s for s in set(slots) if self.kind_of(s) == CONSTANT)
        # (the AD index: under dr.suspend_grad, where passes are traced, grad_enabled is False)
        if not slots or len(slots) > self.MAX_FIXED or self.tables.constants.packed.index_ad != 0:
            return
        spec.fix(lam, {s: self._eval_leaf(mi.UInt32(s), mi.Point2f(0.0), lam, mi.Bool(True), True, None,
                                          self.features((s,))) for s in slots})

    def release_per_sample(self) -> None:
        """Drop the emitter spectra :meth:`fix_per_sample` fixed (D65 stays)."""
        spec.release()

    def _fixed_value(self, slot, lam, reach):
        """The value :meth:`fix_per_sample` fixed for ``slot`` (one of ``reach``) at
        wavelengths ``lam``, or None."""
        vals = spec.fixed_for(lam) if reach else None
        if vals is None or not all(int(r) in vals for r in reach):
            return None
        reach = sorted(int(r) for r in reach)
        v = vals[reach[-1]]
        for r in reach[-2::-1]:
            v = dr.select(slot == r, vals[r], v)
        return mi.Spectrum(v)

    def eval(self, slot, uv, lam: mi.Spectrum, active=True, illuminant=True, reach=None) -> mi.Spectrum:
        """Spectrum of texture ``slot`` at ``uv``: surface coordinates, or the surface
        interaction (BSDFs pass ``ctx.si``: ``mesh_attribute`` textures need the hit; they
        are 0 at plain coordinates). Callers that can only reach non-illuminant textures
        (reflectances) pass ``illuminant=False`` to keep the D65 lookup out of their kernels.
        ``reach``: the slots ``slot`` can hold (Python ints), or None for any: only what
        those slots use is traced (:meth:`features`)."""
        slot = mi.UInt32(slot)
        if illuminant:
            v = self._fixed_value(slot, lam, reach)
            if v is not None:
                return v
        si = uv if isinstance(uv, mi.SurfaceInteraction3f) else None
        uv = si.uv if si is not None else uv
        f = self.features(reach)
        if not f.composites:
            return self._eval_leaf(slot, uv, lam, active, illuminant, si, f)
        return self._eval_node(slot, uv, lam, mi.Bool(active), illuminant, f.depth, si, f)

    def _eval_node(self, slot, uv, lam, active, illuminant, depth, si=None, f=None):
        """Evaluate ``slot`` whose combinator nesting is at most ``depth`` levels: at each
        level a composite lane evaluates its children one level down, any other lane
        passes its own (leaf) slot down as the first child."""
        if depth == 0:
            return self._eval_leaf(slot, uv, lam, active, illuminant, si, f)
        T = self.tables.composites
        ops, dx, dy, dm = f.levels[depth]
        comp = active & (dr.gather(mi.UInt32, self.tables.slot_kind, slot, active) == COMPOSITE)
        ni = dr.gather(mi.UInt32, self.tables.slot_index, slot, comp)
        op = dr.gather(mi.UInt32, T.op, ni, comp) if len(ops) > 1 else mi.UInt32(next(iter(ops)))
        x_slot = dr.select(comp, dr.gather(mi.UInt32, T.x, ni, comp), slot)
        x = self._eval_node(x_slot, uv, lam, active, illuminant, dx, si, f)
        result = x
        if ops & {OP_SCALE, OP_MIX}:
            uses_m = comp & (op != OP_CHECKER)
            m = self._eval_node(dr.gather(mi.UInt32, T.m, ni, uses_m), uv, lam, uses_m, illuminant, dm, si, f)
        if ops & {OP_MIX, OP_CHECKER}:
            uses_y = comp & (op != OP_SCALE)
            y = self._eval_node(dr.gather(mi.UInt32, T.y, ni, uses_y), uv, lam, uses_y, illuminant, dy, si, f)
        if OP_SCALE in ops:
            result = dr.select(comp & (op == OP_SCALE), x * m, result)
        if OP_MIX in ops:
            result = dr.select(comp & (op == OP_MIX), dr.fma(m, y - x, x), result)
        if OP_SQRT in ops:
            result = dr.select(comp & (op == OP_SQRT), dr.sqrt(dr.maximum(x, 0.0)), result)
        if OP_CHECKER in ops:
            is_ck = comp & (op == OP_CHECKER)
            st = self._apply_uv(T.to_uv, uv, ni)
            frac = st - dr.floor(st)
            second = (frac.x > 0.5) != (frac.y > 0.5)
            result = dr.select(is_ck & second, y, result)
        return result

    def _eval_leaf(self, slot, uv, lam, active, illuminant, si=None, f=None):
        """A constant, checkerboard (of constants), bitmap, mesh-attribute, procedural,
        MIP-mapped or volume slot."""
        f = f or self.features()
        T = self.tables
        if len(f.leaf_kinds) == 1:      # the kind of every lane (inactive lanes do not matter)
            kind = mi.UInt32(next(iter(f.leaf_kinds)))
        else:
            kind = dr.gather(mi.UInt32, T.slot_kind, slot, active)
        # With constants only (in the whole set), slots are constant-table indices already.
        only_constants = not (self.checkers or self.bitmaps or self.composites or self.mesh_attrs
                                or self.procedurals or self.mipmaps or self.volumes)
        idx = slot if only_constants else dr.gather(mi.UInt32, T.slot_index, slot, active)
        result = mi.Spectrum(0.0)
        if f.constants:
            ci = idx
            if f.checkers:
                is_ck = active & (kind == CHECKERBOARD)
                st = self._apply_uv(T.checkers.to_uv, uv, idx)
                frac = st - dr.floor(st)
                same = (frac.x > 0.5) == (frac.y > 0.5)
                c0 = dr.gather(mi.UInt32, T.checkers.color0, idx, is_ck)
                c1 = dr.gather(mi.UInt32, T.checkers.color1, idx, is_ck)
                ci = dr.select(is_ck, dr.select(same, c0, c1), idx)
            on = active & (kind != BITMAP)
            for k, lst in ((MESH_ATTRIBUTE, f.mesh_attrs), (PROCEDURAL, f.procedurals), (MIPMAP, f.mipmaps),
                           (VOLUME, f.volumes)):
                if lst:
                    on &= kind != k
            result = self._eval_constant(ci, lam, on, illuminant, f)
        if f.bitmaps:
            is_bm = active & (kind == BITMAP)
            if len(f.bitmaps) < f.n_leaves and dispatch.branching():
                # A symbolic conditional: vector packets with no bitmap lane skip the
                # lookup (four texel spectra), instead of computing and discarding it.
                result = dr.if_stmt(
                    (idx, uv, lam, is_bm, result), is_bm,
                    lambda i, u, l, m, r: mi.Spectrum(self._eval_bitmap(i, u, l, m, illuminant, f)),
                    lambda i, u, l, m, r: r, label="bitmap texture")
            else:
                result = dr.select(is_bm, self._eval_bitmap(idx, uv, lam, is_bm, illuminant, f), result)
        if f.procedurals:
            is_pr = active & (kind == PROCEDURAL)
            result = dr.select(is_pr, procedural.evaluate(self, idx, uv, si, lam, is_pr), result)
        if f.mipmaps:
            is_mm = active & (kind == MIPMAP)
            result = dr.select(is_mm, mipmap.evaluate(self, idx, uv, si, lam, is_mm, illuminant), result)
        if f.volumes:
            is_vo = active & (kind == VOLUME)
            result = dr.select(is_vo, volume.evaluate(self, idx, uv, si, lam, is_vo), result)
        if f.mesh_attrs and self.mesh_data and si is not None:   # elsewhere mesh attributes are 0
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


def _uv_rows(items) -> list:
    """The six ``to_uv`` rows of a kind's instances (see :mod:`.tables`)."""
    return [mi.Float([t.to_uv[r, k] for t in items]) for r in range(2) for k in (0, 1, 3)]
