"""pbrt-v4 scene files -> pbr/Mitsuba scene dicts (``to_dict``), so that
``pbr.load_file("scene.pbrt")`` renders them.

The directives are interpreted with pbrt-v4's graphics state: the current transformation
matrix (CTM), named coordinate systems, the attribute stack (``AttributeBegin/End``,
``TransformBegin/End``), ``ReverseOrientation``, the current material, area light and
media, named materials/textures/media, object instances, ``Include`` and ``Import``.
Each pbrt-v4 plugin is mapped to pbr's plugin of the same model, with pbrt-v4's defaults
and units (docs/pbrt.md lists every mapping and what is approximated or left out):

* Cameras: pbrt's camera space is left-handed (x to the right on the image); Mitsuba's
  is right-handed with x to the left, so ``to_world = inverse(CTM) @ Scale(-1, 1, 1)``;
  ``fov`` is the field of view of the shorter image axis (Mitsuba's ``fov_axis``
  'smaller'). A moving camera gets ``to_world_end`` and ``transform_times``; so do moving
  shapes (built in their object space) and object instances (``ActiveTransform``).
* Filters, films, cameras and textures that pbr registers under pbrt-v4's names
  (``gaussian`` of radius 1.5, ``mitchell``, ``sinc``, ``triangle``; ``rgb`` with its
  pixel sensor, ``gbuffer``, ``spectral``; ``spherical``, ``realistic``; ``imagemap``,
  ``checkerboard``, ``dots``, ``fbm``, ...) take pbrt-v4's parameters; Mitsuba's plugin
  is used where it gives the same image. ``mitsuba=True`` keeps to Mitsuba 3's plugins.
* Lights: pbrt-v4 divides every light's spectrum by its luminance
  (``SpectrumToPhotometric``) before ``scale``/``power``: RGB values are already of unit
  luminance in pbr (rgb times a D65 of unit luminance), other spectra (``blackbody``,
  sampled) are divided by their luminance here.
* Meshes are written to PLY files (``mesh_dir``) in world space, with pbrt-v4's
  orientation: a triangle's normal follows its vertex normals if it has them, else its
  winding, flipped by ``ReverseOrientation`` and by transforms that swap handedness.

Errors raise :class:`~pbr.scene.xml.XMLError` naming ``file:line`` and the directive.
With ``approximate=True`` features pbr lacks are replaced by the nearest supported one
and listed in the dict's ``notes`` (:func:`convert`) instead of raising.
"""
from __future__ import annotations

import gzip
import hashlib
import math
import os
import tempfile

import numpy as np

from .. import backend
from ..bsdfs import BSDF_TYPES
from ..cameras import SENSORS
from ..films import FILMS, camera_sensors
from ..integrators import INTEGRATORS
from ..lights import LIGHT_TYPES
from ..lights.goniometric import equal_area_sphere_to_square
from ..media.mediumset import MEDIUM_TYPES
from ..media.presets import MEASURED_SCATTERING, measured_scattering
from ..plugins.props import did_you_mean
from ..spectrum import CIE_Y_INTEGRAL, LAMBDA_MAX, LAMBDA_MIN, SELLMEIER, blackbody, cie_tables_np, xyz_to_srgb
from ..textures import TEXTURE_TYPES
from .pbrt_tokens import Directive, Param, last_of_each, read_directives, resolve
from .xml import XMLError

__all__ = ["to_dict", "convert", "PBRTScene"]


# -- transforms (4x4 numpy, pbrt-v4's conventions) ---------------------------------------

def _translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def _scale(x, y, z):
    return np.diag([x, y, z, 1.0])


def _rotate(angle, axis):
    a = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(a)
    if n == 0:
        raise ValueError("rotation axis is zero")
    x, y, z = a / n
    s, c = math.sin(math.radians(angle)), math.cos(math.radians(angle))
    m = np.eye(4)
    m[:3, :3] = [[x * x + (1 - x * x) * c, x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                 [x * y * (1 - c) + z * s, y * y + (1 - y * y) * c, y * z * (1 - c) - x * s],
                 [x * z * (1 - c) - y * s, y * z * (1 - c) + x * s, z * z + (1 - z * z) * c]]
    return m


def _look_at(pos, look, up):
    """pbrt-v4's ``LookAt``: camera-from-world (the camera looks down +z, y up)."""
    pos, look, up = (np.asarray(v, dtype=np.float64) for v in (pos, look, up))
    d = look - pos
    if np.linalg.norm(d) == 0:
        raise ValueError("'up' and the viewing direction are undefined: eye and look-at point coincide")
    d /= np.linalg.norm(d)
    right = np.cross(up / max(np.linalg.norm(up), 1e-300), d)
    if np.linalg.norm(right) == 0:
        raise ValueError("'up' vector and viewing direction are parallel")
    right /= np.linalg.norm(right)
    new_up = np.cross(d, right)
    world_from_camera = np.eye(4)
    world_from_camera[:3, 0], world_from_camera[:3, 1], world_from_camera[:3, 2] = right, new_up, d
    world_from_camera[:3, 3] = pos
    return np.linalg.inv(world_from_camera)


def _mi_transform(m):
    import mitsuba as mi
    return mi.ScalarTransform4f(np.asarray(m, dtype=np.float64))


# -- spectra -----------------------------------------------------------------------------

# pbrt-v4's named glasses that pbr has no dispersion data for: their IOR near 587.6 nm
# (from pbrt-v4's tables), used under ``approximate``.
_GLASS_ND = {"glass-fk51a": 1.4869, "glass-lasf9": 1.8509, "glass-f5": 1.6732, "glass-f10": 1.7277}

# -- colour spaces ------------------------------------------------------------------------

# pbrt-v4's named RGB colour spaces (RGBColorSpace::Init): the xy chromaticities of the
# red, green and blue primaries and the white of the space's illuminant (D65, and for
# ACES2065-1 pbrt-v4's "illum-acesD60"). pbrt-v4's "dci-p3" is P3-D65 (Display P3), not
# DCI's projector white.
_D65_XY = (0.3127, 0.3290)
COLOR_SPACES = {
    "srgb": ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06), _D65_XY),
    "dci-p3": ((0.68, 0.32), (0.265, 0.690), (0.15, 0.06), _D65_XY),
    "rec2020": ((0.708, 0.292), (0.170, 0.797), (0.131, 0.046), _D65_XY),
    "aces2065-1": ((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.077), (0.32168, 0.33767)),
}
# Bradford's cone-response matrix (the von Kries adaptation is done in its space).
_BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])


def _xy_to_xyz(xy) -> np.ndarray:
    x, y = xy
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def rgb_to_xyz_matrix(name: str) -> np.ndarray:
    """XYZ from linear RGB of colour space ``name``: the primaries' XYZ scaled so that RGB
    (1, 1, 1) is the space's white, of luminance 1 (as pbrt-v4's RGBColorSpace)."""
    *prims, white = COLOR_SPACES[name]
    P = np.stack([_xy_to_xyz(c) for c in prims], axis=1)
    return P * np.linalg.solve(P, _xy_to_xyz(white))


def color_space_to_srgb(name: str, adapt: bool) -> np.ndarray:
    """The 3x3 matrix from linear RGB of pbrt-v4's colour space ``name`` to linear sRGB.
    ``adapt`` (reflectances): the space's white is mapped to D65 by Bradford's adaptation,
    since pbrt-v4 upsamples a reflectance against its space's own illuminant (RGB
    (1, 1, 1) is a flat reflectance in every space); without it (illuminants) the colour
    is kept as it is (ACES2065-1's (1, 1, 1) is light of D60's colour, as pbrt-v4 emits
    its illuminant times the RGB's spectrum). The D65 spaces need no adaptation."""
    m = rgb_to_xyz_matrix(name)
    if adapt and COLOR_SPACES[name][3] != _D65_XY:
        gain = (_BRADFORD @ _xy_to_xyz(_D65_XY)) / (_BRADFORD @ _xy_to_xyz(COLOR_SPACES[name][3]))
        m = np.linalg.solve(_BRADFORD, gain[:, None] * _BRADFORD) @ m
    return np.linalg.solve(rgb_to_xyz_matrix("srgb"), m)


# pbrt-v4's named metal spectra and the Mitsuba IOR data of the same metal.
_METALS = {"Ag": "Ag", "Al": "Al", "Au": "Au", "Cu": "Cu", "CuZn": "CuZn", "MgO": "MgO", "TiO2": "TiO2"}


def luminance_of(values: np.ndarray, lam: np.ndarray) -> float:
    """The luminance of a spectrum sampled at ``lam`` (nm), in pbr's units
    (``int s ybar / int ybar``, the value a constant spectrum of 1 has)."""
    xyz, _ = cie_tables_np()
    grid = LAMBDA_MIN + 5.0 * np.arange(len(xyz))
    s = np.interp(grid, lam, values, left=0.0, right=0.0)
    return float(np.trapezoid(s * xyz[:, 1], grid) / CIE_Y_INTEGRAL)


def _blackbody_luminance(t: float) -> float:
    lam = np.arange(LAMBDA_MIN, LAMBDA_MAX + 1.0)
    return luminance_of(blackbody(lam, t), lam)


def _spectrum_srgb(v) -> np.ndarray:
    """Linear sRGB of a pbr spectrum value as pbrt-v4's ``SpectrumToXYZ`` + sRGB gives it
    (a ``blackbody`` normalised to a peak of 1, as pbrt-v4's ``BlackbodySpectrum``)."""
    if isinstance(v, float):
        return np.full(3, v)
    if v.get("type") == "rgb":
        return np.asarray(v["value"], dtype=np.float64)
    xyz, _ = cie_tables_np()
    grid = LAMBDA_MIN + 5.0 * np.arange(len(xyz))
    if v.get("type") == "blackbody":
        s = blackbody(grid, v["temperature"]) / _blackbody_peak(v["temperature"])
    else:
        pr = np.asarray(v["value"], dtype=np.float64)
        s = np.interp(grid, pr[:, 0], pr[:, 1], left=0.0, right=0.0)
    XYZ = np.trapezoid(s[:, None] * xyz, grid, axis=0) / CIE_Y_INTEGRAL
    return xyz_to_srgb(XYZ)


def _mean_image_luminance(path: str, p) -> float:
    """The mean luminance of an image's pixels (pbrt-v4's k_e factor of an image area
    light given 'power')."""
    from ..image import read_image
    try:
        img = np.asarray(read_image(path), dtype=np.float64)
    except Exception as e:
        raise p.error("filename", f"cannot read image {path!r}: {e}") from None
    if img.ndim == 2:
        img = img[..., None].repeat(3, axis=2)
    return float(np.mean(img[..., :3] @ [0.2126, 0.7152, 0.0722]))


def _blackbody_peak(t: float) -> float:
    """pbrt-v4's BlackbodySpectrum normalisation: Planck's law at its peak (Wien)."""
    return float(blackbody(np.array([2.8977721e-3 / t * 1e9]), t)[0])


def _read_spd(path: str, where: str) -> np.ndarray:
    """A pbrt-v4 spectrum file: (wavelength, value) pairs, ``#`` comments."""
    try:
        with open(path) as f:
            vals = [float(x) for line in f for x in line.split("#", 1)[0].split()]
    except (OSError, ValueError) as e:
        raise XMLError(f"{where}: cannot read spectrum file {path!r}: {e}") from None
    if len(vals) < 2 or len(vals) % 2:
        raise XMLError(f"{where}: spectrum file {path!r} needs (wavelength, value) pairs")
    return np.array(vals).reshape(-1, 2)


# -- mesh files ---------------------------------------------------------------------------

class _TextureLoader:
    """What pbr's texture loading functions read of a scene loader (the reader's texture
    dicts are inline, their file names absolute): a texture set of its own."""

    def __init__(self, base: str):
        from ..textures import TextureSet
        self.textures, self.texture_range, self.base = TextureSet(), None, base

    def resolve_path(self, fname: str, path: str) -> str:
        full = resolve(fname, self.base)
        if not os.path.exists(full):
            raise XMLError(f"{path}: file not found: {fname!r} (looked for {full})")
        return full

    def resolve_ref(self, oid: str, path: str):
        raise XMLError(f"{path}: a reference ({oid!r}) cannot be evaluated here")


def _texture_at(tex: dict, pos, n, uv, base: str) -> np.ndarray:
    """Values of float texture ``tex`` (a pbr texture dict) at points ``pos`` with normals
    ``n`` and coordinates ``uv``, evaluated by pbr's texture set with no pixel footprint
    (the value at the first wavelength, as pbr reads float textures), as an unbounded
    float (a height)."""
    import drjit as dr
    import mitsuba as mi

    from ..textures import load_spectrum
    with backend.pbr_variant():
        loader = _TextureLoader(base)
        slot = load_spectrum(loader, tex, "displacement", emitter=False, unbounded=True, scalar=True)
        T = loader.textures
        T.build()
        si = dr.zeros(mi.SurfaceInteraction3f, len(pos))
        si.p = mi.Point3f(*np.asarray(pos, np.float32).T)
        si.n = mi.Normal3f(*np.asarray(n, np.float32).T)
        si.sh_frame = mi.Frame3f(si.n)
        si.uv = mi.Point2f(*np.asarray(uv, np.float32).T)
        lam = dr.full(mi.Spectrum, 550.0, len(pos))
        active = dr.full(mi.Bool, True, len(pos))
        return np.array(T.eval(slot, si, lam, active, illuminant=False)[0], np.float64)


def write_ply(path: str, p: np.ndarray, f: np.ndarray, n=None, uv=None) -> None:
    """A binary little-endian PLY file that Mitsuba's and pbr's loaders read."""
    cols = [p.astype("<f4")]
    props = ["x", "y", "z"]
    if n is not None:
        cols.append(n.astype("<f4"))
        props += ["nx", "ny", "nz"]
    if uv is not None:
        cols.append(uv.astype("<f4"))
        props += ["u", "v"]
    vert = np.ascontiguousarray(np.hstack(cols), dtype="<f4")
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(p)}"]
    head += [f"property float {c}" for c in props]
    head += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    faces = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = f
    tmp = path + f".{os.getpid()}.tmp"
    with open(tmp, "wb") as out:
        out.write(("\n".join(head) + "\n").encode())
        out.write(vert.tobytes())
        out.write(faces.tobytes())
    os.replace(tmp, path)


def vertex_normals(pos: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """pbrt-v4's TriQuadMesh::ComputeNormals: per vertex, the normalised sum of the unit
    normals cross(p1 - p0, p2 - p1) of its triangles (0 where there are none)."""
    fn = np.cross(pos[tri[:, 1]] - pos[tri[:, 0]], pos[tri[:, 2]] - pos[tri[:, 1]])
    ln = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = np.where(ln > 0, fn / np.where(ln > 0, ln, 1.0), 0.0)
    n = np.zeros_like(pos)
    for k in range(3):
        np.add.at(n, tri[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(ln > 0, n / np.where(ln > 0, ln, 1.0), 0.0)


def refine_mesh(pos, tri, n, uv, render_from_object, max_dist: float):
    """pbrt-v4's TriQuadMesh::Displace tessellation: every triangle with an edge of
    render-space length >= ``max_dist`` is split at the midpoint of its longest edge
    (pbrt-v4's order among equal lengths), until no edge is that long; a midpoint is shared
    by the triangles on both sides of its edge (no cracks), its normal is the normalised
    sum of the edge's, its uv the mean. Done in rounds over all triangles (the recursion's
    result: each split depends on the triangle's own vertices only). Returns (pos, tri, n, uv)."""
    pos, n, uv = [np.asarray(a, np.float64) for a in (pos, n, uv)]
    tri = np.asarray(tri, np.int64).reshape(-1, 3)
    m = np.asarray(render_from_object, np.float64)
    done = []
    split_keys, split_mid = np.zeros(0, np.int64), np.zeros(0, np.int64)   # edges split so far (sorted)
    while len(tri):
        pw = pos @ m[:3, :3].T + m[:3, 3]
        d = np.stack([np.linalg.norm(pw[tri[:, a]] - pw[tri[:, b]], axis=1) for a, b in ((0, 1), (1, 2), (2, 0))], 1)
        small = (d < max_dist).all(axis=1)
        done.append(tri[small])
        tri, d = tri[~small], d[~small]
        if not len(tri):
            break
        # Rotate each triangle so that its longest edge is (v0, v1), as pbrt-v4 orders them.
        first = np.where(d[:, 0] > d[:, 1], np.where(d[:, 0] > d[:, 2], 0, 2), np.where(d[:, 1] > d[:, 2], 1, 2))
        v = np.stack([tri[np.arange(len(tri)), (first + k) % 3] for k in range(3)], axis=1)
        lo, hi = np.minimum(v[:, 0], v[:, 1]), np.maximum(v[:, 0], v[:, 1])
        key = lo * (1 << 31) + hi
        # Midpoints of edges split in an earlier round are reused, new ones added once.
        at = np.minimum(np.searchsorted(split_keys, key), max(len(split_keys) - 1, 0))
        old = (split_keys[at] == key) if len(split_keys) else np.zeros(len(key), bool)
        new_keys, inv = np.unique(key[~old], return_inverse=True)
        a, b = new_keys >> 31, new_keys & ((1 << 31) - 1)
        new_mid = len(pos) + np.arange(len(new_keys))
        pos = np.concatenate([pos, 0.5 * (pos[a] + pos[b])])
        nm = n[a] + n[b]
        n = np.concatenate([n, nm / np.maximum(np.linalg.norm(nm, axis=1, keepdims=True), 1e-30)])
        uv = np.concatenate([uv, 0.5 * (uv[a] + uv[b])])
        vm = np.empty(len(key), np.int64)
        vm[old] = split_mid[at[old]] if len(split_keys) else 0
        vm[~old] = new_mid[inv.reshape(-1)]
        order = np.argsort(np.concatenate([split_keys, new_keys]), kind="stable")
        split_keys = np.concatenate([split_keys, new_keys])[order]
        split_mid = np.concatenate([split_mid, new_mid])[order]
        tri = np.concatenate([np.stack([v[:, 0], vm, v[:, 2]], 1), np.stack([vm, v[:, 1], v[:, 2]], 1)])
    return pos, np.concatenate(done), n, uv


def _read_ply(path: str, where: str):
    """(positions, triangles, normals or None, uv or None) of a PLY file (``.ply.gz`` too)."""
    import io
    import trimesh
    try:
        if path.endswith(".gz"):
            with gzip.open(path, "rb") as fh:
                data = io.BytesIO(fh.read())
            mesh = trimesh.load(data, file_type="ply", process=False, maintain_order=True)
        else:
            mesh = trimesh.load(path, file_type="ply", process=False, maintain_order=True)
    except Exception as e:
        raise XMLError(f"{where}: Shape: cannot read PLY file {path!r}: {e}") from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise XMLError(f"{where}: Shape: {path!r} holds no triangle mesh (a point cloud or several meshes)")
    p = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    has_n = "vertex_normals" in mesh._cache.cache
    n = np.asarray(mesh.vertex_normals, dtype=np.float64) if has_n else None
    vis = getattr(mesh, "visual", None)
    uv = None
    if vis is not None and getattr(vis, "uv", None) is not None and len(vis.uv) == len(p):
        uv = np.asarray(vis.uv, dtype=np.float64)
    return p, f, n, uv


# -- the converter -------------------------------------------------------------------------

class _Params:
    """The parameters of one directive, read by name with pbrt-v4's types and defaults."""

    def __init__(self, d: Directive, conv: "PBRTScene", defaults: list | None = None):
        self.d, self.conv = d, conv
        self.p = {q.name: q for q in d.params}
        for q in defaults or ():          # ``Attribute`` defaults, overridden by the directive's own
            self.p.setdefault(q.name, q)

    def error(self, name: str | None, msg: str) -> XMLError:
        where = self.p[name].where if name in self.p else self.d.where
        key = f"parameter {name!r}: " if name else ""
        return XMLError(f"{where}: {self.d.name}: {key}{msg}")

    def has(self, name):
        return name in self.p

    def _get(self, name, types):
        q = self.p.get(name)
        if q is None:
            return None
        if q.type not in types:
            raise self.error(name, f"expected type {' or '.join(types)}, got {q.type}")
        q.used = True
        return q

    def one(self, name, ptype, default=None):
        q = self._get(name, (ptype,) if ptype != "float" else ("float", "integer"))
        if q is None:
            return default
        if len(q.values) != 1:
            raise self.error(name, f"expected one value, got {len(q.values)}")
        return q.values[0]

    def floats(self, name, default=None):
        q = self._get(name, ("float", "integer"))
        return default if q is None else [float(v) for v in q.values]

    def ints(self, name, default=None):
        q = self._get(name, ("integer",))
        return default if q is None else list(q.values)

    def array(self, name, ptype, width):
        synonyms = {"point3": ("point3", "vector3", "normal"), "normal": ("normal", "vector3"),
                    "point2": ("point2", "vector2", "float")}
        q = self._get(name, synonyms.get(ptype, (ptype,)))
        if q is None:
            return None
        return np.asarray(q.values, dtype=np.float64).reshape(-1, width)

    def vec3(self, name, default):
        q = self._get(name, ("point3", "vector3", "normal"))
        if q is None:
            return np.asarray(default, dtype=np.float64)
        if len(q.values) != 3:
            raise self.error(name, f"expected one 3-vector, got {len(q.values)} values")
        return np.asarray(q.values, dtype=np.float64)

    def string(self, name, default=None):
        return self.one(name, "string", default)

    def bool(self, name, default):
        return self.one(name, "bool", default)

    def texture_name(self, name):
        q = self.p.get(name)
        return q.values[0] if q is not None and q.type == "texture" else None

    def value(self, name, default=None, kind="albedo"):
        """A spectrum or float parameter as a pbr value: a float, an RGB/spectrum dict, a
        named texture, or ``default``. ``kind``: 'albedo' (reflectances), 'unbounded'
        (IORs, coefficients), 'illuminant' (emission: see :meth:`emission`)."""
        q = self.p.get(name)
        if q is None:
            return default
        q.used = True
        return self.conv.spectrum_value(q, self, kind)

    def unused(self):
        return [q for q in self.p.values() if not q.used and q in self.d.params]


class _State:
    """pbrt-v4's graphics state (saved by ``AttributeBegin``)."""

    def __init__(self):
        self.ctm = [np.eye(4), np.eye(4)]       # start and end transforms
        self.active = [True, True]
        self.reverse = False
        self.material = None                    # (kind, key): ('named', name) or ('anon', key)
        self.area = None                        # the AreaLightSource directive
        self.inside = self.outside = None
        self.attributes = {k: [] for k in ("shape", "light", "material", "medium", "texture")}
        self.color_space = "srgb"

    def copy(self):
        s = _State()
        s.ctm = [m.copy() for m in self.ctm]
        s.active = list(self.active)
        s.reverse, s.material, s.area = self.reverse, self.material, self.area
        s.inside, s.outside, s.color_space = self.inside, self.outside, self.color_space
        s.attributes = {k: list(v) for k, v in self.attributes.items()}
        return s


class PBRTScene:
    """Reads a pbrt-v4 scene file into a Mitsuba-style dict (see the module docstring)."""

    def __init__(self, path: str, approximate: bool = False, mesh_dir: str | None = None, overrides=None,
                 skip_missing: bool = False, mitsuba: bool = False):
        self.path = os.path.abspath(path)
        self.mitsuba = mitsuba
        self.skip_missing = skip_missing
        self.base = os.path.dirname(self.path)
        self.approximate = approximate
        self.mesh_dir = mesh_dir or os.path.join(tempfile.gettempdir(), "pbr-pbrt-meshes")
        self.displacement_edge_scale = 1.0      # pbrt-v4's Option "displacementedgescale"
        self.overrides = dict(overrides or {})
        self.notes: list[str] = []
        self.state = _State()
        self.stack: list[tuple[str, _State, str]] = []
        self.named_cs: dict[str, list] = {}
        self.named_materials: dict[str, str] = {}        # name -> key in out
        self.material_uses: dict[str, str] = {}          # NamedMaterial name -> where first used
        self.textures = {"float": {}, "spectrum": {}}
        self.media: dict[str, str] = {}
        self.objects: dict[str, str] = {}                 # instance definitions -> shapegroup key
        self.current_object = None
        self.out = {"type": "scene"}
        self.lines: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.camera = self.film = self.sampler = self.filter = self.integrator = None
        self.camera_medium = None
        self.world = False
        self.including: list[str] = []
        self.default_material = None
        self.transform_times = (0.0, 1.0)
        self.camera_times = (0.0, 1.0)

    # -- bookkeeping -------------------------------------------------------------------
    def note(self, where: str, msg: str) -> None:
        self.notes.append(f"{where}: {msg}")

    def unsupported(self, d: Directive, msg: str) -> None:
        """A feature pbr lacks: an error, or a note under ``approximate``. ``msg`` is
        'feature' or 'feature: substitute is used'."""
        feature, subst = msg, "ignored"
        if msg.endswith(" is used") and ": " in msg:
            feature, subst = msg.rsplit(": ", 1)
        if not self.approximate:
            raise XMLError(f"{d.where}: {d.name}: {feature} is not supported by pbr "
                           f"(with approximate=True: {subst}, noted)")
        self.note(d.where, f"{d.name}: {feature} is not supported: {subst}")

    def missing(self, where: str, directive: str, name: str, full: str) -> None:
        """A file that does not exist: an error, or a note under ``skip_missing`` (the
        caller then leaves the object out or substitutes a constant)."""
        msg = f"file not found: {name!r} (looked for {full})"
        if not self.skip_missing:
            raise XMLError(f"{where}: {directive}: {msg}")
        self.note(where, f"{directive}: {msg}; left out")

    def add(self, prefix: str, v: dict, where: str, key: str | None = None) -> str:
        if key is None:
            self.counts[prefix] = self.counts.get(prefix, 0) + 1
            key = f"{prefix}_{self.counts[prefix]:04d}"
        self.out[key] = v
        self.lines[f"scene.{key}"] = where
        return key

    def ctm(self):
        return self.state.ctm[0]

    def pbr_plugin(self, registry, name: str) -> bool:
        """Whether ``name`` (a pbrt-v4 plugin name) is used as pbr's plugin of that name:
        registered, and the dict is not meant for Mitsuba 3 (``mitsuba=True`` keeps to
        Mitsuba's plugins, substituting or refusing the rest)."""
        return name in registry and not self.mitsuba

    # -- reading -----------------------------------------------------------------------
    def read(self) -> dict:
        self.run_file(self.path)
        if self.stack:
            raise XMLError(f"{self.stack[-1][2]}: {self.stack[-1][0]}Begin: no matching {self.stack[-1][0]}End")
        if self.current_object is not None:
            raise XMLError(f"{self.current_object[1]}: ObjectBegin: no matching ObjectEnd")
        self.finish()
        return self.out

    def run_file(self, path: str, where: str | None = None, extra: list = ()) -> None:
        """Run the directives of ``path``. ``extra``: parameters that follow the
        ``Include`` of this file; pbrt-v4 splices an included file's tokens into the
        including one, so they continue the file's last directive."""
        if path in self.including:
            raise XMLError(f"{where}: Include: {path!r} includes itself")
        if not os.path.exists(path):
            raise XMLError(f"{where or path + ':0'}: file not found: {path!r}")
        self.including.append(path)
        try:
            last = None
            for d in read_directives(path, known=DIRECTIVES):
                if last is not None:
                    self.directive(last)
                last = d
            if extra and last is None:
                raise XMLError(f"{where}: Include: parameters after an empty file {path!r}")
            if last is not None:
                last.params = last_of_each(list(last.params) + list(extra))
                self.directive(last)
        finally:
            self.including.pop()

    def directive(self, d: Directive) -> None:
        h = getattr(self, f"_d_{d.name}", None)
        if h is None:
            raise XMLError(f"{d.where}: unknown directive {d.name!r}{did_you_mean(d.name, DIRECTIVES)}")
        if d.name in WORLD_ONLY and not self.world:
            raise XMLError(f"{d.where}: {d.name}: must come after WorldBegin (the scene description is "
                           "in the world block)")
        for q in d.params:          # pbrt-v4 ties each parameter to the colour space of its directive
            if q.color_space is None:
                q.color_space = self.state.color_space
        try:
            h(d)
        except XMLError:
            raise
        except (ValueError, TypeError, IndexError, KeyError) as e:
            raise XMLError(f"{d.where}: {d.name}: {e}") from None

    def args(self, d: Directive, n: int, kind=str, allow_params=False):
        if len(d.args) != n or not all(isinstance(a, kind) if kind is str else isinstance(a, (int, float))
                                       for a in d.args):
            what = "strings" if kind is str else "numbers"
            raise XMLError(f"{d.where}: {d.name}: expected {n} {what}, got {d.args}")
        if d.params and not allow_params:
            raise XMLError(f"{d.where}: {d.name}: takes no parameters")
        return d.args

    def warn_unused(self, p: _Params, what: str) -> None:
        for q in p.unused():
            self.note(q.where, f"{p.d.name}: parameter {q.name!r} of {what} is not used by pbr")

    # -- transforms --------------------------------------------------------------------
    def _apply(self, f):
        for i in (0, 1):
            if self.state.active[i]:
                self.state.ctm[i] = f(self.state.ctm[i])

    def _d_Identity(self, d):
        self.args(d, 0)
        self._apply(lambda m: np.eye(4))

    def _d_Translate(self, d):
        a = self.args(d, 3, float)
        self._apply(lambda m: m @ _translate(*a))

    def _d_Scale(self, d):
        a = self.args(d, 3, float)
        self._apply(lambda m: m @ _scale(*a))

    def _d_Rotate(self, d):
        a = self.args(d, 4, float)
        r = _rotate(a[0], a[1:])
        self._apply(lambda m: m @ r)

    def _d_LookAt(self, d):
        a = self.args(d, 9, float)
        r = _look_at(a[0:3], a[3:6], a[6:9])
        self._apply(lambda m: m @ r)

    def _matrix(self, d):
        a = self.args(d, 16, float)
        m = np.asarray(a, dtype=np.float64).reshape(4, 4).T   # pbrt lists the matrix column by column
        if abs(np.linalg.det(m)) < 1e-300:
            raise XMLError(f"{d.where}: {d.name}: the matrix is singular")
        return m

    def _d_Transform(self, d):
        m = self._matrix(d)
        self._apply(lambda _: m.copy())

    def _d_ConcatTransform(self, d):
        m = self._matrix(d)
        self._apply(lambda c: c @ m)

    def _d_CoordinateSystem(self, d):
        name, = self.args(d, 1)
        self.named_cs[name] = [m.copy() for m in self.state.ctm]

    def _d_CoordSysTransform(self, d):
        name, = self.args(d, 1)
        if name not in self.named_cs:
            raise XMLError(f"{d.where}: {d.name}: unknown coordinate system {name!r} "
                           f"(known: {', '.join(sorted(self.named_cs)) or 'none'})")
        self.state.ctm = [m.copy() for m in self.named_cs[name]]

    def _d_TransformTimes(self, d):
        a = self.args(d, 2, float)
        self.transform_times = tuple(a)

    def _d_ActiveTransform(self, d):
        which, = [str(a) for a in d.args] if len(d.args) == 1 else [None]
        choices = {"StartTime": [True, False], "EndTime": [False, True], "All": [True, True]}
        if which not in choices:
            raise XMLError(f"{d.where}: {d.name}: expected StartTime, EndTime or All, got {d.args}")
        self.state.active = choices[which]

    def _d_ReverseOrientation(self, d):
        self.args(d, 0)
        self.state.reverse = not self.state.reverse

    # -- attribute stack -------------------------------------------------------------------
    def _d_AttributeBegin(self, d):
        self.args(d, 0)
        self.stack.append(("Attribute", self.state.copy(), d.where))

    def _d_AttributeEnd(self, d):
        self.args(d, 0)
        if not self.stack or self.stack[-1][0] != "Attribute":
            raise XMLError(f"{d.where}: AttributeEnd: no matching AttributeBegin")
        self.state = self.stack.pop()[1]

    def _d_TransformBegin(self, d):
        self.args(d, 0)
        self.note(d.where, "TransformBegin is deprecated in pbrt-v4 (AttributeBegin saves the transform)")
        self.stack.append(("Transform", self.state.copy(), d.where))

    def _d_TransformEnd(self, d):
        self.args(d, 0)
        if not self.stack or self.stack[-1][0] != "Transform":
            raise XMLError(f"{d.where}: TransformEnd: no matching TransformBegin")
        saved = self.stack.pop()[1]
        self.state.ctm, self.state.active = saved.ctm, saved.active

    def _d_Attribute(self, d):
        target, = self.args(d, 1, allow_params=True)
        if target not in self.state.attributes:
            raise XMLError(f"{d.where}: Attribute: unknown target {target!r} "
                           f"(pbrt-v4's: {', '.join(self.state.attributes)})")
        self.state.attributes[target] = [q for q in self.state.attributes[target]
                                         if q.name not in {p.name for p in d.params}] + list(d.params)

    def _d_Option(self, d):
        self.args(d, 0, allow_params=True)
        for q in d.params:
            if q.name == "displacementedgescale" and q.type in ("float", "integer") and len(q.values) == 1:
                # pbrt-v4 multiplies every plymesh's 'edgelength' by it
                self.displacement_edge_scale = float(q.values[0])
                continue
            self.note(q.where, f"Option {q.name!r} ignored (pbr has no pbrt-v4 options)")

    def _d_ColorSpace(self, d):
        # pbrt-v4's RGBColorSpace::GetNamed: the name in any case. RGB parameters of later
        # directives are converted to linear sRGB (see rgb_value).
        name, = self.args(d, 1)
        if name.lower() not in COLOR_SPACES:
            raise XMLError(f"{d.where}: ColorSpace: unknown color space {name!r} "
                           f"(pbrt-v4's: {', '.join(COLOR_SPACES)})")
        self.state.color_space = name.lower()

    def _d_Accelerator(self, d):
        self.args(d, 1, allow_params=True)
        self.note(d.where, "Accelerator ignored (Mitsuba's ray tracer builds its own BVH)")

    def _d_Include(self, d):
        name, = self.args(d, 1, allow_params=d.name == "Include")
        full = resolve(name, self.base)
        if not os.path.exists(full):
            return self.missing(d.where, d.name, name, full)
        self.run_file(full, d.where, d.params)

    def _d_Import(self, d):
        # pbrt-v4 parses imported files in parallel (no parameters follow them); their
        # named objects join the scene.
        self._d_Include(d)

    def _d_WorldBegin(self, d):
        self.args(d, 0)
        if self.world:
            raise XMLError(f"{d.where}: WorldBegin: given twice")
        self.world = True
        self.state.ctm = [np.eye(4), np.eye(4)]
        self.named_cs["world"] = [np.eye(4), np.eye(4)]

    def _d_WorldEnd(self, d):
        self.note(d.where, "WorldEnd is pbrt-v3 syntax; ignored")

    # -- rendering options -----------------------------------------------------------------
    def _option(self, d, attr):
        if self.world:
            raise XMLError(f"{d.where}: {d.name}: must come before WorldBegin")
        self.args(d, 1, allow_params=True)
        setattr(self, attr, d)

    def _d_Camera(self, d):
        self._option(d, "camera")
        self.camera_ctm = [m.copy() for m in self.state.ctm]
        self.camera_times = self.transform_times
        self.named_cs["camera"] = [np.linalg.inv(m) for m in self.state.ctm]
        self.camera_medium = self.state.outside

    def _d_Film(self, d):
        if self.state.color_space != "srgb":
            self.note(d.where, f"Film: pbrt-v4 writes the image in the color space {self.state.color_space!r}; "
                               "pbr's films write linear sRGB (Rec. 709 primaries, D65)")
        self._option(d, "film")

    def _d_Sampler(self, d):
        self._option(d, "sampler")

    def _d_PixelFilter(self, d):
        self._option(d, "filter")

    def _d_Integrator(self, d):
        self._option(d, "integrator")

    # -- named things ------------------------------------------------------------------------
    def _d_MakeNamedMedium(self, d):
        name, = self.args(d, 1, allow_params=True)
        p = _Params(d, self, self.state.attributes["medium"])
        key = self.add("medium", self.medium(p), d.where, key=f"medium_{_safe(name)}")
        self.media[name] = key

    def _d_MediumInterface(self, d):
        if len(d.args) not in (1, 2) or not all(isinstance(a, str) for a in d.args):
            raise XMLError(f"{d.where}: MediumInterface: expected one or two medium names, got {d.args}")
        inside, outside = (d.args[0], d.args[0]) if len(d.args) == 1 else d.args
        for n in (inside, outside):
            if n and n not in self.media:
                msg = f"unknown medium {n!r} (known: {', '.join(sorted(self.media)) or 'none'})"
                if not (self.skip_missing and any("file not found" in x for x in self.notes)):
                    raise XMLError(f"{d.where}: MediumInterface: {msg}")
                # Probably defined in a file left out (e.g. a density grid's file).
                self.note(d.where, f"MediumInterface: {msg}, after a missing file; left out")
        known = lambda n: n if n in self.media else None
        self.state.inside, self.state.outside = known(inside), known(outside)

    def _d_Texture(self, d):
        if len(d.args) != 3 or not all(isinstance(a, str) for a in d.args):
            raise XMLError(f"{d.where}: Texture: expected a name, a type ('float' or 'spectrum') and a class, got {d.args}")
        name, kind, cls = d.args
        if kind not in ("float", "spectrum"):
            raise XMLError(f"{d.where}: Texture: type must be 'float' or 'spectrum', got {kind!r}")
        p = _Params(d, self, self.state.attributes["texture"])
        self.textures[kind][name] = self.texture(p, cls, kind)
        self.warn_unused(p, f"texture {name!r}")

    def _d_Material(self, d):
        t, = self.args(d, 1, allow_params=True)
        p = _Params(d, self, self.state.attributes["material"])
        key = self.add("material", self.material(p, t), d.where)
        self.state.material = key

    def _d_MakeNamedMaterial(self, d):
        name, = self.args(d, 1, allow_params=True)
        p = _Params(d, self, self.state.attributes["material"])
        t = p.string("type")
        if t is None:
            raise XMLError(f"{d.where}: MakeNamedMaterial: {name!r} needs a \"string type\" parameter")
        key = f"mat_{_safe(name)}"
        if key in self.out:
            self.note(d.where, f"MakeNamedMaterial: {name!r} redefined")
        self.add("material", self.material(p, t), d.where, key=key)
        self.named_materials[name] = key

    def _d_NamedMaterial(self, d):
        # pbrt-v4 resolves named materials after parsing: one may be defined after its
        # use (e.g. in a materials file included at the end); checked in finish().
        name, = self.args(d, 1)
        self.material_uses.setdefault(name, d.where)
        self.state.material = self.named_materials.get(name, f"mat_{_safe(name)}")

    def nanovdb_medium(self, p: _Params, m, common: dict) -> dict:
        """pbrt-v4's ``nanovdb`` medium: pbr's ``nanovdb`` medium (read with NVIDIA Warp),
        in the CTM's frame; it emits from its temperature grid, never ``Le``."""
        fname = p.string("filename")
        if not fname:
            raise p.error(None, "nanovdb needs \"string filename\" (a .nvdb file)")
        full = resolve(fname, self.base)
        if not os.path.exists(full):
            self.missing(p.d.where, p.d.name, fname, full)
            return {"type": "homogeneous", **common}
        if "Le" in common:
            self.note(p.p["Le"].where, "MakeNamedMedium: pbrt-v4's nanovdb medium ignores 'Le' (it emits from "
                                       "its temperature grid)")
            common.pop("Le")
        out = {"type": "nanovdb", "filename": full, "to_world": _mi_transform(m), **common}
        out["Lescale"] = p.one("Lescale", "float", 1.0)
        for k in ("gridname", "temperaturename"):
            if p.has(k):
                out[k] = p.string(k)
        for k in ("temperatureoffset", "temperaturecutoff", "temperaturescale"):
            if p.has(k):
                out[k] = p.one(k, "float")
        return out

    # -- lights --------------------------------------------------------------------------------
    def _d_LightSource(self, d):
        t, = self.args(d, 1, allow_params=True)
        if self.current_object is not None:
            raise XMLError(f"{d.where}: LightSource: lights inside ObjectBegin/ObjectEnd are not supported by pbrt-v4")
        p = _Params(d, self, self.state.attributes["light"])
        light = self.light(p, t)
        if light is not None:
            self.add("light", light, d.where)
        self.warn_unused(p, f"light {t!r}")

    def _d_AreaLightSource(self, d):
        t, = self.args(d, 1, allow_params=True)
        if t != "diffuse":
            raise XMLError(f"{d.where}: AreaLightSource: unknown type {t!r} (pbrt-v4's: 'diffuse')")
        self.state.area = d

    # -- instancing ------------------------------------------------------------------------------
    def _d_ObjectBegin(self, d):
        name, = self.args(d, 1)
        if self.current_object is not None:
            raise XMLError(f"{d.where}: ObjectBegin: nested inside {self.current_object[0]!r}")
        self.stack.append(("Attribute", self.state.copy(), d.where))
        key = f"object_{_safe(name)}"
        self.out[key] = {"type": "shapegroup"}
        self.lines[f"scene.{key}"] = d.where
        self.objects[name] = key
        self.current_object = (name, d.where, key)

    def _d_ObjectEnd(self, d):
        self.args(d, 0)
        if self.current_object is None:
            raise XMLError(f"{d.where}: ObjectEnd: no matching ObjectBegin")
        key = self.current_object[2]
        if len(self.out[key]) == 1:       # an empty object: nothing to instance
            del self.out[key]
        self.current_object = None
        self._d_AttributeEnd(Directive("AttributeEnd", [], [], d.where))

    def _d_ObjectInstance(self, d):
        name, = self.args(d, 1)
        if name not in self.objects:
            raise XMLError(f"{d.where}: ObjectInstance: unknown object {name!r}")
        key = self.objects[name]
        if key not in self.out:
            return
        inst = {"type": "instance", "to_world": _mi_transform(self.ctm()), "shapegroup": {"type": "ref", "id": key}}
        if self.animated():
            if self.mitsuba:
                self.unsupported(d, "an animated ObjectInstance (ActiveTransform EndTime) in a dict for Mitsuba 3 "
                                    "(mitsuba=True): the start transform is used")
            else:
                inst.update(self.motion())
        self.add("instance", inst, d.where)

    # -- motion blur -----------------------------------------------------------------------------
    def animated(self) -> bool:
        """Whether the CTM differs at TransformTimes' start and end (ActiveTransform)."""
        c0, c1 = self.state.ctm
        return c0 is not c1 and not np.allclose(c0, c1)

    def motion(self, m=None) -> dict:
        """pbr's motion keys for the animated CTM (times ``m`` on the right, the shape's own
        transform): ``to_world`` at the start, ``to_world_end`` at the end, ``transform_times``."""
        m = np.eye(4) if m is None else m
        return {"to_world": _mi_transform(self.state.ctm[0] @ m), "to_world_end": _mi_transform(self.state.ctm[1] @ m),
                "transform_times": [float(x) for x in self.transform_times]}

    def moving_shape(self, p: _Params, t: str) -> dict | None:
        """A shape under an animated CTM, built in its object space (pbrt-v4 creates
        animated shapes with the identity transform, so only ReverseOrientation flips them)
        with the CTM's motion (pbr's ``to_world_end``, geometry.py)."""
        saved = self.state.ctm
        self.state.ctm = [np.eye(4), np.eye(4)]
        try:
            shape = self.shape(p, t)
        finally:
            self.state.ctm = saved
        if shape is not None:
            own = shape.pop("to_world", None)
            shape.update(self.motion(None if own is None else np.asarray(own.matrix, np.float64)))
        return shape

    # -- shapes ----------------------------------------------------------------------------------
    def _d_Shape(self, d):
        t, = self.args(d, 1, allow_params=True)
        p = _Params(d, self, self.state.attributes["shape"])
        moving = self.animated()
        if moving and (self.mitsuba or self.current_object is not None or self.state.area is not None or t == "curve"):
            why = ("in a dict for Mitsuba 3 (mitsuba=True)" if self.mitsuba else "inside ObjectBegin/ObjectEnd "
                   "(an animated ObjectInstance moves)" if self.current_object is not None else "of curves"
                   if t == "curve" else "with an area light")
            self.unsupported(d, f"animated transforms of shapes (ActiveTransform EndTime) {why}: "
                                f"the start transform is used")
            moving = False
        if moving:
            shape = self.moving_shape(p, t)
        else:
            shape = self.shape(p, t)
        if shape is None:
            return
        mat = self.state.material
        if mat is None:
            if self.default_material is None:
                self.default_material = self.add("material", {"type": "twosided", "bsdf": {
                    "type": "diffuse", "reflectance": 0.5}}, d.where, key="mat_default")
            mat = self.default_material
        bsdf = {"type": "ref", "id": mat}
        alpha = p.value("alpha", 1.0, kind="float")
        if not (isinstance(alpha, float) and alpha >= 1.0):
            bsdf = {"type": "mask", "opacity": alpha, "bsdf": bsdf}
        shape["bsdf"] = bsdf
        if self.state.area is not None:
            if self.current_object is not None:
                raise XMLError(f"{d.where}: Shape: area lights inside ObjectBegin/ObjectEnd are not supported by pbrt-v4")
            shape["emitter"] = self.area_light(_Params(self.state.area, self, self.state.attributes["light"]),
                                               shape, d)
        if self.state.inside:
            shape["interior"] = {"type": "ref", "id": self.media[self.state.inside]}
        if self.state.outside:
            shape["exterior"] = {"type": "ref", "id": self.media[self.state.outside]}
        self.warn_unused(p, f"shape {t!r}")
        if self.current_object is not None:
            group = self.out[self.current_object[2]]
            if "emitter" in shape:
                del shape["emitter"]
            k = f"shape_{len(group):04d}"
            group[k] = shape
            self.lines[f"scene.{self.current_object[2]}.{k}"] = d.where
        else:
            self.add("shape", shape, d.where)

    def mesh(self, p: _Params, pos, tri, n=None, uv=None, where=None) -> dict:
        """A ``ply`` shape for a triangle mesh given in object space: baked into world space
        with pbrt-v4's orientation rules (see the module docstring)."""
        m = self.ctm()
        tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
        pos = np.asarray(pos, dtype=np.float64).reshape(-1, 3)
        if len(tri) == 0:
            raise p.error(None, "the mesh has no triangles")
        if tri.min() < 0 or tri.max() >= len(pos):
            raise p.error("indices", f"vertex indices must be in [0, {len(pos) - 1}], got [{tri.min()}, {tri.max()}]")
        pw = pos @ m[:3, :3].T + m[:3, 3]
        e = np.cross(pw[tri[:, 1]] - pw[tri[:, 0]], pw[tri[:, 2]] - pw[tri[:, 0]])
        nw = None
        if n is not None:
            n = np.asarray(n, dtype=np.float64).reshape(-1, 3)
            if len(n) != len(pos):
                raise p.error("N", f"needs one normal per vertex ({len(pos)}), got {len(n)}")
            nw = n @ np.linalg.inv(m[:3, :3])
            nw /= np.maximum(np.linalg.norm(nw, axis=1, keepdims=True), 1e-30)
            flip = np.einsum("ij,ij->i", e, nw[tri].sum(axis=1)) < 0
        else:
            flip = np.full(len(tri), self.state.reverse ^ (np.linalg.det(m[:3, :3]) < 0))
        tri = tri.copy()
        tri[flip] = tri[flip][:, [0, 2, 1]]
        if uv is not None:
            uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
            if len(uv) != len(pos):
                raise p.error("uv", f"needs one (u, v) per vertex ({len(pos)}), got {len(uv)}")
        os.makedirs(self.mesh_dir, exist_ok=True)
        h = hashlib.sha1()
        for a in (pw, tri, nw, uv):
            h.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
        fname = os.path.join(self.mesh_dir, f"{h.hexdigest()[:20]}.ply")
        if not os.path.exists(fname):
            write_ply(fname, pw, tri, nw, uv)
        shape = {"type": "ply", "filename": fname}
        shape["_tri_areas"] = 0.5 * np.linalg.norm(e, axis=1)
        return shape

    def shape(self, p: _Params, t: str) -> dict | None:
        s = self._shape(p, t)
        if s is not None and t in ("sphere", "disk", "cylinder"):
            # pbrt-v4's Area() of a quadric, in object space (what an area light's
            # 'power' divides by): phimax r (zmax - zmin), phimax (r^2 - ri^2) / 2.
            r = p.one("radius", "float", 1.0)
            ph = math.radians(min(p.one("phimax", "float", 360.0), 360.0))
            if t == "sphere":
                zmin = max(p.one("zmin", "float", -r), -r)
                zmax = min(p.one("zmax", "float", r), r)
                s["_light_area"] = ph * r * (zmax - zmin)
            elif t == "disk":
                s["_light_area"] = ph * 0.5 * (r * r - p.one("innerradius", "float", 0.0) ** 2)
            else:
                s["_light_area"] = ph * r * (p.one("zmax", "float", 1.0) - p.one("zmin", "float", -1.0))
        return s

    def _shape(self, p: _Params, t: str) -> dict | None:
        m = self.ctm()
        rev = self.state.reverse
        if t == "sphere":
            r = p.one("radius", "float", 1.0)
            zmin, zmax, phimax = p.one("zmin", "float", -r), p.one("zmax", "float", r), p.one("phimax", "float", 360.0)
            if zmin <= -r and zmax >= r and phimax >= 360 and _is_similarity(m):
                # World-space centre and radius: Mitsuba's sphere takes no reflections or
                # non-uniform scales in to_world (ellipsoids become meshes below).
                k = abs(np.linalg.det(m[:3, :3])) ** (1.0 / 3.0)
                return {"type": "sphere", "center": [float(x) for x in m[:3, 3]], "radius": r * k,
                        "flip_normals": rev}
            if zmin <= -r and zmax >= r and phimax >= 360:
                return self.mesh(p, *_sphere_mesh(r, -r, r, 360.0))
            return self.mesh(p, *_sphere_mesh(r, max(zmin, -r), min(zmax, r), phimax))
        if t == "disk":
            h, r = p.one("height", "float", 0.0), p.one("radius", "float", 1.0)
            ri, phimax = p.one("innerradius", "float", 0.0), p.one("phimax", "float", 360.0)
            if ri <= 0 and phimax >= 360:
                return {"type": "disk", "to_world": _mi_transform(m @ _translate(0, 0, h) @ _scale(r, r, r)),
                        "flip_normals": rev}
            return self.mesh(p, *_disk_mesh(h, r, ri, phimax))
        if t == "cylinder":
            r = p.one("radius", "float", 1.0)
            zmin, zmax, phimax = p.one("zmin", "float", -1.0), p.one("zmax", "float", 1.0), p.one("phimax", "float", 360.0)
            if phimax >= 360 and abs(np.linalg.det(m[:3, :3])) > 0 and _is_similarity(m):
                return {"type": "cylinder", "radius": r, "p0": [0.0, 0.0, zmin], "p1": [0.0, 0.0, zmax],
                        "to_world": _mi_transform(m), "flip_normals": rev}
            return self.mesh(p, *_cylinder_mesh(r, zmin, zmax, phimax))
        if t == "trianglemesh":
            pos = p.array("P", "point3", 3)
            if pos is None:
                raise p.error(None, "trianglemesh needs \"point3 P\"")
            idx = p.ints("indices")
            if idx is None:
                if len(pos) != 3:
                    raise p.error(None, "\"integer indices\" is required unless the mesh is one triangle")
                idx = [0, 1, 2]
            if len(idx) % 3:
                raise p.error("indices", f"needs a multiple of 3 values, got {len(idx)}")
            n = p.array("N", "normal", 3)
            uv = p.array("uv", "point2", 2)
            for k in ("S", "faceIndices"):
                if p.has(k):
                    p._get(k, (p.p[k].type,))
                    self.note(p.p[k].where, f"Shape: {k!r} of trianglemesh ignored")
            return self.mesh(p, pos, idx, n, uv)
        if t == "plymesh":
            fname = p.string("filename")
            if fname is None:
                raise p.error(None, "plymesh needs \"string filename\"")
            full = resolve(fname, self.base)
            if not os.path.exists(full):
                return self.missing(p.d.where, p.d.name, fname, full)
            pos, f, n, uv = _read_ply(full, p.d.where)
            if p.has("displacement"):
                pos, f, n, uv = self.displace(p, pos, f, n, uv)
            elif p.has("edgelength"):
                p.p["edgelength"].used = True
                self.note(p.p["edgelength"].where, "Shape: 'edgelength' without 'displacement' does nothing")
            return self.mesh(p, pos, f, n, uv)
        if t == "bilinearmesh":
            pos = p.array("P", "point3", 3)
            idx = p.ints("indices")
            if pos is None:
                raise p.error(None, "bilinearmesh needs \"point3 P\"")
            if idx is None:
                if len(pos) != 4:
                    raise p.error(None, "\"integer indices\" is required unless the mesh is one patch")
                idx = [0, 1, 2, 3]
            if len(idx) % 4:
                raise p.error("indices", f"needs a multiple of 4 values, got {len(idx)}")
            q = np.asarray(idx).reshape(-1, 4)
            # pbrt-v4's patch p00 p10 p01 p11 -> two triangles (planar patches are exact).
            tri = np.concatenate([q[:, [0, 1, 3]], q[:, [0, 3, 2]]], axis=0)
            return self.mesh(p, pos, tri, p.array("N", "normal", 3), p.array("uv", "point2", 2))
        if t == "loopsubdiv":
            from trimesh.remesh import subdivide_loop
            pos = p.array("P", "point3", 3)
            idx = p.ints("indices")
            if pos is None or idx is None:
                raise p.error(None, "loopsubdiv needs \"point3 P\" and \"integer indices\"")
            levels = p.one("levels", "integer", 3)
            v, f = subdivide_loop(pos, np.asarray(idx).reshape(-1, 3), iterations=max(0, levels))
            self.note(p.d.where, "Shape: loopsubdiv is subdivided without pbrt-v4's push to the limit surface")
            return self.mesh(p, v, f)
        if t == "curve":
            return self.curve(p)
        if t in ("cone", "paraboloid", "hyperboloid"):
            raise p.error(None, f"{t!r} is a pbrt-v3 shape that pbrt-v4 removed")
        raise p.error(None, f"unknown shape {t!r} (pbrt-v4's: sphere, disk, cylinder, trianglemesh, plymesh, "
                             "bilinearmesh, loopsubdiv, curve)")

    def displace(self, p: _Params, pos, tri, n, uv):
        """pbrt-v4's true displacement of a ``plymesh`` (TriQuadMesh::Displace): the mesh
        is tessellated until its render-space edges are shorter than ``edgelength`` (1),
        each vertex moves by d n, d the float texture ``displacement`` evaluated at its
        object-space position and uv (no filtering: pbrt-v4 gives no footprint), n its
        normal (the file's, else pbrt-v4's vertex normals), and the normals are recomputed
        from the displaced triangles."""
        if uv is None:
            raise p.error("displacement", "displacement needs vertex uvs in the PLY file (as pbrt-v4)")
        edge = p.one("edgelength", "float", 1.0) * self.displacement_edge_scale
        if not edge > 0:
            raise p.error("edgelength", f"must be positive, got {edge}")
        tex = p.value("displacement", 0.0, kind="float")
        if not np.isfinite(np.asarray(pos, np.float64)).all():
            raise p.error("filename", "the mesh has non-finite vertex positions: it cannot be tessellated")
        if n is None:
            n = vertex_normals(np.asarray(pos, np.float64), np.asarray(tri, np.int64).reshape(-1, 3))
        pos, tri, n, uv = refine_mesh(pos, tri, n, uv, self.ctm(), edge)
        d = np.full(len(pos), tex) if isinstance(tex, float) else _texture_at(tex, pos, n, uv, self.base)
        pos = pos + d[:, None] * n
        return pos, tri, vertex_normals(pos, tri), uv

    def curve(self, p: _Params) -> dict:
        """pbrt-v4 curves as Mitsuba's ``bsplinecurve`` (round tubes; cubic Bezier control
        points are converted to the B-spline basis)."""
        pos = p.array("P", "point3", 3)
        if pos is None:
            raise p.error(None, "curve needs \"point3 P\"")
        basis = p.string("basis", "bezier")
        degree = p.one("degree", "integer", 3)
        ctype = p.string("type", "flat")
        if ctype != "cylinder":
            self.unsupported(p.d, f"curve type {ctype!r}: a round tube (Mitsuba's bsplinecurve) is used")
        if degree != 3:
            self.unsupported(p.d, f"curve degree {degree} (only cubic curves)")
        w = p.one("width", "float", 1.0)
        w0, w1 = p.one("width0", "float", w), p.one("width1", "float", w)
        for k in ("N", "splitdepth"):
            if p.has(k):
                p.p[k].used = True
        m = self.ctm()
        pw = pos @ m[:3, :3].T + m[:3, 3]
        scale = _area_scale(m) ** 0.5
        if basis == "bezier":
            if (len(pw) - 1) % 3:
                raise p.error("P", f"a cubic Bezier curve needs 3 n + 1 control points, got {len(pw)}")
            segs = [pw[i:i + 4] for i in range(0, len(pw) - 1, 3)]
            # B-spline control points of each Bezier segment: B = M_bspline^-1 M_bezier P.
            conv = np.array([[6, -7, 2, 0], [0, 2, -1, 0], [0, -1, 2, 0], [0, 2, -7, 6]], dtype=np.float64)
            ctrl = [conv @ s for s in segs]
        elif basis == "bspline":
            if len(pw) < 4:
                raise p.error("P", f"a cubic B-spline needs at least 4 control points, got {len(pw)}")
            ctrl = [pw]
        else:
            raise p.error("basis", f"expected 'bezier' or 'bspline', got {basis!r}")
        lines = []
        for c in ctrl:
            t = np.linspace(0, 1, len(c))
            r = 0.5 * ((1 - t) * w0 + t * w1) * scale
            lines += [f"{x:.9g} {y:.9g} {z:.9g} {rr:.9g}" for (x, y, z), rr in zip(c, r)]
            lines.append("")
        os.makedirs(self.mesh_dir, exist_ok=True)
        text = "\n".join(lines)
        fname = os.path.join(self.mesh_dir, hashlib.sha1(text.encode()).hexdigest()[:20] + ".txt")
        if not os.path.exists(fname):
            with open(fname, "w") as f:
                f.write(text)
        return {"type": "bsplinecurve", "filename": fname}

    # -- values ------------------------------------------------------------------------------------
    def spectrum_value(self, q: Param, p: _Params, kind: str):
        """A parameter's value as pbr takes it (see :meth:`_Params.value`)."""
        where = q.where
        if q.type == "texture":
            name = q.values[0]
            order = ("float", "spectrum") if kind == "float" else ("spectrum", "float")
            for k in order:
                if name in self.textures[k]:
                    return self.textures[k][name]
            raise XMLError(f"{where}: {p.d.name}: parameter {q.name!r}: unknown texture {name!r}")
        if q.type in ("float", "integer"):
            if len(q.values) != 1:
                raise XMLError(f"{where}: {p.d.name}: parameter {q.name!r}: expected one value, got {len(q.values)}")
            return float(q.values[0])
        if q.type == "rgb":
            if len(q.values) != 3:
                raise XMLError(f"{where}: {p.d.name}: parameter {q.name!r}: expected one RGB triple")
            return {"type": "rgb", "value": [float(v) for v in self.rgb_value(q, p, q.values, kind)]}
        if q.type == "blackbody":
            t = float(q.values[0])
            if t <= 0:
                raise XMLError(f"{where}: {p.d.name}: parameter {q.name!r}: temperature must be positive, got {t}")
            bb = {"type": "blackbody", "temperature": t}
            if kind == "illuminant":
                return bb
            # pbrt-v4's BlackbodySpectrum is normalised to a peak of 1 (tabulated here, so
            # that it can be an albedo).
            lam = np.arange(LAMBDA_MIN, LAMBDA_MAX + 1.0, 5.0)
            vals = blackbody(lam, t) / _blackbody_peak(t)
            return {"type": "spectrum", "value": [(float(a), float(b)) for a, b in zip(lam, vals)]}
        if q.type == "spectrum":
            v = q.values[0]
            if isinstance(v, str):
                return self.named_spectrum(v, q, p, kind)
            pairs = np.asarray(q.values, dtype=np.float64).reshape(-1, 2)
            return {"type": "spectrum", "value": [(float(a), float(b)) for a, b in pairs]}
        raise XMLError(f"{where}: {p.d.name}: parameter {q.name!r}: a {q.type} cannot be a spectrum or float")

    def rgb_value(self, q: Param, p: _Params, values, kind: str) -> np.ndarray:
        """RGB ``values`` (3 or (..., 3)) of parameter ``q`` as linear sRGB: unchanged in
        pbrt-v4's default "srgb", else converted from ``q.color_space``
        (:func:`color_space_to_srgb`; reflectances adapted to D65, illuminants not).
        Colours outside sRGB's gamut get negative components, which pbr's spectral
        upsampling cannot represent (pbrt-v4 clamps its own at 0 too): clipped at 0; a
        reflectance (``kind`` 'albedo', given within [0, 1]) is also clipped at 1; an
        unbounded or illuminant value keeps components above 1. Clipping is noted."""
        a = np.asarray(values, dtype=np.float64).reshape(-1, 3)
        cs = q.color_space or "srgb"
        if cs == "srgb":
            return a.reshape(np.shape(values))
        out = a @ color_space_to_srgb(cs, adapt=kind != "illuminant").T
        hi = 1.0 if kind in ("albedo", "float") and a.max(initial=0.0) <= 1.0 else np.inf
        clipped = np.clip(out, 0.0, hi)
        bad = np.abs(clipped - out).max(axis=1) > 1e-6
        if bad.any():
            i = int(np.argmax(bad))
            self.note(q.where, f"{p.d.name}: parameter {q.name!r}: {int(bad.sum())} of {len(a)} RGB value(s) in "
                               f"{cs!r} outside sRGB's gamut, clipped to {'[0, 1]' if hi == 1.0 else '[0, inf)'} "
                               f"(e.g. {np.round(a[i], 6).tolist()} -> sRGB {np.round(out[i], 6).tolist()})")
        return clipped.reshape(np.shape(values))

    def named_spectrum(self, name: str, q: Param, p: _Params, kind: str):
        lname = name.lower()
        if lname in SELLMEIER:
            return name          # pbr's dielectrics take Sellmeier glass names
        if lname == "glass-f11":
            return "glass-SF11"  # pbrt-v4's "glass-F11" is Schott SF11
        if lname in _GLASS_ND:
            self.unsupported(p.d, f"dispersive glass {name!r} (pbr has Sellmeier data for "
                                  f"{', '.join(sorted(SELLMEIER))}): its IOR at 587.6 nm, {_GLASS_ND[lname]}, is used")
            return _GLASS_ND[lname]
        if lname.startswith("metal-"):
            return name          # conductors take "metal-Cu-eta" (handled by the material)
        if lname == "stdillum-d65":
            return {"type": "rgb", "value": [1.0, 1.0, 1.0]}    # pbr's RGB illuminant: D65 of unit luminance
        full = resolve(name, self.base)
        if os.path.exists(full):
            pairs = _read_spd(full, q.where)
            return {"type": "spectrum", "value": [(float(a), float(b)) for a, b in pairs]}
        if self.skip_missing and "." in os.path.basename(name):
            self.missing(q.where, p.d.name, name, full)
            return 1.0
        raise XMLError(f"{q.where}: {p.d.name}: parameter {q.name!r}: unknown named spectrum or missing file {name!r} "
                       f"(pbr knows {', '.join(sorted(SELLMEIER))}, metal-<X>-eta/k, stdillum-D65)")

    def emission(self, p: _Params, name: str, default_rgb=(1.0, 1.0, 1.0)):
        """(spectrum value, luminance) of an emission parameter: pbrt-v4 divides the
        light's scale by this luminance (``SpectrumToPhotometric``)."""
        v = p.value(name, None, kind="illuminant")
        if v is None:
            return {"type": "rgb", "value": list(default_rgb)}, 1.0
        if isinstance(v, float):
            return v, (1.0 if v == 0 else v)   # a constant spectrum has luminance v
        if v.get("type") == "rgb":
            return v, 1.0                    # pbrt-v4: only the illuminant counts
        if v.get("type") == "blackbody":
            return v, _blackbody_luminance(v["temperature"])
        if v.get("type") == "spectrum":
            pr = np.asarray(v["value"], dtype=np.float64)
            return v, luminance_of(pr[:, 1], pr[:, 0])
        raise p.error(name, "a light's spectrum cannot be a texture")

    # -- textures --------------------------------------------------------------------------------------
    def _uv_transform(self, p: _Params, flip_v: bool):
        mapping = p.string("mapping", "uv")
        if mapping != "uv":
            self.unsupported(p.d, f"texture mapping {mapping!r} (only 'uv')")
        su, sv = p.one("uscale", "float", 1.0), p.one("vscale", "float", 1.0)
        du, dv = p.one("udelta", "float", 0.0), p.one("vdelta", "float", 0.0)
        m = np.array([[su, 0, du], [0, sv, dv], [0, 0, 1]], dtype=np.float64)
        if flip_v:
            m = np.array([[1, 0, 0], [0, -1, 1], [0, 0, 1]]) @ m
        return m

    def texture(self, p: _Params, cls: str, kind: str):
        if cls == "constant":
            return p.value("value", 1.0)
        if cls == "scale":
            return {"type": "scale", "tex": p.value("tex", 1.0), "scale": p.value("scale", 1.0, kind="float")}
        if cls == "mix":
            return {"type": "mix", "tex1": p.value("tex1", 0.0), "tex2": p.value("tex2", 1.0),
                    "amount": p.value("amount", 0.5, kind="float")}
        if cls in ("imagemap", "checkerboard", "dots") and self.pbr_plugin(TEXTURE_TYPES, cls):
            return self.pbrt_texture(p, cls)
        if cls == "imagemap":
            full = self.image_file(p)
            if full is None:
                return 0.5
            wrap = p.string("wrap", "repeat")
            wraps = {"repeat": "repeat", "clamp": "clamp", "black": "clamp", "octahedralsphere": "repeat"}
            if wrap not in wraps:
                raise p.error("wrap", f"expected repeat, black, clamp or octahedralsphere, got {wrap!r}")
            if wrap in ("black", "octahedralsphere"):
                self.unsupported(p.d, f"imagemap wrap {wrap!r}: {wraps[wrap]!r} is used")
            filt = p.string("filter", "bilinear")
            if filt not in ("bilinear", "point"):
                self.note(p.d.where, f"Texture: imagemap filter {filt!r} is bilinear in pbr (no MIP-mapping yet)")
            enc = p.string("encoding", "sRGB")
            if enc not in ("sRGB", "linear"):
                self.unsupported(p.d, f"imagemap encoding {enc!r} (sRGB or linear)")
            raw = enc == "linear"
            t = {"type": "bitmap", "filename": full, "wrap_mode": wraps[wrap],
                 "filter_type": "nearest" if filt == "point" else "bilinear",
                 "to_uv": _mi_transform(_affine3_to4(self._uv_transform(p, flip_v=True)))}
            if raw:
                t["raw"] = True
            sc, inv = p.one("scale", "float", 1.0), p.bool("invert", False)
            if sc != 1.0:
                t = {"type": "scale", "tex": t, "scale": sc}
            if inv:      # pbrt-v4: 1 - scale * texel, i.e. mix(1, 0) with the texel as amount
                t = {"type": "mix", "tex1": 1.0, "tex2": 0.0, "amount": t}
            return t
        if cls == "checkerboard" and p.one("dimension", "integer", 2) == 2:
            # pbrt's squares have size 1 in (s, t); Mitsuba's checkerboard has period 1.
            m = np.array([[0.5, 0, 0], [0, 0.5, 0], [0, 0, 1]]) @ self._uv_transform(p, flip_v=False)
            return {"type": "checkerboard", "color0": p.value("tex1", 1.0), "color1": p.value("tex2", 0.0),
                    "to_uv": _mi_transform(_affine3_to4(m))}
        if cls in TEXTURE_TYPES or cls in ("fbm", "wrinkled", "windy", "marble", "dots", "checkerboard",
                                           "imagemap", "bilerp", "directionmix", "ptex"):
            if not self.pbr_plugin(TEXTURE_TYPES, cls):
                who = "Mitsuba 3 (mitsuba=True)" if self.mitsuba else "pbr"
                self.unsupported(p.d, f"texture {cls!r} ({who} has no such texture): a constant 0.5 is used")
                for q in p.d.params:
                    q.used = True
                return 0.5
            return self.pbrt_texture(p, cls)
        raise p.error(None, f"unknown texture {cls!r}")

    def image_file(self, p: _Params):
        """The path of an ``imagemap``'s ``filename``, or None when the file is missing
        (noted by :meth:`missing`; the texture's parameters count as used)."""
        fname = p.string("filename")
        if fname is None:
            raise p.error(None, "imagemap needs \"string filename\"")
        full = resolve(fname, self.base)
        if not os.path.exists(full):
            self.missing(p.d.where, p.d.name, fname, full)
            for q in p.d.params:
                q.used = True
            return None
        return full

    def pbrt_texture(self, p: _Params, cls: str):
        """pbr's texture of pbrt-v4's name, with pbrt-v4's parameters, and ``to_world`` =
        the CTM at the ``Texture`` directive (pbrt-v4's texture space, used by 3D
        textures and the spherical, cylindrical and planar mappings)."""
        if cls == "imagemap":
            full = self.image_file(p)
            if full is None:
                return 0.5
        t = self.passthrough(p, cls)
        if cls == "imagemap" and "encoding" in t and os.path.splitext(t["filename"])[1].lower() not in (
                ".png", ".exr", ".pfm", ".hdr", ".qoi"):
            # pbrt-v4 reads 8-bit images other than PNG (JPEG, TGA, BMP, ...) as sRGB,
            # whatever 'encoding' says (pbr's imagemap would honour it).
            self.note(p.p["encoding"].where, "Texture: pbrt-v4 reads this 8-bit image as sRGB whatever its "
                                             f"'encoding' ({t['encoding']!r}): ignored")
            del t["encoding"]
        if cls == "checkerboard":
            t.setdefault("dimension", 2)      # pbrt-v4's checkerboard, also without tex1/tex2
        if not np.allclose(self.ctm(), np.eye(4)):
            t["to_world"] = _mi_transform(self.ctm())
        return t

    def passthrough(self, p: _Params, t: str) -> dict:
        """A plugin registered in pbr under pbrt-v4's name: pbrt-v4's parameter names pass
        through unchanged (values converted)."""
        out = {"type": t}
        for q in p.d.params:
            q.used = True
            if q.type in ("rgb", "spectrum", "blackbody", "texture"):
                out[q.name] = self.spectrum_value(q, p, "albedo")
            elif q.type == "string" and q.name in ("filename", "lensfile"):
                out[q.name] = resolve(q.values[0], self.base)
            elif len(q.values) == 1:
                out[q.name] = q.values[0] if q.type != "float" else float(q.values[0])
            else:
                out[q.name] = list(q.values)
        return out

    # -- materials ----------------------------------------------------------------------------------------
    def _roughness(self, p: _Params, prefix: str = ""):
        """(alpha_u, alpha_v) from pbrt-v4's roughness parameters (``remaproughness``:
        alpha = sqrt(roughness), TrowbridgeReitzDistribution::RoughnessToAlpha). pbrt-v4
        remaps a roughness texture's value at each lookup: the texture is wrapped in pbr's
        ``sqrt`` texture (the same dict for u and v when both come from ``roughness``)."""
        r = p.value(prefix + "roughness", 0.0, kind="float")
        ru, rv = p.value(prefix + "uroughness", r, kind="float"), p.value(prefix + "vroughness", r, kind="float")
        remap = p.bool("remaproughness", True)
        done = {}

        def alpha(v):
            if isinstance(v, float):
                return math.sqrt(max(v, 0.0)) if remap else v
            if not remap:
                return v
            if id(v) not in done:
                if self.pbr_plugin(TEXTURE_TYPES, "sqrt"):
                    done[id(v)] = {"type": "sqrt", "tex": v}
                else:
                    self.unsupported(p.d, "a roughness texture with remaproughness in a dict for Mitsuba 3 "
                                          "(mitsuba=True: Mitsuba has no square-root texture): the texture, "
                                          "not remapped, is used")
                    done[id(v)] = v
            return done[id(v)]

        return [alpha(ru), alpha(rv)]

    def material(self, p: _Params, t: str) -> dict:
        b = self._material(p, t)
        nm = p.string("normalmap")
        if p.has("displacement"):
            b = self._displacement(p, b, nm)
        full = resolve(nm, self.base) if nm else None
        if nm and not os.path.exists(full):
            self.missing(p.p["normalmap"].where, p.d.name, nm, full)
        elif nm:
            b = {"type": "normalmap", "normalmap": {"type": "bitmap", "filename": full, "raw": True,
                                                    "to_uv": _mi_transform(_affine3_to4(np.array(
                                                        [[1, 0, 0], [0, -1, 1], [0, 0, 1]])))}, "bsdf": b}
        if p.has("type"):
            p.p["type"].used = True
        self.warn_unused(p, f"material {t!r}")
        return b

    def _displacement(self, p: _Params, b: dict, normalmap) -> dict:
        """pbrt-v4's material ``displacement`` (a float texture): pbr's ``bumpmap`` around
        the BSDF (the texture differenced as pbrt-v4's BumpMap does). pbrt-v4 ignores it
        when the material has a normal map; a constant displaces nothing."""
        d = p.value("displacement", 0.0, kind="float")
        if normalmap:
            self.note(p.p["displacement"].where, "Material: 'displacement' is ignored with a 'normalmap' "
                                                 "(pbrt-v4 uses the normal map)")
            return b
        if isinstance(d, float):
            return b
        if self.mitsuba and d.get("type") != "bitmap":
            self.unsupported(p.d, "material 'displacement' of a non-image texture (Mitsuba's bumpmap takes "
                                  "bitmaps): ignored")
            return b
        return {"type": "bumpmap", "displacement": d, "bsdf": b}

    def _material(self, p: _Params, t: str) -> dict:
        two = lambda b: {"type": "twosided", "bsdf": b}    # pbrt-v4's reflective BSDFs are two-sided
        if t == "diffuse":
            return two({"type": "diffuse", "reflectance": p.value("reflectance", 0.5)})
        if t in ("conductor",):
            au, av = self._roughness(p)
            b = {}
            if p.has("reflectance"):
                self.unsupported(p.d, "conductor 'reflectance' (pbrt-v4's artist Fresnel): "
                                      "a mirror times the reflectance is used")
                b["material"] = "none"
                b["specular_reflectance"] = p.value("reflectance")
            else:
                eta = p.value("eta", "metal-Cu-eta", kind="unbounded")
                k = p.value("k", "metal-Cu-k", kind="unbounded")
                if isinstance(eta, str) and isinstance(k, str):
                    me, mk = _metal_name(eta, "eta"), _metal_name(k, "k")
                    if me is None or mk is None or me != mk:
                        raise p.error("eta", f"eta {eta!r} and k {k!r} must name the same metal "
                                             "(metal-<X>-eta, metal-<X>-k)")
                    b["material"] = me
                else:
                    for nm, v in (("eta", eta), ("k", k)):
                        if isinstance(v, str):
                            raise p.error(nm, f"a named metal ({v!r}) needs the other of eta/k named too")
                    b["eta"], b["k"] = eta, k
            if isinstance(au, float) and isinstance(av, float) and max(au, av) < 1e-3:
                return two({"type": "conductor", **b})
            b.update({"type": "roughconductor", "distribution": "ggx"})
            b.update({"alpha": au} if au is av or (isinstance(au, float) and au == av) else {"alpha_u": au, "alpha_v": av})
            return two(b)
        if t in ("dielectric", "thindielectric"):
            eta = p.value("eta", 1.5, kind="unbounded")
            if isinstance(eta, dict) and eta.get("type") == "rgb":
                raise p.error("eta", "an RGB IOR is not physical; give a float or a spectrum")
            if t == "thindielectric":
                return {"type": "thindielectric", "int_ior": eta, "ext_ior": 1.0}
            au, av = self._roughness(p)
            if isinstance(eta, float) and eta == 1.0:
                return {"type": "null"}       # pbrt-v4: an index-matched interface passes light unchanged
            if isinstance(au, float) and isinstance(av, float) and max(au, av) < 1e-3:
                return {"type": "dielectric", "int_ior": eta, "ext_ior": 1.0}
            b = {"type": "roughdielectric", "int_ior": eta, "ext_ior": 1.0, "distribution": "ggx"}
            b.update({"alpha": au} if isinstance(au, float) and au == av else {"alpha_u": au, "alpha_v": av})
            return b
        if t == "interface":
            return {"type": "null"}
        if t == "mix":
            q = p._get("materials", ("string",))
            if q is None or len(q.values) != 2:
                raise p.error("materials", "mix needs \"string materials\" with two material names")
            refs = []
            for n in q.values:
                if n not in self.named_materials:
                    raise p.error("materials", f"unknown material {n!r}")
                refs.append({"type": "ref", "id": self.named_materials[n]})
            return {"type": "mix", "amount": p.value("amount", 0.5, kind="float"), "bsdf_0": refs[0], "bsdf_1": refs[1]}
        if t == "hair":
            b = {"type": "hair"}
            if p.has("sigma_a"):
                b["sigma_a"] = p.value("sigma_a", kind="unbounded")
            elif p.has("reflectance") or p.has("color"):
                # pbrt-v4 reads "color" (pbrt-v3's name) when "reflectance" is not given.
                b["reflectance"] = p.value("reflectance" if p.has("reflectance") else "color")
            else:
                # pbrt-v4: eumelanin 1.3 when no colour is given, pheomelanin 0 (Mitsuba: 0.2).
                b["eumelanin"] = p.value("eumelanin", 1.3, kind="float")
                b["pheomelanin"] = p.value("pheomelanin", 0.0, kind="float")
            b["int_ior"] = p.one("eta", "float", 1.55)
            b["longitudinal_roughness"] = p.value("beta_m", 0.3, kind="float")
            b["azimuthal_roughness"] = p.value("beta_n", 0.3, kind="float")
            b["scale_tilt"] = p.value("alpha", 2.0, kind="float")
            return b
        if t == "measured":
            fname = p.string("filename")
            if fname is None:
                raise p.error(None, "measured needs \"string filename\"")
            full = resolve(fname, self.base)
            if not os.path.exists(full):
                self.missing(p.d.where, p.d.name, fname, full)
                return {"type": "twosided", "bsdf": {"type": "diffuse"}}
            return {"type": "measured", "filename": full}
        if t in ("coateddiffuse", "coatedconductor", "diffusetransmission"):
            b = {"type": t}
            for q in p.d.params:
                if q.name in ("type", "displacement", "normalmap"):
                    continue
                q.used = True
                if q.name == "remaproughness":
                    b[q.name] = q.values[0]
                elif q.name in ("maxdepth", "nsamples"):
                    b[q.name] = int(q.values[0])
                elif q.name == "eta" and q.type in ("float", "integer"):
                    b[q.name] = float(q.values[0])
                else:
                    kind = "unbounded" if q.name.endswith((".eta", ".k", "eta")) else (
                        "float" if "roughness" in q.name or q.name in ("thickness", "g", "scale") else "albedo")
                    b[q.name] = self.spectrum_value(q, p, kind)
            if t == "diffusetransmission":
                return b
            return two(b)
        if t == "subsurface" and not self.pbr_plugin(BSDF_TYPES, "subsurface"):
            self.unsupported(p.d, "material 'subsurface' (Mitsuba 3 has no BSSRDF): a coated diffuse surface is used")
            for q in p.d.params:
                q.used = True
            refl = p.value("reflectance", 0.5) if p.has("reflectance") else 0.5
            return two({"type": "coateddiffuse", "reflectance": refl,
                        "eta": p.one("eta", "float", 1.33)})
        if t == "subsurface":
            # pbr's subsurface takes pbrt-v4's parameters.
            b = {"type": "subsurface"}
            skip = {"type", "displacement", "normalmap", "name"}
            if p.has("name"):
                # pbrt-v4: the measured coefficients (mm^-1, reduced scattering) replace
                # sigma_a/sigma_s and force g = 0; scale still applies.
                name = p.string("name")
                coeffs = measured_scattering(name)
                if coeffs is None:
                    raise p.error("name", f"unknown measured medium {name!r}{did_you_mean(name, MEASURED_SCATTERING)} "
                                          f"(pbrt-v4's: {', '.join(MEASURED_SCATTERING)})")
                b["sigma_a"], b["sigma_s"] = ({"type": "rgb", "value": list(c)} for c in coeffs)
                for k in ("sigma_a", "sigma_s", "g", "reflectance", "mfp"):
                    if p.has(k):
                        p.p[k].used = True
                        self.note(p.p[k].where, f"Material: subsurface \"name\" {name!r} replaces {k!r} (as in pbrt-v4)")
                skip |= {"sigma_a", "sigma_s", "g", "reflectance", "mfp"}
            for q in p.d.params:
                if q.name in skip:
                    continue
                q.used = True
                if q.name == "remaproughness":
                    b[q.name] = bool(q.values[0])
                elif q.name in ("scale", "eta", "g"):
                    b[q.name] = float(p.one(q.name, "float", None))
                else:
                    kind = "albedo" if q.name == "reflectance" else ("float" if "roughness" in q.name else "unbounded")
                    b[q.name] = self.spectrum_value(q, p, kind)
            return b
        if t in ("", "none"):
            return {"type": "null"}
        raise p.error(None, f"unknown material {t!r} (pbrt-v4's: diffuse, conductor, dielectric, thindielectric, "
                             "coateddiffuse, coatedconductor, diffusetransmission, hair, measured, mix, interface, "
                             "subsurface)")

    # -- media ------------------------------------------------------------------------------------------------
    def medium(self, p: _Params) -> dict:
        t = p.string("type")
        if t is None:
            raise p.error(None, "MakeNamedMedium needs \"string type\"")
        grid = t == "rgbgrid"        # its sigma_a, sigma_s and Le are per-voxel RGB values (read below)
        common = {"sigma_a": None if grid else p.value("sigma_a", 1.0, kind="unbounded"),
                  "sigma_s": None if grid else p.value("sigma_s", 1.0, kind="unbounded"),
                  "scale": p.one("scale", "float", 1.0), "g": p.one("g", "float", 0.0)}
        preset = p.string("preset")
        if preset and t == "rgbgrid":
            raise p.error("preset", "an rgbgrid takes its coefficients from its grids, not a preset")
        if preset:
            # pbrt-v4: the measured coefficients (mm^-1) replace sigma_a and sigma_s, times scale
            if t != "homogeneous":
                self.note(p.p["preset"].where, f"MakeNamedMedium: pbrt-v4 reads 'preset' for homogeneous media "
                                               f"only (a {t} reports it unused); pbr applies it")
            coeffs = measured_scattering(preset)
            if coeffs is None:
                raise p.error("preset", f"unknown preset {preset!r}{did_you_mean(preset, MEASURED_SCATTERING)} "
                                        f"(pbrt-v4's: {', '.join(MEASURED_SCATTERING)})")
            if p.has("sigma_a") or p.has("sigma_s"):
                self.note(p.p["preset"].where, f"MakeNamedMedium: preset {preset!r} replaces sigma_a and sigma_s "
                                               "(as in pbrt-v4)")
            common["sigma_a"], common["sigma_s"] = ({"type": "rgb", "value": list(c)} for c in coeffs)
        le = None if grid else p.value("Le", None, kind="illuminant")
        if le is not None:
            common["Le"] = le
            common["Lescale"] = p.one("Lescale", "float", 1.0)
        if t == "homogeneous":
            return {"type": "homogeneous", **common}
        m = self.ctm()
        p0, p1 = p.vec3("p0", (0, 0, 0)), p.vec3("p1", (1, 1, 1))
        nx, ny, nz = (p.one(k, "integer", 1) for k in ("nx", "ny", "nz"))
        if t == "uniformgrid":
            dens = p.floats("density")
            if dens is None:
                if p.has("temperature"):
                    self.unsupported(p.d, "uniformgrid 'temperature' (blackbody emission grid)")
                raise p.error(None, "uniformgrid needs \"float density\"")
            if len(dens) != nx * ny * nz:
                raise p.error("density", f"has {len(dens)} values, nx*ny*nz = {nx * ny * nz}")
            return {"type": "uniformgrid", "density": np.asarray(dens, dtype=np.float32).reshape(nz, ny, nx),
                    "p0": list(p0), "p1": list(p1), "to_world": _mi_transform(m), **common}
        if t == "rgbgrid":
            out = {"type": "rgbgrid", "p0": list(p0), "p1": list(p1), "to_world": _mi_transform(m),
                   "scale": common["scale"], "g": common["g"]}
            for k in ("sigma_a", "sigma_s", "Le"):
                q = p._get(k, ("rgb",))
                if q is None:
                    continue
                if len(q.values) != 3 * nx * ny * nz:
                    raise p.error(k, f"has {len(q.values) // 3} RGB values, nx*ny*nz = {nx * ny * nz}")
                rgb = self.rgb_value(q, p, q.values, "illuminant" if k == "Le" else "unbounded")
                out[k] = np.asarray(rgb, dtype=np.float32).reshape(nz, ny, nx, 3)
            if "Le" in out:
                out["Lescale"] = p.one("Lescale", "float", 1.0)
            return out
        if t == "cloud" and self.pbr_plugin(MEDIUM_TYPES, "cloud"):
            common.pop("Le", None), common.pop("Lescale", None)    # pbrt-v4's cloud does not emit
            return {"type": "cloud", "p0": list(p0), "p1": list(p1), "to_world": _mi_transform(m),
                    "density": p.one("density", "float", 1.0), "wispiness": p.one("wispiness", "float", 1.0),
                    "frequency": p.one("frequency", "float", 5.0), **common}
        if t == "nanovdb" and self.pbr_plugin(MEDIUM_TYPES, "nanovdb"):
            return self.nanovdb_medium(p, m, common)
        if t in ("cloud", "nanovdb"):
            self.unsupported(p.d, f"medium {t!r} ({'procedural clouds' if t == 'cloud' else 'NanoVDB files'}): "
                                  "a homogeneous medium of its sigma_a/sigma_s is used")
            return {"type": "homogeneous", **common}
        raise p.error("type", f"unknown medium {t!r} (pbrt-v4's: homogeneous, uniformgrid, rgbgrid, cloud, nanovdb)")

    # -- lights ----------------------------------------------------------------------------------------------------
    def _light_scale(self, p, name, value, lum):
        """``{name: value, ...}`` with pbrt-v4's scale, divided by the spectrum's luminance
        unless ``power`` (which pbr's lights normalise themselves) is given. A factor on an
        RGB value is folded into it (so that Mitsuba reads the dict too)."""
        sc = p.one("scale", "float", 1.0)
        power = p.one("power", "float", -1.0)
        out = {name: value}
        if power > 0:
            out["power"] = power
        else:
            if lum <= 0:
                raise p.error(None, "the light's spectrum is black (zero luminance)")
            sc = sc / lum
        if isinstance(value, dict) and value.get("type") == "rgb":
            out[name] = {"type": "rgb", "value": [v * sc for v in value["value"]]}
        elif isinstance(value, float):
            out[name] = value * sc
        elif sc != 1.0:
            out["scale"] = sc
        return out

    def light(self, p: _Params, t: str) -> dict | None:
        m = self.ctm()
        if t == "point":
            i, lum = self.emission(p, "I")
            frm = p.vec3("from", (0, 0, 0))
            return {"type": "point", "to_world": _mi_transform(m @ _translate(*frm)),
                    **self._light_scale(p, "intensity", i, lum)}
        if t == "spot":
            i, lum = self.emission(p, "I")
            frm, to = p.vec3("from", (0, 0, 0)), p.vec3("to", (0, 0, 1))
            cone, delta = p.one("coneangle", "float", 30.0), p.one("conedeltaangle", "float", 5.0)
            self.note(p.d.where, "LightSource: spot falls off linearly in angle between the cone angles "
                                 "(Mitsuba's), pbrt-v4 uses a smoothstep in cos")
            frame = np.linalg.inv(_look_at(frm, to, _any_up(to - frm)))
            return {"type": "spot", "cutoff_angle": cone, "beam_width": max(cone - delta, 0.0),
                    "to_world": _mi_transform(m @ frame), **self._light_scale(p, "intensity", i, lum)}
        if t == "distant":
            l, lum = self.emission(p, "L")
            w = m[:3, :3] @ (p.vec3("to", (0, 0, 1)) - p.vec3("from", (0, 0, 0)))
            if not np.linalg.norm(w) > 0:
                raise p.error("to", "'from' and 'to' coincide: the light has no direction")
            direction = [float(x) for x in w / np.linalg.norm(w)]
            ill = p.one("illuminance", "float", -1.0)
            if ill > 0:
                return {"type": "distant", "L": l, "direction": direction, "scale": p.one("scale", "float", 1.0),
                        "illuminance": ill}
            # pbrt's L times scale is the irradiance on a plane facing the light: Mitsuba's
            # directional light.
            out = self._light_scale(p, "irradiance", l, lum)
            return {"type": "directional", "direction": direction, **out}
        if t == "goniometric":
            i, lum = self.emission(p, "I")
            fname = p.string("filename")
            if fname is None:
                raise p.error(None, "goniometric needs \"string filename\"")
            return {"type": "goniometric", "filename": resolve(fname, self.base),
                    "to_world": _mi_transform(m), **self._light_scale(p, "I", i, lum)}
        if t == "projection":
            fname = p.string("filename")
            if fname is None:
                raise p.error(None, "projection needs \"string filename\"")
            out = {"type": "projection", "filename": resolve(fname, self.base), "fov": p.one("fov", "float", 90.0),
                   "to_world": _mi_transform(m), "scale": p.one("scale", "float", 1.0)}
            if p.one("power", "float", -1.0) > 0:
                out["power"] = p.one("power", "float")
            return out
        if t == "infinite":
            fname = p.string("filename")
            sc = p.one("scale", "float", 1.0)
            if p.has("portal"):
                return self.portal_infinite(p, fname, sc, m)
            if fname is not None:
                return self.image_infinite(p, resolve(fname, self.base), sc, m)
            l, lum = self.emission(p, "L")
            ill = p.one("illuminance", "float", -1.0)
            if ill > 0:
                sc *= ill / math.pi      # pbrt-v4: the upper hemisphere's illuminance of a constant L is pi L
            if isinstance(l, dict) and l.get("type") == "rgb":
                return {"type": "constant", "radiance": {"type": "rgb", "value": [v * sc / lum for v in l["value"]]}}
            return {"type": "constant", "radiance": {"type": "scale", "tex": l, "scale": sc / lum}}
        raise p.error(None, f"unknown light {t!r} (pbrt-v4's: point, spot, distant, goniometric, projection, infinite)")

    def portal_infinite(self, p, fname, sc, m):
        """pbrt-v4's portal light (``PortalImageInfiniteLight``): pbr's ``portalenvmap``.
        The portal's 4 points are in world space (pbrt-v4 ignores the CTM for them); the
        image, or ``L`` converted to sRGB as pbrt-v4 does (without dividing by L's
        luminance: only by the illuminant's), is rotated by the CTM as for ``infinite``."""
        pts = p.array("portal", "point3", 3)
        if pts.shape != (4, 3):
            raise p.error("portal", f"expected 4 points, got {len(pts)}")
        if not self.pbr_plugin(LIGHT_TYPES, "portalenvmap"):
            self.unsupported(p.d, "infinite light 'portal' (Mitsuba 3 has no portal light): "
                                  "the environment without the portal is used")
        if p.one("illuminance", "float", -1.0) > 0:
            self.unsupported(p.d, "infinite light 'illuminance' with a portal")
        if fname is not None:
            if p.has("L"):
                raise p.error("L", "give either \"L\" or \"filename\"")
            out = self.image_infinite(p, resolve(fname, self.base), sc, m)
        else:
            l, _ = self.emission(p, "L")
            rgb = np.maximum(_spectrum_srgb(l), 0.0)
            frame = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)
            out = {"type": "envmap", "data": np.broadcast_to(rgb.astype(np.float32), (2, 4, 3)).copy(),
                   "scale": sc, "to_world": _mi_transform(m @ frame)}
        if out["type"] != "envmap" or not self.pbr_plugin(LIGHT_TYPES, "portalenvmap"):
            return out
        out["type"] = "portalenvmap"
        out["portal"] = pts.tolist()
        return out

    def image_infinite(self, p, fname, sc, m):
        """pbrt-v4's image infinite light: an equal-area octahedral square image, resampled
        to Mitsuba's latitude-longitude ``envmap``."""
        import mitsuba as mi
        if not os.path.exists(fname):
            self.missing(p.d.where, p.d.name, os.path.basename(fname), fname)
            return {"type": "constant", "radiance": sc}
        try:
            bmp = mi.Bitmap(fname).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
        except Exception as e:
            raise p.error("filename", f"cannot read image {fname!r}: {e}") from None
        img = np.asarray(bmp, dtype=np.float32)
        if img.ndim == 2:
            img = img[..., None].repeat(3, axis=2)
        img = img[..., :3]
        if img.shape[0] != img.shape[1]:
            raise p.error("filename", f"pbrt-v4's infinite light takes a square equal-area image, got {img.shape[1]}x{img.shape[0]}")
        if p.one("illuminance", "float", -1.0) > 0:
            self.unsupported(p.d, "infinite light 'illuminance' with an image")
        env = equal_area_to_latlong(img)
        # pbrt's light space has +z up; Mitsuba's envmap has +y up: rotate -90 degrees about x.
        frame = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)
        return {"type": "envmap", "data": env, "scale": sc, "to_world": _mi_transform(m @ frame)}

    def area_light(self, p: _Params, shape: dict, sd: Directive) -> dict:
        l, lum = self.emission(p, "L")
        two = p.bool("twosided", False)
        extra = {}
        if two and self.pbr_plugin(LIGHT_TYPES, "area") and not self.mitsuba:
            extra["twosided"] = True
        elif two:
            self.unsupported(p.d, "two-sided area lights in a dict for Mitsuba 3 (its area emitters emit from the "
                                  "front only): the front is used")
        image = None
        if p.has("filename"):
            if p.has("L"):
                raise p.error("filename", "give either \"L\" or \"filename\" (pbrt-v4)")
            fname = resolve(p.string("filename"), self.base)
            if self.mitsuba:
                self.unsupported(p.d, "area light 'filename' in a dict for Mitsuba 3: L is used")
            elif not os.path.exists(fname):
                self.missing(p.d.where, p.d.name, os.path.basename(fname), fname)
            else:
                # pbrt-v4 looks the image up bilinearly at (u, 1 - v): pbr's imagemap convention.
                image = {"type": "imagemap", "filename": fname, "filter": "bilinear", "wrap": "clamp"}
        sc = p.one("scale", "float", 1.0) / lum
        power = p.one("power", "float", -1.0)
        if power > 0:
            # pbrt-v4 makes one light per shape: per quadric, per triangle of a mesh (each
            # triangle gets the whole 'power').
            if "_light_area" in shape:
                area = shape["_light_area"]
            elif "_tri_areas" in shape:
                tri = shape["_tri_areas"]
                area = float(tri.mean())
                if tri.max() > 1.001 * tri.min():
                    self.unsupported(sd, "'power' on a mesh of unequal triangles (pbrt-v4 gives each triangle "
                                         "the power, so their radiances differ): the mean triangle's radiance "
                                         "(the same total power) is used")
            else:
                raise p.error("power", f"the area of this {shape['type']!r} shape is unknown")
            if not area > 0:
                raise p.error("power", "the emitting shape has no area")
            k_e = math.pi * area * (2 if two else 1)
            if image is not None:
                k_e *= _mean_image_luminance(image["filename"], p)
            sc *= power / k_e
        if image is not None:
            return {"type": "area", "radiance": image if sc == 1.0 else {"type": "scale", "tex": image, "scale": sc},
                    **extra}
        if isinstance(l, float):
            return {"type": "area", "radiance": l * sc, **extra}
        if l.get("type") == "rgb":
            return {"type": "area", "radiance": {"type": "rgb", "value": [v * sc for v in l["value"]]}, **extra}
        return {"type": "area", "radiance": {"type": "scale", "tex": l, "scale": sc}, **extra}

    # -- camera, film, sampler, integrator ------------------------------------------------------------------------
    def finish(self) -> None:
        for name, where in self.material_uses.items():
            if name not in self.named_materials:
                raise XMLError(f"{where}: NamedMaterial: unknown material {name!r}")
        # Materials first, so that a shape's reference to a named material defined after
        # it points backwards (as loaders that instantiate in order need).
        mats = {k: v for k, v in self.out.items() if k.startswith(("mat_", "material_"))}
        self.out = {**mats, **{k: v for k, v in self.out.items() if k not in mats}}
        for v in list(self.out.values()):
            _strip_private(v)
        sensor, integrator = self.sensor(), self.make_integrator()
        if integrator["type"] in ("bdpt", "mlt", "lightpath") and (
                sensor["type"] not in ("perspective", "thinlens") or "to_world_end" in sensor):
            # pbr's light-tracing integrators connect paths to a static perspective camera
            # (pinhole or thin lens) only.
            what = "a moving" if sensor["type"] in ("perspective", "thinlens") else "an"
            self.unsupported(self.integrator, f"{integrator['type']!r} with {what} {sensor['type']!r} camera: "
                                              "'volpath' is used")
            integrator = {"type": "volpath", "max_depth": integrator.get("maxdepth", 5) + 1}
        if not any(isinstance(v, dict) and v.get("type") in ("ply", "sphere", "disk", "cylinder", "bsplinecurve",
                                                            "instance") for v in self.out.values()):
            raise XMLError(f"{self.path}:0: the scene has no shapes")
        self.out["sensor"], self.out["integrator"] = sensor, integrator
        self.lines["scene.sensor"] = self.camera.where if self.camera else f"{self.path}:1"
        self.lines["scene.integrator"] = self.integrator.where if self.integrator else f"{self.path}:1"
        # Keep the sensor and the integrator first, as Mitsuba scenes usually list them.
        self.out = {"type": "scene", "integrator": self.out.pop("integrator"), "sensor": self.out.pop("sensor"),
                    **{k: v for k, v in self.out.items() if k != "type"}}

    def film_size(self):
        f = _Params(self.film, self) if self.film else None
        w = f.one("xresolution", "integer", 1280) if f else 1280
        h = f.one("yresolution", "integer", 720) if f else 720
        o = self.overrides
        if "res" in o or "width" in o:
            nw = int(o.get("res", o.get("width")))
            h = int(o["height"]) if "height" in o else max(1, round(nw * h / w))
            w = nw
        elif "height" in o:
            nh = int(o["height"])
            w, h = max(1, round(nh * w / h)), nh
        return f, w, h

    def exposure(self) -> float:
        """The camera's shutter interval: pbrt-v4's exposure time for the film's sensor."""
        if self.camera is None:
            return 1.0
        p = _Params(self.camera, self)
        return p.one("shutterclose", "float", 1.0) - p.one("shutteropen", "float", 0.0)

    def make_film(self) -> dict:
        """pbrt-v4's film: Mitsuba's ``hdrfilm`` when it gives the same image (an ``rgb``
        film whose pixel sensor is the identity: imaging ratio shutter x iso / 100 = 1, no
        white balance, no ``maxcomponentvalue``, no ``diagonal`` for a realistic camera),
        else pbr's film of pbrt-v4's name and parameters (``mitsuba=True``: hdrfilm, the
        rest noted)."""
        f, w, h = self.film_size()
        t = self.film.args[0] if self.film else "rgb"
        if t not in ("rgb", "gbuffer", "spectral"):
            raise XMLError(f"{self.film.where}: Film: unknown film {t!r} (pbrt-v4's: rgb, gbuffer, spectral)")
        iso = f.one("iso", "float", 100.0) if f else 100.0
        wb = f.one("whitebalance", "float", 0.0) if f else 0.0
        sensor = f.string("sensor", "cie1931") if f else "cie1931"
        ratio = self.exposure() * iso / 100.0
        cam = self.camera.args[0] if self.camera else "perspective"
        plain = (t == "rgb" and ratio == 1.0 and wb == 0 and sensor == "cie1931"
                 and not (f and f.has("maxcomponentvalue")) and not (cam == "realistic" and f and f.has("diagonal")))
        if f is not None and f.has("exposuretime"):
            f.p["exposuretime"].used = True
            self.note(f.p["exposuretime"].where, "Film: 'exposuretime' is not a pbrt-v4 film parameter (pbrt-v4's "
                                                 "exposure time is the camera's shutterclose - shutteropen): ignored")
        if not plain and self.pbr_plugin(FILMS, t):
            film = {"type": t}
            for q in (f.d.params if f else ()):
                if q.name in ("filename", "exposuretime", "xresolution", "yresolution"):
                    q.used = True
                    continue
                if q.name == "sensor" and sensor not in camera_sensors() and sensor != "cie1931":
                    raise f.error("sensor", f"unknown sensor {sensor!r} (pbrt-v4's: cie1931, "
                                            f"{', '.join(camera_sensors())})")
                q.used = True
                film[q.name] = list(q.values) if len(q.values) != 1 else (
                    float(q.values[0]) if q.type == "float" else q.values[0])
            film["xresolution"], film["yresolution"] = w, h
        else:
            film = {"type": "hdrfilm", "width": w, "height": h, "pixel_format": "rgb"}
            if t != "rgb" and self.film is not None:
                self.unsupported(self.film, f"film {t!r}: an RGB hdrfilm is used")
            if f is not None:
                cw = f.floats("cropwindow")
                if cw is not None:
                    if len(cw) != 4:
                        raise f.error("cropwindow", "expected 4 values: x0 x1 y0 y1")
                    x0, x1 = math.ceil(w * cw[0]), math.ceil(w * cw[1])
                    y0, y1 = math.ceil(h * cw[2]), math.ceil(h * cw[3])
                    film.update(crop_offset_x=x0, crop_offset_y=y0, crop_width=max(1, x1 - x0),
                                crop_height=max(1, y1 - y0))
                pb = f.ints("pixelbounds")
                if pb is not None:
                    film.update(crop_offset_x=pb[0], crop_offset_y=pb[2], crop_width=pb[1] - pb[0],
                                crop_height=pb[3] - pb[2])
                if not plain and t == "rgb":
                    self.unsupported(self.film, f"pbrt-v4's pixel sensor (imaging ratio {ratio:g}, white balance "
                                                f"{wb:g}, sensor {sensor!r}, maxcomponentvalue) in a dict for "
                                                "Mitsuba 3: a plain hdrfilm is used")
                for k in ("filename", "maxcomponentvalue", "diagonal", "savefp16", "writefp16", "iso",
                          "whitebalance", "sensor", "nbuckets", "lambdamin", "lambdamax", "coordinatesystem"):
                    if f.has(k):
                        f.p[k].used = True
                self.warn_unused(f, f"film {t!r}")
        film["rfilter"] = self.make_filter()
        return film

    def make_filter(self) -> dict:
        """pbrt-v4's pixel filter with its parameters and defaults (pbr registers each
        under pbrt-v4's name); ``mitsuba=True``: Mitsuba's nearest filter, noted."""
        t = self.filter.args[0] if self.filter is not None else "gaussian"
        f = _Params(self.filter, self) if self.filter is not None else None
        g = (lambda k, dflt: f.one(k, "float", dflt)) if f else (lambda k, dflt: dflt)
        defaults = {"box": 0.5, "gaussian": 1.5, "mitchell": 2.0, "sinc": 4.0, "triangle": 2.0}
        if t == "lanczos":      # not a pbrt-v4 name: its windowed sinc is "sinc"
            self.note(self.filter.where, "PixelFilter: 'lanczos' is pbrt-v3's name of pbrt-v4's 'sinc'")
            t = "sinc"
        if t not in defaults:
            raise XMLError(f"{self.filter.where}: PixelFilter: unknown filter {t!r} "
                           f"(pbrt-v4's: {', '.join(defaults)})")
        rx = g("xradius", defaults[t])
        ry = g("yradius", defaults[t])
        if not self.mitsuba:
            out = {"type": t, "xradius": rx, "yradius": ry}
            if t == "box" and rx == ry == 0.5:
                return {"type": "box"}                       # Mitsuba's box: the same filter
            if t == "gaussian":
                out["sigma"] = g("sigma", 0.5)
            elif t == "mitchell":
                out.update(B=g("B", 1.0 / 3.0), C=g("C", 1.0 / 3.0))
            elif t == "sinc":
                out["tau"] = g("tau", 3.0)
            if f:
                self.warn_unused(f, f"filter {t!r}")
            return out
        # Mitsuba 3's filters: one radius, fixed shapes.
        if t == "box":
            if rx != 0.5 or ry != 0.5:
                self.unsupported(self.filter, "a box filter wider than one pixel in a dict for Mitsuba 3: "
                                              "Mitsuba's box is used")
            return {"type": "box"}
        if t == "gaussian":
            sigma = g("sigma", 0.5)
            self.note(self.filter.where if self.filter else f"{self.path}:1",
                      f"PixelFilter: gaussian of radius {rx} is Mitsuba's, of radius 4 sigma ({4 * sigma})")
            return {"type": "gaussian", "stddev": sigma}
        if t == "triangle":
            if rx != ry:
                self.unsupported(self.filter, "a triangle filter of two radii in a dict for Mitsuba 3: xradius is used")
            return {"type": "tent", "radius": rx}
        if t == "mitchell" and rx == ry == 2.0:
            return {"type": "mitchell", "B": g("B", 1.0 / 3.0), "C": g("C", 1.0 / 3.0)}
        self.unsupported(self.filter, f"pixel filter {t!r} with these parameters in a dict for Mitsuba 3: "
                                      "a Gaussian is used")
        return {"type": "gaussian", "stddev": 0.5}

    def sensor(self) -> dict:
        d = self.camera
        t = d.args[0] if d else "perspective"
        p = _Params(d, self) if d else None
        ctm = self.camera_ctm[0] if d else np.eye(4)
        # pbrt's camera space is left-handed (image x to the right): mirror x for Mitsuba's.
        to_world = np.linalg.inv(ctm) @ _scale(-1, 1, 1)
        s = {}
        if d and not np.allclose(self.camera_ctm[0], self.camera_ctm[1]):
            if self.mitsuba:
                self.unsupported(d, "a moving camera (ActiveTransform EndTime) in a dict for Mitsuba 3: "
                                    "the start transform is used")
            else:
                # pbrt-v4's animated camera transform: the CTM at TransformTimes' start and end.
                s["to_world_end"] = _mi_transform(np.linalg.inv(self.camera_ctm[1]) @ _scale(-1, 1, 1))
                s["transform_times"] = [float(x) for x in self.camera_times]
        _, w, h = self.film_size()
        spp = self.sampler_spp()
        if t in ("perspective", "orthographic"):
            s.update(type=t, to_world=_mi_transform(to_world))
            screen = self.screen_window(p, w, h)
            lr = p.one("lensradius", "float", 0.0) if p else 0.0
            fd = p.one("focaldistance", "float", 1e6) if p else 1e6
            if t == "perspective":
                fov = p.one("fov", "float", 90.0) if p else 90.0
                if screen is None:
                    s.update(fov=fov, fov_axis="smaller")
                else:
                    # pbrt-v4's screen window [x0, x1] x [y0, y1] (in units of tan(fov / 2)):
                    # its width and centre as Mitsuba's fov along x and principal point.
                    x0, x1, y0, y1 = screen
                    tn = math.tan(math.radians(fov) / 2)
                    s.update(fov=math.degrees(2 * math.atan((x1 - x0) / 2 * tn)), fov_axis="x")
                    ppx, ppy = (x0 + x1) / (2 * (x1 - x0)), -(y0 + y1) / (2 * (y1 - y0))
                    if ppx or ppy:
                        s.update(principal_point_offset_x=ppx, principal_point_offset_y=ppy)
                if lr > 0:
                    if "principal_point_offset_x" in s and not self.mitsuba:
                        s.update(lensradius=lr, focaldistance=fd)      # pbr's perspective: a thin lens, shifted
                    else:
                        if "principal_point_offset_x" in s:
                            self.unsupported(d, "a thin lens with an off-centre screen window in a dict for "
                                                "Mitsuba 3: the centred window is used")
                            s.pop("principal_point_offset_x"), s.pop("principal_point_offset_y")
                        s.update(type="thinlens", aperture_radius=lr, focus_distance=fd)
            else:
                # pbrt-v4's screen window is camera-space x, y; Mitsuba's orthographic
                # camera sees [-1, 1] x [-h/w, h/w], scaled and moved by to_world.
                a = w / h
                x0, x1, y0, y1 = screen or ((-a, a, -1.0, 1.0) if a > 1 else (-1.0, 1.0, -1 / a, 1 / a))
                m = _translate(-(x0 + x1) / 2, (y0 + y1) / 2, 0) @ _scale((x1 - x0) / 2, a * (y1 - y0) / 2, 1)
                s["to_world"] = _mi_transform(to_world @ m)
                if lr > 0:
                    self.unsupported(d, "a thin lens on the orthographic camera")
            if p:
                so, sc = p.one("shutteropen", "float", 0.0), p.one("shutterclose", "float", 1.0)
                if p.has("shutteropen") or p.has("shutterclose"):
                    s.update(shutter_open=so, shutter_close=sc)
                self.warn_unused(p, f"camera {t!r}")
        elif t in ("spherical", "realistic"):
            if not self.pbr_plugin(SENSORS, t):
                self.unsupported(d, f"camera {t!r} in a dict for Mitsuba 3: a 90 degree perspective is used")
                s.update(type="perspective", to_world=_mi_transform(to_world), fov=90.0, fov_axis="smaller")
            else:
                s.update(self.passthrough(p, t))
                s["to_world"] = _mi_transform(to_world)
        else:
            raise XMLError(f"{d.where}: Camera: unknown camera {t!r} (pbrt-v4's: perspective, orthographic, "
                           "realistic, spherical)")
        s["film"] = self.make_film()
        s["sampler"] = {"type": "independent", "sample_count": spp}
        if self.camera_medium:
            s["medium"] = {"type": "ref", "id": self.media[self.camera_medium]}
        return {"type": s.pop("type"), **s}

    def screen_window(self, p, w, h):
        """pbrt-v4's screen window (x0, x1, y0, y1) when ``screenwindow`` or
        ``frameaspectratio`` is given (None: the default window of the film's aspect).
        Mitsuba's cameras have square pixels: a window whose aspect is not the film's is
        refused (``approximate``: its x extent is kept)."""
        if p is None or not (p.has("screenwindow") or p.has("frameaspectratio")):
            return None
        frame = p.one("frameaspectratio", "float", w / h)
        if not frame > 0:
            raise p.error("frameaspectratio", f"must be positive, got {frame}")
        sw = p.floats("screenwindow")
        if sw is None:
            sw = [-frame, frame, -1.0, 1.0] if frame > 1 else [-1.0, 1.0, -1 / frame, 1 / frame]
        elif len(sw) != 4:
            raise p.error("screenwindow", f"expected 4 values x0 x1 y0 y1, got {len(sw)}")
        x0, x1, y0, y1 = sw
        if not (x1 != x0 and y1 != y0):
            raise p.error("screenwindow", f"the window is empty: {sw}")
        if not math.isclose((x1 - x0) / (y1 - y0), w / h, rel_tol=1e-4):
            self.unsupported(p.d, f"a screen window of aspect {(x1 - x0) / (y1 - y0):.4g} on a film of aspect "
                                  f"{w / h:.4g} (non-square pixels): a window of the film's aspect around the same "
                                  "centre, as wide, is used")
            cy, hy = (y0 + y1) / 2, (x1 - x0) * h / w / 2 * (1 if y1 > y0 else -1)
            y0, y1 = cy - hy, cy + hy
        return x0, x1, y0, y1

    def sampler_spp(self) -> int:
        spp = 16
        if self.sampler is not None:
            p = _Params(self.sampler, self)
            spp = p.one("pixelsamples", "integer", 16)
            for q in p.d.params:
                q.used = True
            if self.sampler.args[0] not in ("independent",):
                self.note(self.sampler.where, f"Sampler {self.sampler.args[0]!r}: pbr samples independently "
                                              "(the image converges to the same value)")
        return int(self.overrides.get("spp", spp))

    def make_integrator(self) -> dict:
        d = self.integrator
        t = d.args[0] if d else "volpath"
        p = _Params(d, self) if d else None
        maxdepth = p.one("maxdepth", "integer", 5) if p else 5
        if "maxdepth" in self.overrides:
            maxdepth = int(self.overrides["maxdepth"])
            if maxdepth < 0:
                raise XMLError(f"load_file: maxdepth: expected an integer >= 0, got {maxdepth}")
        elif maxdepth < 0:
            # Not one meaning in pbrt-v4: path, simplepath and lightpath never reach it
            # (no limit), volpath and simplevolpath stop at the first vertex
            raise p.error("maxdepth", f"expected an integer >= 0, got {maxdepth} (pbrt-v4's integrators "
                                      "disagree on a negative one)")
        names = {"volpath": "volpath", "path": "path", "bdpt": "bdpt", "mlt": "mlt", "sppm": "sppm",
                 "lightpath": "lightpath", "simplepath": "simplepath", "simplevolpath": "simplevolpath",
                 "randomwalk": "randomwalk", "ambientocclusion": "ambientocclusion", "aov": "aov"}
        if t not in names:
            raise XMLError(f"{d.where}: Integrator: unknown integrator {t!r} (pbrt-v4's: {', '.join(names)})")
        if names[t] not in INTEGRATORS:
            raise XMLError(f"{d.where}: Integrator: {t!r} is not available in pbr")
        out = {"type": names[t]}
        if t in ("volpath", "path", "simplepath", "simplevolpath", "randomwalk", "lightpath"):
            out["max_depth"] = maxdepth + 1          # Mitsuba counts the emitter seen directly as depth 1
        elif t in ("bdpt", "mlt", "sppm"):
            out["maxdepth"] = maxdepth
        if p:
            ls = p.string("lightsampler")
            if ls is not None and t in ("volpath", "path"):
                if ls not in ("uniform", "power", "bvh"):
                    raise p.error("lightsampler", f"expected uniform, power or bvh, got {ls!r}")
                out["light_sampler"] = ls
            if p.bool("regularize", False):
                if t in ("path", "volpath") and not self.mitsuba:
                    out["regularize"] = True     # pbr's path and volpath regularise as pbrt-v4's
                else:
                    self.unsupported(d, f"'regularize' with {t!r}" + (" (Mitsuba's integrators do not regularise)"
                                                                      if self.mitsuba else ""))
            for q in p.d.params:
                if not q.used and t in ("bdpt", "mlt", "sppm", "ambientocclusion"):
                    q.used = True
                    out[q.name] = q.values[0] if len(q.values) == 1 else list(q.values)
            self.warn_unused(p, f"integrator {t!r}")
        return out


# -- helpers ----------------------------------------------------------------------------------------------

# pbrt-v4's directives that pbr reads: one ``_d_<name>`` method each.
DIRECTIVES = frozenset(n[3:] for n in dir(PBRTScene) if n.startswith("_d_"))
# Those pbrt-v4 refuses before WorldBegin (its VERIFY_WORLD); the options (Camera, Film,
# ...) are refused after it (``PBRTScene._option``).
WORLD_ONLY = frozenset(("Shape", "LightSource", "AreaLightSource", "Material", "MakeNamedMaterial", "NamedMaterial",
                        "Texture", "ObjectBegin", "ObjectEnd", "ObjectInstance"))


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in name)


def _strip_private(v):
    if isinstance(v, dict):
        for k in [k for k in v if k.startswith("_")]:
            del v[k]
        for c in v.values():
            _strip_private(c)


def _metal_name(s: str, comp: str):
    parts = s.split("-")
    if len(parts) == 3 and parts[0] == "metal" and parts[2] == comp:
        return _METALS.get(parts[1])
    return None


def _area_scale(m) -> float:
    """How a uniformly scaling transform scales areas (|det|^(2/3))."""
    return abs(np.linalg.det(m[:3, :3])) ** (2.0 / 3.0)


def _is_similarity(m) -> bool:
    a = m[:3, :3]
    g = a.T @ a
    return np.allclose(g, np.eye(3) * g[0, 0], rtol=1e-6, atol=1e-9 * max(g[0, 0], 1e-300))


def _any_up(d):
    d = np.asarray(d, dtype=np.float64)
    return np.array([1.0, 0, 0]) if abs(d[1]) > 0.99 * np.linalg.norm(d) else np.array([0, 1.0, 0])


def _affine3_to4(m3):
    m = np.eye(4)
    m[:2, :2] = m3[:2, :2]
    m[:2, 3] = m3[:2, 2]
    return m


def _grid_mesh(fn, nu, nv):
    """Triangles of a (nu+1) x (nv+1) grid of points fn(u, v), u, v in [0, 1]."""
    u, v = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    pos = fn(u.ravel(), v.ravel())
    i = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel()
    tri = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    uv = np.stack([u.ravel(), v.ravel()], 1)
    return pos, tri, None, uv


def _sphere_mesh(r, zmin, zmax, phimax, n=96):
    t0, t1 = math.acos(np.clip(zmin / r, -1, 1)), math.acos(np.clip(zmax / r, -1, 1))
    ph = math.radians(min(phimax, 360.0))

    def f(u, v):
        th = t0 + v * (t1 - t0)
        return np.stack([r * np.sin(th) * np.cos(u * ph), r * np.sin(th) * np.sin(u * ph), r * np.cos(th)], 1)
    pos, tri, _, uv = _grid_mesh(f, n, n // 2)
    return pos, tri, pos / r, uv


def _disk_mesh(h, r, ri, phimax, n=96):
    ph = math.radians(min(phimax, 360.0))

    def f(u, v):
        rr = r + v * (ri - r)
        return np.stack([rr * np.cos(u * ph), rr * np.sin(u * ph), np.full_like(u, h)], 1)
    pos, tri, _, uv = _grid_mesh(f, n, 4)
    return pos, tri, np.tile([0.0, 0.0, 1.0], (len(pos), 1)), uv


def _cylinder_mesh(r, zmin, zmax, phimax, n=96):
    ph = math.radians(min(phimax, 360.0))

    def f(u, v):
        return np.stack([r * np.cos(u * ph), r * np.sin(u * ph), zmin + v * (zmax - zmin)], 1)
    pos, tri, _, uv = _grid_mesh(f, n, 4)
    nrm = pos.copy()
    nrm[:, 2] = 0
    return pos, tri, nrm / r, uv


def equal_area_to_latlong(img: np.ndarray, height: int | None = None) -> np.ndarray:
    """Resample pbrt-v4's equal-area octahedral image (Clarberg's mapping, +z up in light
    space) to a latitude-longitude map in pbrt's light space (rows: polar angle from +z)."""
    n = img.shape[0]
    h = height or max(8, n // 2)
    w = 2 * h
    theta = (np.arange(h) + 0.5) / h * math.pi
    phi = (np.arange(w) + 0.5) / w * 2 * math.pi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    # The direction of Mitsuba's envmap texel (u, v) = (phi / 2 pi, theta / pi) in its
    # +y-up frame, then in pbrt's light space (+z up; the caller's frame maps one to the other).
    mx, my, mz = np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)
    px, py, pz = mx, -mz, my
    st = equal_area_sphere_to_square(np.stack([px, py, pz], axis=-1))
    s, t = st[..., 0], st[..., 1]
    xi = np.clip((s * n).astype(int), 0, n - 1)
    yi = np.clip((t * n).astype(int), 0, n - 1)
    return img[yi, xi]


@backend.uses_pbr_variant
def convert(path: str, approximate: bool = False, mesh_dir: str | None = None, skip_missing: bool = False,
            mitsuba: bool = False, **overrides):
    """(scene dict, notes, key path -> ``file:line``) of a pbrt-v4 file (see :func:`to_dict`).
    ``notes``: ``file:line: ...`` messages on what was ignored or approximated;
    ``skip_missing``: leave out objects whose files are missing, with a note;
    ``mitsuba``: keep to Mitsuba 3's plugins (hdrfilm, its filters, bitmap and its
    checkerboard, a static camera), so that ``mi.load_dict`` renders the dict; what
    Mitsuba lacks is refused (``approximate``: substituted, noted). By default pbrt-v4's
    filters, films, cameras, camera motion and textures map to pbr's plugins of pbrt-v4's
    names, so the image is pbrt-v4's."""
    backend.ensure()   # transforms are Mitsuba objects: a variant must be set
    unknown = set(overrides) - {"spp", "res", "width", "height", "maxdepth"}
    if unknown:
        raise XMLError(f"{path}:0: unknown override(s) {sorted(unknown)} (pbrt scenes take spp, res, width, "
                       "height, maxdepth)")
    c = PBRTScene(path, approximate, mesh_dir, overrides, skip_missing, mitsuba)
    d = c.read()
    return d, c.notes, c.lines


@backend.uses_pbr_variant
def to_dict(path: str, approximate: bool = False, mesh_dir: str | None = None, mitsuba: bool = False,
            **overrides) -> dict:
    """A pbr/Mitsuba scene dict of the pbrt-v4 scene file ``path``.

    ``overrides``: ``spp``, ``res`` (image width, aspect kept) or ``width``/``height``,
    ``maxdepth`` (pbrt-v4's). ``approximate``: substitute what pbr cannot render (see
    :func:`convert` for the notes) instead of raising. Meshes are written as PLY files to
    ``mesh_dir`` (default: a ``pbr-pbrt-meshes`` folder in the temporary directory), so
    the dict can be saved as Mitsuba XML (``pbr.scene.xml.to_xml``); volume grids stay
    numpy arrays."""
    return convert(path, approximate, mesh_dir, mitsuba=mitsuba, **overrides)[0]
