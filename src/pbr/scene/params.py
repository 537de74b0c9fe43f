"""``pbr.traverse``: a scene's parameters under ``mi.traverse``'s keys, with
``mitsuba.SceneParameters``'s methods.

Three kinds of keys (``flags(key)`` tells them apart, with Mitsuba's ``mi.ParamFlags``):

- pbr's differentiable parameters: textures, BSDF scalars, emitter radiance, media
  (``red.reflectance.value``, ``light.emitter.radiance.value``, ``<id>.reflectance.data``
  for bitmaps, ``ball.interior_medium.sigma_t.value.value``, ``smoke.sigma_t.data``).
  Enable gradients on them or assign new values, then call ``update()`` to rebuild the
  scene's tables (which keeps the AD graph to the parameters).
- geometry, Mitsuba's own keys of the shapes pbr hands to Mitsuba: ``<shape>.to_world``
  (rectangle, disk, sphere, cylinder), ``<mesh>.vertex_positions``, ``vertex_normals``,
  ``vertex_texcoords``, ``faces``, with Mitsuba's flags (positions and transforms are
  differentiable and discontinuous; ``faces`` and the geometry of emissive shapes are not
  differentiable in pbr). ``update()`` lets Mitsuba rebuild the shapes and its
  ray-tracing acceleration structure (``parameters_changed``); moved vertices or
  transforms then rebuild only the lights of emissive shapes and what the integrator
  derives from the geometry (``Scene.geometry_changed``), other changes every table.
  Derivatives: interior ones in ``path``/``prb``/``prbvolpath``, boundary ones (silhouettes,
  shadows) in the projective integrators. Inside ``pbr.freeze``, an update of moved
  vertices or transforms (of shapes that emit no light) only assigns the arrays: Mitsuba
  rebuilds its acceleration structure on the host, which a recording cannot replay, so
  ``pbr.freeze`` rebuilds it after each call (recorded or replayed), and no ray may be
  traced in between (:func:`geometry_deferred`).
- the sensor: ``<sensor>.to_world`` (rigid), ``x_fov`` (degrees), ``near_clip``,
  ``far_clip``, ``principal_point_offset_x``/``_y`` (a ``thinlens``: ``aperture_radius``,
  ``focus_distance`` too); the film's ``size``, ``crop_size``
  and ``crop_offset`` are read-only (load the scene with another film to change them).
  Not differentiable in pbr, except a perspective camera's ``to_world`` (its pose: the
  projective integrators differentiate it; the attached value is kept as the camera's
  ``to_world_ad``).

Mitsuba keys pbr does not have (documented exceptions): ``allow_thread_reordering``
(a CUDA scheduling hint of Mitsuba's), ``<shape>.silhouette_sampling_weight`` (Mitsuba's
projective integrators), ``<sensor>.shutter_open`` / ``shutter_open_time`` (no motion
blur), ``<emitter>.sampling_weight`` (pbr's light samplers weigh lights by power or its
BVH), ``<emitter>.radiance.d65.*`` (an RGB emitter's D65 factor is fixed in pbr), and the
``object_...`` names of shapes Mitsuba merges by default (pbr never merges shapes: its
keys are those of ``mi.load_dict(d, optimize=False)``). Keys not exposed yet (plastic
``eta``, light ``to_world``/``position``, texture ``to_uv``, tabulated spectra, ...) are
listed in docs/porting_from_mitsuba.md.

As in Mitsuba, iterating over the parameters gives ``(key, value)`` pairs, ``update(values)``
skips keys it does not have, and ``keep`` takes a regular expression or a list of them.

``tables_as_leaves``: forward-mode differentiation inside a symbolic loop can only start
from variables whose tangents are already known; it may not cross an edge built outside
the loop (Dr.Jit: "outside of the current dr.isolate_grad() scope"). The tables built
from parameters are such edges, so for a forward pass they are replaced by leaves that
carry the tangent the parameters give them.
"""

from __future__ import annotations

import contextlib
import re

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import backend
from ..bsdfs import bsdf_names
from ..cameras import SENSORS
from ..geometry import SHAPE_PARAMS
from ..lights import LIGHT_TYPES
from ..media import MEDIUM_TYPES
from ..plugins.params import check_params
from ..plugins.tables import map_tables
from .views import variant_types

# Mitsuba's shape keys that pbr exposes (Mitsuba's traversal of pbr's geometry also has
# the placeholder BSDF Mitsuba gives every shape, and silhouette weights).
GEOMETRY_KEYS = ("to_world", "vertex_positions", "vertex_normals", "vertex_texcoords", "faces")

DIFFERENTIABLE = 0

# Set while pbr.freeze calls a frozen function: it rebuilds the geometry after the call.
_deferring = [0]


@contextlib.contextmanager
def geometry_deferred():
    """Within the block (``pbr.freeze``'s call of a frozen function), ``update()`` of moved
    vertices or transforms inside the recording assigns them and leaves Mitsuba's rebuild
    (its acceleration structure, built on the host) to the caller, which runs it after the
    call; until then the scene's geometry refuses ray queries (``Geometry.stale``)."""
    _deferring[0] += 1
    try:
        yield
    finally:
        _deferring[0] -= 1


def _flags(*names) -> int:
    return int(sum(int(getattr(mi.ParamFlags, n)) for n in names))


def _matrix(value, key: str) -> np.ndarray:
    """A 4x4 float64 matrix from a Mitsuba transform (anything with ``.matrix``) or an
    array-like."""
    m = value.matrix if hasattr(value, "matrix") else value
    try:
        a = np.array(m, dtype=np.float64)
    except Exception as e:
        raise TypeError(f"{key}: expected a Mitsuba transform or a 4x4 matrix, got {type(value).__name__}: {e}") from None
    a = a.reshape(a.shape[:2]) if a.ndim == 3 and a.shape[2] == 1 else a
    if a.shape != (4, 4):
        raise ValueError(f"{key}: expected a 4x4 transform, got shape {a.shape}")
    return a


# Mitsuba's names of a shape's children, in the order its traversal visits them.
SHAPE_CHILDREN = ("bsdf", "emitter", "interior_medium", "exterior_medium")

# Mitsuba's names of the BSDFs nested in a BSDF (in declaration order), whatever their keys
# in the dict or XML, and of a bump map's texture.
NESTED_BSDFS = {"blendbsdf": ("bsdf_0", "bsdf_1"), "twosided": ("brdf_0", "brdf_1"),
                "mask": ("nested_bsdf",), "normalmap": ("nested_bsdf",), "bumpmap": ("nested_bsdf",)}
NESTED_TEXTURES = {"bumpmap": "nested_texture"}


def mitsuba_key_paths(d: dict) -> dict:
    """Declared key path -> ``mi.traverse``'s key path, for the objects of scene dict
    ``d`` whose keys differ (paths without the leading ``scene.``).

    ``mi.traverse`` names a shape's children by role (``<shape>.bsdf``, ``.emitter``,
    ``.interior_medium``, ``.exterior_medium``) and a sensor's medium ``<sensor>.medium``,
    whatever their keys in the dict (the XML reader names unnamed children ``emitter_0``),
    and the BSDFs nested in a BSDF by position (``bsdf_0``/``bsdf_1`` in a blend,
    ``brdf_0``/``brdf_1`` in a twosided, ``nested_bsdf``; :data:`NESTED_BSDFS`).
    It lists an object once, where the traversal first reaches it: the top-level entries
    in order, each followed by its children; so a BSDF or medium referenced by a shape
    (or the sensor) declared before it takes that shape's key (``s.bsdf``)."""
    ids = {}

    def collect(v, path, top):
        for k, c in v.items():
            if isinstance(c, dict) and "type" in c and c["type"] != "ref":
                p = f"{path}.{k}" if path else k
                oid = c.get("id", k if top else None)
                if oid is not None:
                    ids.setdefault(str(oid), (p, c["type"]))
                collect(c, p, False)

    collect(d, "", True)
    out, reached = {}, set()

    def reach(declared, key):
        if declared not in reached:
            reached.add(declared)
            if declared != key:
                out[declared] = key

    def role(k, c, owner_type):
        t = ids.get(c.get("id"), (None, None))[1] if c["type"] == "ref" else c["type"]
        if owner_type in SENSORS:
            return "medium" if t in MEDIUM_TYPES else None
        if k in ("interior", "exterior"):
            return f"{k}_medium"
        return "bsdf" if t in bsdf_names() else ("emitter" if t in LIGHT_TYPES else None)

    for key, v in d.items():
        if not isinstance(v, dict) or "type" not in v:
            continue
        reach(key, key)
        if v["type"] not in SHAPE_PARAMS and v["type"] not in SENSORS:
            continue
        children = [(role(k, c, v["type"]), k, c) for k, c in v.items() if isinstance(c, dict) and "type" in c]
        order = SHAPE_CHILDREN + ("medium",)
        for name, k, c in sorted((x for x in children if x[0]), key=lambda x: order.index(x[0])):
            target = ids.get(c.get("id")) if c["type"] == "ref" else None
            reach(target[0] if target else f"{key}.{k}", f"{key}.{name}")

    def renamed(path):
        parts = path.split(".")
        for n in range(len(parts), 0, -1):
            if ".".join(parts[:n]) in out:
                return ".".join([out[".".join(parts[:n])]] + parts[n:])
        return path

    def nested(v, path):
        """A wrapper BSDF's inline children take Mitsuba's names (``bsdf_0``, ``brdf_0``,
        ``nested_bsdf``, ...), below the parent's own Mitsuba path."""
        for k, c in v.items():
            if not (isinstance(c, dict) and "type" in c and c["type"] != "ref"):
                continue
            p = f"{path}.{k}" if path else k
            kids = [(kk, cc) for kk, cc in c.items() if isinstance(cc, dict) and "type" in cc]
            kinds = [ids.get(cc.get("id"), (None, None))[1] if cc["type"] == "ref" else cc["type"] for _, cc in kids]
            bsdfs = [(kk, cc) for (kk, cc), t in zip(kids, kinds) if t in bsdf_names()]
            texture = [(kk, cc) for (kk, cc), t in zip(kids, kinds) if t not in bsdf_names()]
            named = list(zip(bsdfs, NESTED_BSDFS.get(c["type"], ())))
            if c["type"] in NESTED_TEXTURES and texture:
                named.append((texture[0], NESTED_TEXTURES[c["type"]]))
            for (kk, cc), name in named:
                if cc["type"] != "ref" and renamed(f"{p}.{kk}") != f"{renamed(p)}.{name}":
                    out[f"{p}.{kk}"] = f"{renamed(p)}.{name}"
            nested(c, p)

    nested(d, "")
    return out


def rename_key_paths(owners, paths: dict) -> None:
    """Give each parameter owner the key path of :func:`mitsuba_key_paths` (the longest
    declared prefix of its path that ``paths`` renames)."""
    for owner in owners:
        parts = owner.path.split(".")
        for n in range(len(parts), 0, -1):
            new = paths.get(".".join(parts[:n]))
            if new is not None:
                owner.path = ".".join([new] + parts[n:])
                break


# Mesh keys of Mitsuba after 3.9 (its redesigned Mesh class, which the current Mitsuba
# tutorials use: (N, 3) tensors) and their Mitsuba 3.9 names (flat arrays), which pbr has.
_NEWER_MESH_KEYS = {"positions": "vertex_positions", "normals": "vertex_normals",
                    "texcoords": "vertex_texcoords"}


def _newer_mesh_key_hint(key, known) -> str:
    """For ``<mesh>.positions`` (and normals, texcoords): the Mitsuba 3.9 key pbr has."""
    head, _, last = key.rpartition(".")
    old = f"{head}.{_NEWER_MESH_KEYS.get(last, '')}"
    if not head or last not in _NEWER_MESH_KEYS or old not in known:
        return ""
    return (f" (pbr uses Mitsuba 3.9's mesh keys: {old!r}, a flat array x0, y0, z0, x1, ...; "
            f"dr.unravel(mi.Point3f, params[{old!r}]) gives the points, dr.ravel(points) "
            f"sets them. '{last}' as an (N, 3) tensor is a later Mitsuba's name)")


class _Param:
    """One key: how to read and write it, its Mitsuba flags, and what it belongs to."""

    kind = "pbr"

    def __init__(self, owner, name, flags=DIFFERENTIABLE):
        self.owner, self.name, self.flags = owner, name, flags

    def get(self):
        return self.owner.params[self.name]

    def set(self, key, value):
        old = self.get()
        tp = type(old)
        try:
            # Always a handle of its own (the same variables): a replay of dr.freeze writes
            # its outputs into nested arrays in place, and an object shared with the
            # optimiser (params[k] = opt[k] at the end of a frozen step) was left with the
            # old values (measured: Adam's steps lost on every replay).
            value = tp(value)
        except Exception as e:
            raise TypeError(f"{key}: cannot convert {type(value).__name__} to {tp.__name__}: {e}") from None
        if dr.width(value) != dr.width(old) or getattr(value, "shape", None) != getattr(old, "shape", None):
            raise ValueError(f"{key}: shape {getattr(value, 'shape', None)} does not match {getattr(old, 'shape', None)}")
        self.owner.params[self.name] = value


class _GeometryParam(_Param):
    """A key of Mitsuba's traversal of the geometry (``mp``: its ``SceneParameters``),
    with Mitsuba's flags (``vertex_positions`` and ``to_world`` are differentiable and
    discontinuous, normals and uvs differentiable), except: ``faces``, and every key of an
    emissive shape (pbr's area-light tables are built on the host), are not
    differentiable."""

    kind = "geometry"

    def __init__(self, mp, mkey, shape, emissive=False):
        flags = int(mp.flags(mkey)) if hasattr(mp, "flags") else _flags("NonDifferentiable")
        if emissive or mkey.endswith(".faces"):
            flags = _flags("NonDifferentiable")
        super().__init__(shape, mkey, flags)
        self.mp, self.emissive = mp, emissive

    def get(self):
        return self.mp[self.name]

    def set(self, key, value):
        if self.name.endswith(".to_world"):
            m = value.matrix if hasattr(value, "matrix") else value
            if isinstance(m, dr.ArrayBase) and dr.is_jit_v(m):
                value = variant_types().Transform4f(m)     # keeps its AD graph
            else:
                value = variant_types().Transform4f(_matrix(value, key).tolist())
        elif self.flags & int(mi.ParamFlags.NonDifferentiable) and dr.grad_enabled(value):
            raise ValueError(f"{key}: not differentiable in pbr (faces, and the geometry of emissive shapes, "
                             f"whose light tables are built on the host): disable its gradients")
        if dr.detail.collect_indices(value) == dr.detail.collect_indices(self.get()):
            # The same variables (e.g. params.update(opt) again with an unchanged opt):
            # nothing changes, as in Mitsuba, which would compare the values on the host
            # first (not possible inside dr.freeze).
            return False
        self.mp[self.name] = value


class _SensorParam(_Param):
    """A sensor attribute: ``to_world`` (a 4x4 array on pbr's camera), ``pp`` components,
    or a float."""

    kind = "sensor"

    def __init__(self, camera, name, read_only=False):
        flags = _flags("NonDifferentiable", "ReadOnly") if read_only else _flags("NonDifferentiable")
        if name == "to_world" and hasattr(camera, "sample_ray_attached"):
            flags = _flags("Discontinuous")   # a pinhole's pose: differentiable (projective integrators)
        super().__init__(camera, name, flags)

    def get(self):
        t, cam = variant_types(), self.owner
        if self.name == "to_world":
            if cam.to_world_ad is not None:
                return t.Transform4f(cam.to_world_ad)
            return t.Transform4f(np.asarray(cam.to_world, np.float64).tolist())
        if self.name.startswith("principal_point_offset_"):
            return t.Float(cam.pp["xy".index(self.name[-1])])
        if self.name in ("x_fov", "aperture_radius", "focus_distance"):
            return t.Float(getattr(cam, self.name))
        if self.name.startswith("film."):
            film = cam.film
            w, h = film.size
            if self.name == "film.size":
                return t.ScalarVector2u(w, h)
            if self.name == "film.crop_size":
                return t.ScalarVector2u(*getattr(film, "crop_size", (w, h)))
            return t.ScalarPoint2u(*getattr(film, "crop_offset", (0, 0)))
        return float(getattr(cam, self.name))

    def set(self, key, value):
        cam = self.owner
        if self.name == "to_world":
            mat = value.matrix if hasattr(value, "matrix") else value
            attached = isinstance(mat, dr.ArrayBase) and dr.grad_enabled(mat)
            if attached and self.flags & int(mi.ParamFlags.NonDifferentiable):
                raise ValueError(f"{key}: the pose of a {type(cam).name!r} camera is not differentiable in pbr "
                                 f"(a 'perspective' camera's is)")
            m = _matrix(dr.detach(mat) if attached else value, key)
            lin = m[:3, :3]
            if not np.allclose(lin.T @ lin, np.eye(3), atol=1e-4):
                raise ValueError(f"{key}: the camera-to-world transform must be rigid (no scale or shear)")
            cam.to_world = m
            cam.to_world_ad = variant_types().Matrix4f(mat) if attached else None
            return
        try:
            v = float(np.asarray(value, np.float64).ravel()[0]) if not isinstance(value, (int, float)) else float(value)
        except Exception as e:
            raise TypeError(f"{key}: expected a number, got {type(value).__name__}: {e}") from None
        if self.name.startswith("principal_point_offset_"):
            pp = list(cam.pp)
            pp["xy".index(self.name[-1])] = v
            cam.pp = tuple(pp)
        elif self.name == "x_fov":
            if not 0.0 < v < 180.0:
                raise ValueError(f"{key}: expected a field of view in (0, 180) degrees, got {v}")
            cam.x_fov = v
        elif self.name in ("aperture_radius", "focus_distance"):
            if not v >= 0.0:
                raise ValueError(f"{key}: expected a distance >= 0, got {v}")
            if self.name == "aperture_radius" and v == 0.0:    # as loading: Mitsuba's epsilon
                v = float(np.finfo(np.float32).eps)
            setattr(cam, self.name, v)
        else:
            if v < 0:
                raise ValueError(f"{key}: expected a distance >= 0, got {v}")
            near, far = (v, cam.far_clip) if self.name == "near_clip" else (cam.near_clip, v)
            if far <= near:
                raise ValueError(f"{key}: far_clip ({far}) must exceed near_clip ({near})")
            setattr(cam, self.name, v)


def _sensor_params(camera) -> dict:
    """name -> _SensorParam for the attributes ``camera`` has."""
    out = {}
    for name in ("near_clip", "far_clip", "x_fov", "to_world"):
        if hasattr(camera, name):
            out[name] = _SensorParam(camera, name)
    if getattr(camera, "name", None) == "thinlens":
        for name in ("aperture_radius", "focus_distance"):
            out[name] = _SensorParam(camera, name)
    if hasattr(camera, "pp"):
        for axis in "xy":
            out[f"principal_point_offset_{axis}"] = _SensorParam(camera, f"principal_point_offset_{axis}")
    if hasattr(camera, "film"):
        for name in ("film.size", "film.crop_size", "film.crop_offset"):
            out[name] = _SensorParam(camera, name, read_only=True)
    return out


class SceneParameters:
    """The parameters of a pbr scene, with the methods of ``mitsuba.SceneParameters``
    (see the module docstring). Made by :func:`traverse`."""

    def __init__(self, scene):
        self.scene = scene
        params: dict[str, _Param] = {}
        for i, cam in enumerate(scene.sensors):
            sid = getattr(cam, "id", "sensor" if i == 0 else f"sensor_{i}")
            for name, p in _sensor_params(cam).items():
                params[f"{sid}.{name}"] = p
        for owner in scene.param_owners():
            if not getattr(owner, "traversed", True):
                continue
            for name in owner.params:
                params[f"{owner.path}.{name}"] = _Param(owner, name)
        self._mp = mi.traverse(scene.mi_scene)
        shapes = {s.id(): s for s in scene.mi_scene.shapes()}
        emissive = {str(scene.shape_ids[i]) for i in scene.top_level_shapes() if scene.shape_emitter[i]}
        for mkey in self._mp.keys():
            sid, _, name = mkey.rpartition(".")
            if name in GEOMETRY_KEYS and sid in shapes and mkey not in params:
                params[mkey] = _GeometryParam(self._mp, mkey, shapes[sid], sid in emissive)
        self._params = params
        self._dirty: set[str] = set()
        self._unchanged = False    # a key was assigned the variables it held already
        self._geometry_read = False

    # -- mapping ----------------------------------------------------------------------
    def keys(self):
        return self._params.keys()

    def values(self):
        return [self[k] for k in self._params]

    def items(self):
        """``(key, value)`` pairs (a list)."""
        return [(k, self[k]) for k in self._params]

    def __iter__(self):
        """``(key, value)`` pairs, as iterating over Mitsuba's ``SceneParameters`` gives."""
        return iter(self.items())

    def __contains__(self, key):
        return key in self._params

    def __len__(self):
        return len(self._params)

    def _param(self, key) -> _Param:
        if key not in self._params:
            near = [k for k in self._params if key.split(".")[0] == k.split(".")[0]] or list(self._params)
            raise KeyError(f"{key!r} is not a parameter of this scene{_newer_mesh_key_hint(key, self._params)}; "
                           f"known keys: {', '.join(near)}")
        return self._params[key]

    def __getitem__(self, key):
        p = self._param(key)
        if p.kind == "geometry":
            self._geometry_read = True   # Mitsuba's parameters notice in-place changes
        return p.get()

    def get(self, key, default=None):
        """``params[key]``, or ``default`` when the scene has no such key."""
        return self[key] if key in self._params else default

    def __setitem__(self, key, value):
        p = self._param(key)
        if p.flags & int(mi.ParamFlags.ReadOnly):
            raise ValueError(f"{key} is read-only in pbr (load the scene with another film to change it)")
        if p.set(key, value) is not False:
            self._dirty.add(key)
        else:
            self._unchanged = True

    def __delitem__(self, key):
        self._param(key)
        del self._params[key]

    def flags(self, key) -> int:
        """Mitsuba's ``ParamFlags`` of ``key``: 0 (differentiable) for pbr's parameters,
        ``NonDifferentiable`` for geometry and sensor keys (``| ReadOnly`` for the film's)."""
        return self._param(key).flags

    def set_dirty(self, key) -> None:
        """Mark ``key`` as changed (after an in-place change such as ``dr.scatter`` into
        its value): the next :meth:`update` refreshes what depends on it."""
        p = self._param(key)
        if p.kind == "geometry":
            self._mp.set_dirty(p.name)
        self._dirty.add(key)

    def keep(self, keys) -> None:
        """Keep only the keys that match ``keys``: a regular expression (matched at the start
        of the key, as ``re.match``), a list of them, or None for the differentiable keys."""
        if keys is None:
            kept = [k for k, p in self._params.items() if not p.flags & int(mi.ParamFlags.NonDifferentiable)]
        else:
            regexps = [re.compile(k).match for k in (keys if isinstance(keys, (list, tuple)) else [keys])]
            kept = [k for k in self._params if any(r(k) for r in regexps)]
        self._params = {k: self._params[k] for k in kept}

    def copy(self) -> "SceneParameters":
        c = object.__new__(SceneParameters)
        c.__dict__.update(self.__dict__)
        c._params, c._dirty = dict(self._params), set()
        return c

    # -- update -------------------------------------------------------------------------
    def update(self, values: dict | None = None) -> list:
        """Apply ``values`` (keys this object lacks are skipped, as Mitsuba does), then
        refresh what depends on the changed parameters. Returns Mitsuba's kind of answer:
        a list of ``(object, set of parameter names)`` for each object that changed.

        Assigned values are checked first: finite, and in the parameter's range (an
        albedo in [0, 1], radiance >= 0, ...), else ``pbr.SceneError`` naming the key (clip
        an optimiser's values into range before the update; not checked inside
        ``dr.freeze``). When every changed key is a BSDF's constant or bitmap texture or a
        BSDF's own scalar (a dielectric's or coating's ``eta``), only those value tables are
        recomputed, with Dr.Jit operations alone (so that an update can be part of a
        ``dr.freeze``-recorded step). Sensor keys need nothing rebuilt (the next render
        reads them). Geometry keys make Mitsuba rebuild the shapes and its acceleration
        structure (pending kernels are evaluated first: they hold a reference to it);
        inside ``pbr.freeze``, moved vertices or transforms are assigned and rebuilt after
        the call (a ray query before then raises an error).
        Otherwise, and when nothing was assigned (e.g. after ``dr.enable_grad(params[k])``),
        the whole scene is rebuilt."""
        with backend.pbr_variant():
            return self._update(values)

    def _update(self, values):
        for k, v in (values or {}).items():
            if k in self._params:
                self[k] = v
        params = self._params
        dirty = {k: params[k] for k in self._dirty if k in params}
        unchanged, self._unchanged = self._unchanged, False
        if unchanged and not dirty:
            return []      # only values assigned again: nothing to refresh
        geometry = [k for k, p in dirty.items() if p.kind == "geometry"]
        sensors = [k for k, p in dirty.items() if p.kind == "sensor"]
        pbr_keys = [k for k, p in dirty.items() if p.kind == "pbr"]
        changed: dict[int, tuple] = {}
        for k, p in dirty.items():
            changed.setdefault(id(p.owner), (p.owner, set()))[1].add(p.name.rsplit(".", 1)[-1])
        freezing = dr.flag(dr.JitFlag.FreezingScope)
        # The assigned values must be finite and in their ranges (a SceneError names the
        # key). Not inside dr.freeze, which cannot read values.
        if not freezing:
            for k in sorted(pbr_keys):
                p = params[k]
                check_params(p.owner, [p.name], path=k[:-len(p.name) - 1] if k.endswith("." + p.name) else None)
        if freezing and sensors:
            raise RuntimeError(
                f"params.update(): {', '.join(sorted(sensors))} cannot be updated inside a "
                "dr.freeze-recorded function (a recording replays the camera it saw)")
        if freezing and geometry:
            self._defer_geometry(geometry)
            geometry = []
        rebuild, moved = False, []
        if geometry or (self._geometry_read and not freezing):
            dr.eval()                           # kernels that reference the old geometry
            for obj, names in self._mp.update():
                if obj is not self.scene.mi_scene:
                    changed.setdefault(id(obj), (obj, set()))[1].update(names)
                    moved.append((obj, set(names)))
            self._geometry_read = False
        if not rebuild and (pbr_keys or not dirty):
            rebuild = not self._refresh_values(pbr_keys) if pbr_keys else True
        if rebuild:
            if freezing:
                raise RuntimeError(
                    f"params.update(): {', '.join(sorted(pbr_keys)) or 'an update with no assigned keys'} "
                    "needs a rebuild of the scene's tables, which reads parameters on the host and "
                    "cannot be recorded by dr.freeze; inside a frozen function only BSDF textures "
                    "(constant or bitmap, e.g. '<bsdf>.reflectance.value' / '.data') and a BSDF's "
                    "'eta' can be updated")
            self.scene.build()
        elif moved:
            self.scene.geometry_changed(moved)
        self._dirty.clear()
        return list(changed.values())

    def _defer_geometry(self, keys) -> None:
        """Inside ``pbr.freeze``: leave the rebuild of the shapes of ``keys`` (assigned
        already) to ``pbr.freeze``, after the call; refuse what it cannot rebuild there."""
        keys = sorted(keys)
        if not _deferring[0]:
            raise RuntimeError(
                f"params.update(): {', '.join(keys)} cannot be updated inside a dr.freeze-recorded "
                "function: Mitsuba rebuilds its ray-tracing acceleration structure on the host, which "
                "a recording cannot replay; use pbr.freeze, which rebuilds it after each call")
        moving = self.scene.MOVING_KEYS
        bad = [k for k in keys if k.rsplit(".", 1)[-1] not in moving or self._params[k].emissive]
        if bad:
            raise RuntimeError(
                f"params.update(): {', '.join(bad)} cannot be updated inside pbr.freeze: only the "
                "vertex positions, normals and 'to_world' of shapes that emit no light (their change "
                "rebuilds nothing but the acceleration structure); faces, uvs and the geometry of "
                "emissive shapes rebuild tables on the host (update them outside the frozen function)")
        # Mitsuba's own bookkeeping of these keys: pbr.freeze rebuilds them instead.
        self._mp.nodes_to_update.clear()
        self._mp.update_candidates.clear()
        self._geometry_read = False
        geometry = self.scene.geometry
        geometry.stale = tuple(sorted(set(geometry.stale) | set(keys)))

    def _refresh_values(self, keys) -> bool:
        """Refresh the value tables of ``keys`` without a rebuild when each is a BSDF's
        constant or bitmap texture or a BSDF family's own scalar; False if one is not."""
        tex = self.scene.textures
        slot_of = {id(t): i for i, t in enumerate(tex.items)}
        family_of = {id(o): f for f in self.scene.bsdfs.families.values()
                     if hasattr(f, "refresh_params") for o in f.param_owners()}
        refreshes = set()
        for k in keys:
            o = self._params[k].owner
            if slot_of.get(id(o)) in self.scene.bsdf_slots and tex.refreshable(o):
                refreshes.add(tex.refresh)
            elif id(o) in family_of:
                refreshes.add(family_of[id(o)].refresh_params)
            else:
                return False
        for refresh in refreshes:
            refresh()
        return True

    def attach_in_recording(self) -> None:
        """Inside a ``dr.freeze`` recording, before a differentiable render: derive again,
        with Dr.Jit operations, the tables of the parameters that have gradients (BSDF
        value tables; meshes' vertex normals, :meth:`Geometry.attach_derived`). A
        recording's gradients stop at its inputs, and these tables may have been derived
        before it (by an update at the end of the previous frozen step, or outside):
        their share of the derivative would not reach the parameters. Tables built on
        the host (lights, media) cannot be derived again here."""
        keys = [k for k, p in self._params.items() if p.kind == "pbr" and dr.grad_enabled(p.get())]
        if keys:
            self._refresh_values(keys)
        if self.scene.geometry_requires_grad():
            self.scene.geometry.attach_derived()

    # -- internal -----------------------------------------------------------------------
    def differentiable_values(self) -> dict:
        """key -> value of the kept differentiable parameters that have gradients enabled
        (pbr's and the geometry's)."""
        out = {}
        for k, p in self._params.items():
            if p.kind in ("pbr", "geometry", "sensor") and not p.flags & int(mi.ParamFlags.NonDifferentiable):
                v = p.get()
                if dr.grad_enabled(v):
                    out[k] = v
        return out

    def __repr__(self):
        rows = []
        for k, p in self._params.items():
            v = p.get()
            f = "R" if p.flags & int(mi.ParamFlags.ReadOnly) else ("" if p.flags else "∂")
            rows.append(f"  {k}: {f:2} {type(v).__name__}{list(getattr(v, 'shape', ()))}")
        return "SceneParameters[\n" + "\n".join(rows) + "\n]"


@backend.uses_pbr_variant
def traverse(scene) -> SceneParameters:
    """The parameters of ``scene`` (a :class:`SceneParameters`; ``mi.traverse``'s keys)."""
    return SceneParameters(scene)


@contextlib.contextmanager
def tables_as_leaves(scene, tangents: dict):
    """Within the block, the scene's tables are built from fresh copies of the parameters
    whose tangents are ``tangents`` (key -> tangent), then replaced by leaves holding the
    tangent each table receives; afterwards the parameters and tables are restored."""
    params = traverse(scene)
    originals = {k: params[k] for k in tangents}
    try:
        with dr.resume_grad():
            leaves = []
            for k, t in tangents.items():
                leaf = dr.detach(originals[k])
                dr.enable_grad(leaf)
                dr.set_grad(leaf, t)
                params[k] = leaf
                leaves.append(leaf)
            params.update()
            dr.enqueue(dr.ADMode.Forward, *leaves)
            dr.traverse(dr.ADMode.Forward, flags=dr.ADFlag.ClearEdges)

            def as_leaf(x):
                if not dr.grad_enabled(x):
                    return x
                y = dr.detach(x)
                dr.enable_grad(y)
                dr.set_grad(y, dr.grad(x))
                return y

            map_tables(scene, as_leaf)
        yield
    finally:
        for k, v in originals.items():
            params[k] = v
        params.update()
