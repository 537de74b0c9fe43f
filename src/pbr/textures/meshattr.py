"""Mesh attributes and Mitsuba's ``mesh_attribute`` texture.

A mesh attribute is a per-vertex (``vertex_*``) or per-face (``face_*``) record of 1 or 3
values stored with a mesh, e.g. ``vertex_color`` or ``face_color``. The ``mesh_attribute``
texture (parameters ``name`` and ``scale``) evaluates one at the hit point: per-face
values are constant over a triangle; per-vertex ones are interpolated with the hit's
barycentric coordinates.

Reading: PLY properties become attributes by the grouping rules of Mitsuba's PLY loader
(``r g b [a]`` or ``red green blue [alpha]`` -> ``*_color``; contiguous properties
``<prefix>_<x y z | r g b | 0 1 2 | 1 2 3>`` -> ``*_<prefix>``, with ``_color`` appended for
the ``r g b`` postfixes; single ``<prefix>_x`` -> a 1-channel attribute; integer values
are converted to float without normalisation, as Mitsuba does). OBJ vertex colours
(``v x y z r g b``), which trimesh reads but Mitsuba's OBJ loader ignores, become
``vertex_color``. The attributes are added to the ``mi.Mesh`` pbr builds, holding the
file's values (Mitsuba's own loaders store sigmoid coefficients of colours instead).

Evaluation (pbr's own tables; Mitsuba is only asked for the hit): a hit's mesh is found
from the Dr.Jit registry id of ``si.shape``, its triangle is ``si.prim_index``, and the
barycentric coordinates are solved from ``si.p`` and the triangle's corners. As in
Mitsuba's spectral variants, 3-channel values are upsampled per vertex (Jakob-Hanika,
albedo or unbounded form as for bitmaps) when the tables are built, and the spectra of a
triangle's three vertices are interpolated. The values are parameters of the shape
(``<shape id>.vertex_color`` in :func:`pbr.traverse`, as in ``mi.traverse``), so gradients
reach them through the tables.
"""

from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..plugins.props import SceneError
from .kinds import MeshAttribute
from .tables import MeshAttributeTable

NONE = 0xFFFFFFFF
# Postfix categories of grouped PLY properties: xyzw, rgba, 0123, 1234 (Mitsuba's ply.h).
_POSTFIXES = ("xr01", "yg12", "zb23", "wa34")
_RESERVED = {"vertex": {"x", "y", "z", "nx", "ny", "nz", "u", "v"},
             "face": {"vertex_index", "vertex_indices"}}
# Mesh buffers that mi.traverse lists beside the attributes.
_BUILTIN = {"vertex_positions", "vertex_normals", "vertex_texcoords", "faces"}


class MeshData:
    """The attributes of one mesh shape that textures read, and its triangles: the owner
    of the ``<shape id>.<attribute>`` parameters."""

    def __init__(self, mesh: "mi.Mesh", path: str, names):
        p = mi.traverse(mesh)
        self.path = path
        self.registry_id = int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(mesh))[0])
        self.faces = np.array(p["faces"], dtype=np.uint32).reshape(-1, 3)
        self.positions = np.array(p["vertex_positions"], dtype=np.float32).reshape(-1, 3)
        self.params = {n: mi.Float(p[n]) for n in names}

    def rows(self, name: str) -> int:
        return len(self.positions) if name.startswith("vertex_") else len(self.faces)


# ------------------------------------------------------------------------ reading files

def _group_ply(element: str, props: dict, where: str) -> list[tuple[str, list[str]]]:
    """Mitsuba's grouping of a PLY element's properties into attributes: a list of
    (attribute name, property names)."""
    kind = element + "_"
    scalar = [n for n, t in props.items() if "," not in str(t)]   # list properties are skipped
    names = set(scalar)
    groups, reserved = [], set(_RESERVED[element]) | {"r", "g", "b", "a"}
    colour = next((c for c in (("r", "g", "b", "a"), ("red", "green", "blue", "alpha"))
                   if set(c[:3]) <= names), None)
    if colour is not None:
        fields = [c for c in colour if c in names]
        groups.append((kind + "color", fields))
        reserved |= set(fields)
    encountered, prefix, cat, fields = set(), None, 0, []

    def flush():
        if len(fields) in (1, 3):
            groups.append((kind + prefix + ("_color" if cat == 1 else ""), list(fields)))
            encountered.add(prefix)
        else:
            warnings.warn(f"{where}: PLY attribute {kind + prefix!r} has {len(fields)} fields "
                          "(1 or 3 are read); ignored")

    skip = None
    for n in scalar:
        if n in reserved or (skip is not None and n.startswith(skip)):
            continue
        skip = None
        pre, sep, post = n.rpartition("_")
        if not sep or len(post) != 1:
            if prefix is not None:
                flush()
                prefix = None
            continue   # Mitsuba ignores properties without a one-letter postfix
        if prefix is not None and pre != prefix:
            flush()
            prefix = None
        if prefix is None:
            if pre in encountered or post not in _POSTFIXES[0]:
                skip = pre if pre in encountered else None
                continue
            prefix, cat, fields = pre, _POSTFIXES[0].index(post), [n]
        elif len(fields) < 4 and post == _POSTFIXES[len(fields)][cat]:
            fields.append(n)
        else:   # a broken postfix sequence: Mitsuba drops the attribute
            prefix, skip = None, pre
    if prefix is not None:
        flush()
    return groups


def file_attributes(tmesh, file_type: str, where: str) -> dict[str, np.ndarray]:
    """The attributes of a mesh read by trimesh: name -> float32 (rows, channels)."""
    out = {}
    if file_type == "ply":
        raw = getattr(tmesh, "metadata", {}).get("_ply_raw", {})
        counts = {"vertex": len(tmesh.vertices), "face": len(tmesh.faces)}
        for element in ("vertex", "face"):
            el = raw.get(element)
            if not el:
                continue
            for name, fields in _group_ply(element, el["properties"], where):
                cols = [np.asarray(el["data"][f]) for f in fields]
                if any(np.issubdtype(c.dtype, np.integer) for c in cols) and len(cols) >= 3:
                    warnings.warn(f"{where}: mesh attribute {name!r} has integer fields; colours are "
                                  "expected in [0, 1] (values are used unnormalised, as in Mitsuba)")
                vals = np.stack(cols, axis=1).astype(np.float32)
                if len(vals) != counts[element]:
                    warnings.warn(f"{where}: attribute {name!r} has {len(vals)} rows but the mesh has "
                                  f"{counts[element]} {element}s (re-indexed for per-corner texture "
                                  "coordinates, or polygons split into triangles); ignored")
                    continue
                out[name] = vals
    elif getattr(tmesh.visual, "kind", None) == "vertex":
        out["vertex_color"] = np.asarray(tmesh.visual.vertex_colors, np.float32)[:, :3] / 255.0
    return out


def attach(mesh: "mi.Mesh", attributes: dict[str, np.ndarray]) -> None:
    """Add ``attributes`` to ``mesh`` holding the given values (``add_attribute`` alone
    would turn colours into sigmoid coefficients in spectral variants)."""
    if not attributes:
        return
    for name, vals in attributes.items():
        mesh.add_attribute(name, vals.shape[1], [0.0] * vals.size)
    p = mi.traverse(mesh)
    for name, vals in attributes.items():
        p[name] = mi.Float(vals.ravel())
    p.update()


def attribute_channels(mesh) -> dict[str, int]:
    """Attribute name -> channel count of a ``mi.Mesh``."""
    p = mi.traverse(mesh)
    counts = {"vertex_": mesh.vertex_count(), "face_": mesh.face_count()}
    out = {}
    for k in p.keys():
        if k in _BUILTIN or not k.startswith(("vertex_", "face_")):
            continue
        rows = counts["vertex_" if k.startswith("vertex_") else "face_"]
        out[k] = dr.width(p[k]) // max(rows, 1)
    return out


# -------------------------------------------------------------------- texture loading

def load(p, form: str) -> MeshAttribute:
    """A ``mesh_attribute`` texture from its Props ``p``."""
    name = p.string("name")
    if not name.startswith(("vertex_", "face_")):
        raise p.error("name", f"a mesh attribute name starts with 'vertex_' or 'face_', got {name!r}")
    scale = p.float("scale", 1.0)
    p.finish()
    if form == "illuminant":
        raise p.error(None, "mesh_attribute is supported in BSDF parameters, not (yet) in emitters")
    return MeshAttribute(p.path, name, scale, form)


def bind(textures, shapes, shape_bsdf, shape_ids, bsdf_textures) -> None:
    """Find the meshes each ``mesh_attribute`` texture is evaluated on (the shapes whose
    BSDF reads it) and check that they carry the attribute with 1 or 3 channels."""
    textures.mesh_data, textures.mesh_uses, textures.mesh_geometry = [], [], {}
    slots = set(textures.mesh_attrs)
    if not slots:
        return
    for s, (shape, b) in enumerate(zip(shapes, shape_bsdf)):
        used = sorted(slots & set(bsdf_textures.get(b, ())))
        if not used:
            continue
        if not isinstance(shape, mi.Mesh):
            kind = shape.get("type") if isinstance(shape, dict) else type(shape).__name__
            tex = textures.items[used[0]]
            raise SceneError(f"{tex.key}: mesh_attribute {tex.name!r} is evaluated on shape "
                             f"{shape_ids[s]!r}, a {kind!r}: it needs a mesh (ply, obj)")
        channels = attribute_channels(shape)
        for slot in used:
            tex = textures.items[slot]
            if tex.name not in channels:
                have = ", ".join(sorted(channels)) or "none"
                raise SceneError(f"{tex.key}.name: shape {shape_ids[s]!r} has no mesh attribute "
                                 f"{tex.name!r} (it has: {have})")
            if channels[tex.name] not in (1, 3):
                raise SceneError(f"{tex.key}.name: mesh attribute {tex.name!r} of shape {shape_ids[s]!r} "
                                 f"has {channels[tex.name]} channels; mesh_attribute reads 1 or 3")
        names = sorted({textures.items[slot].name for slot in used})
        textures.mesh_data.append(MeshData(shape, shape_ids[s], names))
        textures.mesh_uses.append(used)
    data = textures.mesh_data
    if any(textures.items[i].name.startswith("vertex_") for u in textures.mesh_uses for i in u):
        # Triangles and vertex positions of all meshes (for barycentric coordinates).
        pos = np.concatenate([d.positions for d in data])
        textures.mesh_geometry = {
            "foff": mi.UInt32(np.cumsum([0] + [len(d.faces) for d in data])[:-1].astype(np.uint32)),
            "poff": mi.UInt32(np.cumsum([0] + [len(d.positions) for d in data])[:-1].astype(np.uint32)),
            "faces": mi.UInt32(np.concatenate([d.faces for d in data]).ravel()),
            "pos": mi.Array3f(pos[:, 0], pos[:, 1], pos[:, 2])}


# ------------------------------------------------------------------------- tables

def build_tables(textures, index) -> MeshAttributeTable | None:
    """Tables of the ``mesh_attribute`` textures: per (texture, mesh) record the offset of
    its upsampled rows (rebuilt from the parameters), and the meshes' triangles (from
    :func:`bind`); None without mesh attributes."""
    data, n_tex = textures.mesh_data, len(textures.mesh_attrs)
    textures.ma_vertex = textures.ma_face = False
    if not data:
        return None
    n_mesh = len(data)
    key = np.full(max(d.registry_id for d in data) + 1, NONE, np.uint32)
    rec = np.full(n_tex * n_mesh, NONE, np.uint32)
    voff, vertex, total, jobs = [], [], 0, []
    for m, (d, used) in enumerate(zip(data, textures.mesh_uses)):
        key[d.registry_id] = m
        for slot in used:
            tex = textures.items[slot]
            rec[index[slot] * n_mesh + m] = len(voff)
            voff.append(total)
            vertex.append(tex.name.startswith("vertex_"))
            jobs.append((tex, d.params[tex.name], d.rows(tex.name), total))
            total += d.rows(tex.name)
    coeffs, scales = dr.zeros(mi.Array3f, total), dr.zeros(mi.Float, total)
    for tex, vals, rows, off in jobs:
        c, s = _upsample(vals, rows, tex.form)
        idx = dr.arange(mi.UInt32, rows)
        dr.scatter(coeffs, c, idx + off)
        dr.scatter(scales, s * tex.params["scale"], idx + off)
    textures.ma_vertex, textures.ma_face = any(vertex), not all(vertex)
    return MeshAttributeTable(coeffs=coeffs, scale=scales, key=mi.UInt32(key), rec=mi.UInt32(rec),
                              voff=mi.UInt32(voff), vertex=mi.Bool(vertex), **textures.mesh_geometry)


def _upsample(vals: mi.Float, rows: int, form: str):
    """(sigmoid coefficients, scale) per row: 3-channel rows as RGB (``form``), 1-channel
    rows as a constant (S = 1/2 with scale 2v)."""
    channels = dr.width(vals) // max(rows, 1)
    idx = dr.arange(mi.UInt32, rows)
    if channels == 1:
        return dr.zeros(mi.Array3f, rows), 2.0 * dr.gather(mi.Float, vals, idx)
    rgb = mi.Color3f(*[dr.gather(mi.Float, vals, idx * 3 + k) for k in range(3)])
    if form == "albedo":
        return spec.rgb_to_coeffs(rgb), dr.full(mi.Float, 1.0, rows)
    return spec.rgb_unbounded(rgb)


# --------------------------------------------------------------------- evaluation

def barycentric(p, p0, p1, p2):
    """Barycentric coordinates (b0, b1, b2) of ``p`` in the triangle (p0, p1, p2)."""
    e1, e2, d = p1 - p0, p2 - p0, p - p0
    d11, d12, d22 = dr.dot(e1, e1), dr.dot(e1, e2), dr.dot(e2, e2)
    d1, d2 = dr.dot(d, e1), dr.dot(d, e2)
    inv = dr.rcp(d11 * d22 - d12 * d12)
    b1 = (d22 * d1 - d12 * d2) * inv
    b2 = (d11 * d2 - d12 * d1) * inv
    return 1.0 - b1 - b2, b1, b2


def evaluate(textures, ai, si, lam, active) -> mi.Spectrum:
    """Spectrum of mesh-attribute texture ``ai`` (index in its table) at the hit ``si``;
    0 where the hit shape does not carry it (or without a hit). The triangle lookup does
    not depend on the texture, so that the lookups of several textures at one hit are
    shared by the kernel (common subexpressions)."""
    T = textures.tables.mesh_attributes
    reg = dr.reinterpret_array(mi.UInt32, si.shape)
    known = reg < dr.width(T.key)
    mesh = dr.gather(mi.UInt32, T.key, reg, known)
    on_mesh = known & (mesh != NONE)
    rec = dr.gather(mi.UInt32, T.rec, ai * len(textures.mesh_data) + mesh, active & on_mesh)
    ok = active & on_mesh & (rec != NONE)
    off = dr.gather(mi.UInt32, T.voff, rec, ok)
    rows, weights = [off + si.prim_index], [mi.Float(1.0)]
    if textures.ma_vertex:
        first = dr.gather(mi.UInt32, T.foff, mesh, on_mesh) + si.prim_index
        base = dr.gather(mi.UInt32, T.poff, mesh, on_mesh)
        corner = [dr.gather(mi.UInt32, T.faces, first * 3 + k, on_mesh) for k in range(3)]
        p = [dr.gather(mi.Array3f, T.pos, base + c, on_mesh) for c in corner]
        b = barycentric(mi.Array3f(si.p), *p)
        if textures.ma_face:   # per-face rows: the first "corner" with weight 1
            vert = dr.gather(mi.Bool, T.vertex, rec, ok)
            rows = [dr.select(vert, off + corner[0], rows[0])] + [off + c for c in corner[1:]]
            weights = [dr.select(vert, b[0], 1.0), dr.select(vert, b[1], 0.0), dr.select(vert, b[2], 0.0)]
        else:
            rows, weights = [off + c for c in corner], list(b)
    result = mi.Spectrum(0.0)
    for row, w in zip(rows, weights):
        c = dr.gather(mi.Array3f, T.coeffs, row, ok & (w != 0))
        result += w * spec.sigmoid_polynomial(c, lam) * dr.gather(mi.Float, T.scale, row, ok & (w != 0))
    return dr.select(ok, result, 0.0)
