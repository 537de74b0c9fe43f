"""The Dr.Jit tables of a scene's textures, one structure of arrays per kind (indexed by
a slot's index within its kind), built by :meth:`pbr.textures.TextureSet.build`.

Dataclasses, so that ``dr.freeze`` can traverse them and a values-only refresh can rebind
``ConstantTable.packed`` and ``BitmapTable.texel``. Per-instance 2x3 texture-coordinate
transforms (``to_uv``) are six flat ``mi.Float`` rows: (a, b, c, d, e, f) with
``s = a u + b v + c``, ``t = d u + e v + f``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class ConstantTable:
    packed: object = None       # 4 floats per constant: sigmoid coefficients, scale (differentiable)
    base: object = None         # BASE_ONE / BASE_SIGMOID / BASE_TABLE
    d65: object = None          # illuminant form: times D65
    tab_offset: object = None   # offset of a tabulated spectrum in ``tab``
    tab: object = None          # 1 nm tables of tabulated spectra, concatenated (None: none)


@dataclass
class CheckerTable:
    color0: object = None       # constant-table indices of the two colours
    color1: object = None
    to_uv: object = None        # six rows


@dataclass
class BitmapTable:
    texel: object = None        # 4 floats per texel: sigmoid coefficients, scale (differentiable)
    offset: object = None       # first texel of each bitmap in ``texel``
    size: object = None         # (width, height)
    bilinear: object = None
    wrap: object = None         # 0 repeat, 1 mirror, 2 clamp
    d65: object = None
    to_uv: object = None        # six rows
    raw: object = None          # raw 3-channel texels of normal/bump maps (None: none)


@dataclass
class CompositeTable:
    op: object = None           # OP_SCALE / OP_MIX / OP_CHECKER / OP_SQRT
    x: object = None            # child slots
    y: object = None
    m: object = None
    to_uv: object = None        # six rows (checkerboards of non-constant colours)


@dataclass
class MeshAttributeTable:
    coeffs: object = None       # per attribute row: sigmoid coefficients and scale
    scale: object = None
    key: object = None          # registry id of a mesh -> its index (NONE: not read)
    rec: object = None          # (texture, mesh) -> record (NONE: the mesh lacks it)
    voff: object = None         # record -> its first row
    vertex: object = None       # record -> per-vertex (else per-face)
    foff: object = None         # per mesh: first triangle, first vertex, and the
    poff: object = None         # triangles and positions of all meshes (vertex attributes)
    faces: object = None
    pos: object = None


@dataclass
class ProceduralTable:
    pattern: object = None      # pattern id (procedural.FBM, ...)
    mapping: object = None      # 2D mapping id (procedural.MAP_UV, ...)
    octaves: object = None
    omega: object = None        # pbrt-v4's 'roughness'
    scale: object = None
    variation: object = None
    m: object = None            # texture-from-world, 12 rows (3x4)
    uv: object = None           # su, sv, du, dv (planar: du, dv)
    v1: object = None           # planar axes (DIRECTION: v1 is the world direction)
    v2: object = None
    perm: object = None         # the noise permutation table (512 entries)
    marble: object = None       # marble's colour spline (3 Floats)


@dataclass
class MipmapTable:
    texel: object = None        # RGB texels of every level of every image (Array3f)
    level_offset: object = None  # per (image, level): first texel
    level_size: object = None   # per (image, level): (width, height)
    first_level: object = None  # per image: index of its level 0 in level_offset
    n_levels: object = None
    filter: object = None       # 0 point, 1 bilinear, 2 trilinear, 3 ewa
    wrap: object = None         # 0 repeat, 1 black, 2 clamp, 3 octahedralsphere (as repeat)
    max_aniso: object = None
    scale: object = None
    invert: object = None
    form: object = None         # 0 albedo, 1 unbounded, 2 illuminant
    mapping: object = None      # a ProceduralTable of the mappings (mapping, m, uv, v1, v2)
    ewa_lut: object = None      # pbrt-v4's Gaussian filter weights


@dataclass
class VolumeTable:
    grids: object = None        # a grid.GridTable, grid i = volume texture i
    m: object = None            # grid-from-world, 12 rows (3x4)


@dataclass
class TextureTables:
    slot_kind: object = None    # slot -> kind
    slot_index: object = None   # slot -> index within its kind's table
    constants: ConstantTable | None = None
    checkers: CheckerTable | None = None
    bitmaps: BitmapTable | None = None
    composites: CompositeTable | None = None
    mesh_attributes: MeshAttributeTable | None = None
    procedurals: ProceduralTable | None = None
    mipmaps: MipmapTable | None = None
    volumes: VolumeTable | None = None
