"""``load_dict`` / ``load_file``: Mitsuba 3 scene descriptions -> :class:`pbr.scene.Scene`.

Same dict conventions as ``mitsuba.load_dict``: plugin ``type`` names and parameter
names, ids (the dict key, or an explicit ``id``), references ``{'type': 'ref', 'id': ..}``
and nested objects. Unknown types and parameters raise :class:`SceneError` naming the
key path (``scene.small-box.bsdf.reflectance``).

The loader is the top of the loading layers: it looks type names up in the families'
registries, hands each plugin its :class:`~pbr.plugins.props.Props` and itself (the
*load context*: ``textures``, ``resolve_ref``, ``resolve_path``, ``bsdf``, ``medium``),
and records on the scene what later stages need: per shape its key path, BSDF, emitter
and media; per emitter its key path (``LightSet.paths``). See docs/architecture.md.
"""

from __future__ import annotations

import contextlib
import os

from .. import backend
from ..bsdfs import BSDFSet, bsdf_names
from ..cameras import SENSORS
from ..geometry import CURVE_FILES, SHAPE_PARAMS, build_shape, read_motion, shape_to_mitsuba
from ..integrators import INTEGRATORS
from ..lights import LIGHT_TYPES, LightSet
from ..media import MEDIUM_TYPES, MediumSet
from ..plugins.props import FINITE, KNOWN_TYPES, Props, SceneError, did_you_mean
from ..textures import TEXTURE_TYPES, TextureSet, load_spectrum
from .objects import load_object
from .params import mitsuba_key_paths
from .pbrt import convert as pbrt_convert
from .scene import Scene, ShapeList
from .xml import locate, parse_file_lines, parse_string, tag_types

# Emitter types a shape can carry.
SURFACE_EMITTERS = ("area", "directionalarea")

# Every type name the loader accepts, for messages about misspelt nested plugins.
KNOWN_TYPES.update(*tag_types().values(), {"ref"})


class Loader:
    """Parses one scene dict (see the module docstring)."""

    def __init__(self, d: dict, base_dir: str | None = None):
        if not isinstance(d, dict) or d.get("type") != "scene":
            raise SceneError("scene: expected a dict with 'type': 'scene'")
        self.d = d
        self.base_dir = base_dir or os.getcwd()
        self.textures = TextureSet()
        self.bsdfs = BSDFSet()
        self.lights = LightSet()
        self.media = MediumSet()
        self._medium_cache: dict[int, int] = {}
        self.ids: dict[str, tuple[dict, str]] = {}
        self._bsdf_cache: dict[int, int] = {}
        self.bsdf_textures: dict[int, set] = {}   # BSDF entry -> texture slots it reads
        self._reading: list[set] = []
        self._following: dict[int, str] = {}   # id(dict being loaded) -> its key path
        self._collect_ids(d, "scene")

    # -- ids, refs, files ----------------------------------------------------------------
    def _collect_ids(self, d: dict, path: str) -> None:
        for k, v in d.items():
            if isinstance(v, dict) and "type" in v:
                p = f"{path}.{k}"
                # Top-level keys are ids; nested objects have one only if given explicitly.
                oid = v.get("id", k if path == "scene" else None)
                if v["type"] != "ref" and oid is not None:
                    if oid in self.ids and self.ids[oid][0] is not v:
                        raise SceneError(f"{p}: duplicate id {oid!r} (also at {self.ids[oid][1]})")
                    self.ids[oid] = (v, p)
                if v["type"] != "ref":
                    self._collect_ids(v, p)

    def resolve_ref(self, oid: str, path: str) -> dict:
        if oid not in self.ids:
            raise SceneError(f"{path}: reference to unknown id {oid!r}")
        return self.ids[oid][0]

    def resolve_path(self, fname: str, path: str) -> str:
        full = fname if os.path.isabs(fname) else os.path.join(self.base_dir, fname)
        if not os.path.exists(full):
            raise SceneError(f"{path}: file not found: {fname!r} (looked in {self.base_dir})")
        return full

    @contextlib.contextmanager
    def following(self, obj: dict, path: str, at: str | None = None):
        """The block that loads ``obj`` (a BSDF or a referenced texture) at ``path``: a
        reference back to ``obj`` met meanwhile (at key path ``at``, default ``path``) is
        a cycle, which would recurse forever."""
        if id(obj) in self._following:
            raise SceneError(f"{at or path}: reference cycle: it leads back to {self._following[id(obj)]}, "
                             "which is still being loaded")
        self._following[id(obj)] = path
        try:
            yield
        finally:
            del self._following[id(obj)]

    def _deref(self, v: dict, path: str) -> tuple[dict, str]:
        if not isinstance(v, dict):
            raise SceneError(f"{path}: expected a plugin dict with a 'type' (or a reference "
                             f"{{'type': 'ref', 'id': ...}}), got {type(v).__name__} {v!r}")
        if v.get("type") == "ref":
            p = Props(v, path, self)
            oid = p.string("id")
            p.mark("name")
            p.finish()
            return self.resolve_ref(oid, path), self.ids[oid][1]
        return v, path

    def _target_type(self, v) -> str | None:
        """The type of a child dict, or of the object a reference names."""
        if not isinstance(v, dict):
            return None
        if v.get("type") == "ref":
            target = self.ids.get(v.get("id"))
            return target[0].get("type") if target is not None else None
        return v.get("type")

    # -- plugins -------------------------------------------------------------------------
    def bsdf(self, v: dict, path: str) -> int:
        """Entry of the BSDF described (or referenced) by ``v``; each dict is parsed once."""
        at = path
        v, path = self._deref(v, path)
        if id(v) not in self._bsdf_cache:
            first = len(self.textures.items)
            self._reading.append(set())   # slots of nested BSDFs parsed earlier
            try:
                with self.following(v, path, at):
                    b = self.bsdfs.add(self, Props(v, path, self))
            finally:
                nested = self._reading.pop()
            self._bsdf_cache[id(v)] = b
            self.bsdf_textures[b] = set(range(first, len(self.textures.items))) | nested
        b = self._bsdf_cache[id(v)]
        if self._reading:
            self._reading[-1] |= self.bsdf_textures[b]
        return b

    def medium(self, v: dict, path: str) -> int:
        """Index of the medium described (or referenced) by ``v``."""
        v, path = self._deref(v, path)
        if v.get("type") not in MEDIUM_TYPES:
            raise SceneError(f"{path}: expected a medium ({MEDIUM_TYPES.supported()}), got type {v.get('type')!r}")
        if id(v) not in self._medium_cache:
            self._medium_cache[id(v)] = self.media.add(self, Props(v, path, self))
        return self._medium_cache[id(v)]

    def is_medium(self, v) -> bool:
        """Whether a child dict is a medium or a reference to one."""
        return self._target_type(v) in MEDIUM_TYPES

    def _shape(self, key: str, v: dict, shapes: ShapeList, defaults: dict, group: str | None = None) -> None:
        """Parse shape ``key`` with its BSDF, emitter and media into ``shapes`` (inside
        shape group ``group``, if given: then built as a Mitsuba object, without emitter)."""
        path = f"scene.{key}"
        p = Props(v, path, self)
        p.mark("id")
        motion = read_motion(p, p.transform("to_world"))
        if motion is not None:
            if group is not None:
                raise p.error("to_world_end", "shapes inside a shapegroup cannot move (give the instance "
                                              "'to_world_end')")
            if p.type in CURVE_FILES:
                raise p.error("to_world_end", f"{p.type!r} shapes cannot move (motion blur)")
            emitters = [k for k, c in p.children() if c["type"] in LIGHT_TYPES]
            if emitters:
                raise p.error(emitters[0], "moving shapes (with 'to_world_end') cannot carry emitters")
        geo = shape_to_mitsuba(p, self.resolve_path, object_space=motion is not None)
        if group is not None:
            if p.type in CURVE_FILES:
                raise p.error(None, f"{p.type!r} shapes inside a shapegroup are not supported")
            emitters = [k for k, c in p.children() if c["type"] in LIGHT_TYPES]
            if emitters:
                raise p.error(emitters[0], "shapes inside a shapegroup cannot carry emitters (as in Mitsuba)")
            try:
                geo = build_shape(geo)
            except Exception as e:
                raise p.error(None, f"Mitsuba could not build the shape: {e}") from None
        sidx = len(shapes)
        children = p.children()
        if p.has("bsdf"):
            b = self.bsdf(p.raw("bsdf"), p.key("bsdf"))
        else:
            nested = [k for k, c in children if k not in ("interior", "exterior")
                      and (c["type"] in bsdf_names() or c["type"] == "ref")]
            for k in nested[1:]:
                raise p.error(k, "a shape takes at most one BSDF")
            if nested:
                p.mark(nested[0])
                b = self.bsdf(p.raw(nested[0]), p.key(nested[0]))
            else:
                # Mitsuba: a shape without a BSDF gets a diffuse one, black if it emits.
                emits = any(c["type"] in LIGHT_TYPES for _, c in children)
                which = "black" if emits else "diffuse"
                if which not in defaults:
                    d = {"type": "diffuse", "reflectance": 0.0} if emits else {"type": "diffuse"}
                    defaults[which] = self.bsdfs.add(self, Props(d, f"{path}.bsdf", self))
                b = defaults[which]
        light = 0
        for k, c in children:
            if c["type"] not in LIGHT_TYPES:
                continue
            if c["type"] not in SURFACE_EMITTERS:
                raise p.error(k, f"a shape can only carry an 'area' or 'directionalarea' emitter, got {c['type']!r}")
            if light:
                raise p.error(k, "a shape takes at most one emitter")
            light = self.lights.add(self, p.child(k), sidx) + 1
        media = [0, 0]
        for j, k in enumerate(("interior", "exterior")):
            if p.has(k):
                media[j] = self.medium(p.raw(k), p.key(k)) + 1
        p.finish()
        if group is not None:
            shapes.groups[len(shapes)] = group
        if motion is not None:
            shapes.motions[len(shapes)] = motion
        shapes.add(geo, b, light, v.get("id", key), path, media)

    def _shapegroup(self, key: str, v: dict, shapes: ShapeList, defaults: dict) -> None:
        """``shapegroup`` (Mitsuba's): shapes (with their BSDFs and media) that are not
        rendered themselves but through ``instance`` shapes referring to the group."""
        p = Props(v, f"scene.{key}", self)
        p.mark("id")
        members = 0
        for k, c in p.children():
            if c["type"] in ("shapegroup", "instance"):
                raise p.error(k, f"a shapegroup cannot contain a {c['type']!r} (nested instancing is not supported)")
            if c["type"] not in SHAPE_PARAMS:
                raise p.error(k, f"a shapegroup holds shapes only, got {c['type']!r} "
                                 f"(supported: {', '.join(sorted(SHAPE_PARAMS))})")
            p.mark(k)
            self._shape(f"{key}.{k}", c, shapes, defaults, group=key)
            members += 1
        p.finish()
        if not members:
            raise p.error(None, "a shapegroup needs at least one shape")

    def _instance(self, key: str, v: dict, shapes: ShapeList) -> None:
        """``instance`` (Mitsuba's): the shapes of a referenced ``shapegroup`` moved by
        ``to_world`` (and, moving during the shutter, ``to_world_end`` at
        ``transform_times[1]``: pbr's, as for shapes and cameras)."""
        p = Props(v, f"scene.{key}", self)
        p.mark("id")
        to_world = p.transform("to_world")
        motion = read_motion(p, to_world)
        refs = []
        for k, c in p.children():
            if c["type"] != "ref":
                raise p.error(k, f"an instance takes a reference to a shapegroup, got a {c['type']!r}")
            target = self.resolve_ref(c.get("id"), p.key(k))
            if target.get("type") != "shapegroup":
                raise p.error(k, f"an instance refers to a shapegroup, {c.get('id')!r} is a {target.get('type')!r}")
            p.mark(k)
            refs.append(self.ids[c["id"]][1])
        p.finish()
        if len(refs) != 1:
            raise p.error(None, f"an instance needs exactly one shapegroup reference, got {len(refs)}")
        shapes.instances.append((refs[0].split(".", 1)[1], to_world, motion))

    def load(self) -> Scene:
        sensors, integrator_props = [], None
        shapes, defaults, instances = ShapeList(), {}, []
        root = Props(self.d, "scene", self)
        for key, v in self.d.items():
            if key == "type":
                continue
            path = f"scene.{key}"
            if not isinstance(v, dict) or "type" not in v:
                raise SceneError(f"{path}: expected a plugin dict with a 'type', got {type(v).__name__}")
            root.mark(key)
            t = v["type"]
            if t in SENSORS:
                sp = Props(v, path, self)
                sensor = SENSORS[t](sp)
                sensor.id = str(v.get("id", key))
                # The medium the camera sits in (Mitsuba: a medium nested in the sensor).
                med = [(k, c) for k, c in sp.children() if self.is_medium(c)]
                if len(med) > 1:
                    raise sp.error(med[1][0], "a sensor takes at most one medium")
                sensor.medium = self.medium(med[0][1], sp.key(med[0][0])) + 1 if med else 0
                sensors.append(sensor)
            elif t in INTEGRATORS:
                if integrator_props is not None:
                    raise SceneError(f"{path}: a scene has at most one integrator")
                integrator_props = Props(v, path, self)
            elif t in SHAPE_PARAMS:
                self._shape(key, v, shapes, defaults)
            elif t == "shapegroup":
                self._shapegroup(key, v, shapes, defaults)
            elif t == "instance":
                instances.append((key, v))
            elif t in TEXTURE_TYPES and (t != "mix" or "tex1" in v or "tex2" in v):
                # pbrt-v4 has both a mix texture (tex1, tex2) and a mix material. Its range
                # is checked where it is referenced; here only that it is finite.
                load_spectrum(self, v, path, emitter=False, valid=FINITE)
            elif t in bsdf_names():
                self.bsdf(v, path)
            elif t in LIGHT_TYPES:
                self.lights.add(self, Props(v, path, self))
            elif t in MEDIUM_TYPES:
                self.medium(v, path)
            elif t == "ref":
                raise SceneError(f"{path}: a reference ('type': 'ref') belongs inside the plugin that uses the "
                                 "object it names, not at the top level of the scene")
            else:
                raise SceneError(f"{path}: unknown plugin type {t!r}{did_you_mean(t, KNOWN_TYPES)}")
        for key, v in instances:   # after every shapegroup, wherever it appears
            self._instance(key, v, shapes)
        if len(shapes) == len(shapes.groups) and not shapes.instances:
            raise SceneError("scene: the scene has no shapes")
        if not sensors:
            sensors.append(SENSORS["perspective"](Props({"type": "perspective", "fov": 45.0}, "scene.sensor", self)))
        if integrator_props is None:
            integrator_props = Props({"type": "path"}, "scene.integrator", self)
        integrator = INTEGRATORS[integrator_props.type](integrator_props)
        return Scene(self.textures, self.bsdfs, self.lights, self.media, shapes, sensors, integrator,
                     self.bsdf_textures, mitsuba_key_paths(self.d))


@backend.uses_pbr_variant
def load_dict(d: dict, base_dir: str | None = None, parallel: bool = True, optimize: bool = True):
    """Build a :class:`pbr.scene.Scene` from a Mitsuba-style scene dict; a dict of an
    integrator or sensor type gives that plugin (see :mod:`.objects`). ``parallel`` and
    ``optimize`` are Mitsuba's keywords, accepted and ignored: pbr loads on one thread
    and never merges shapes (Mitsuba's ``optimize=False``, which keeps each shape's id)."""
    if isinstance(d, dict) and d.get("type") != "scene" and "type" in d:
        return load_object(d)
    return Loader(d, base_dir).load()


@backend.uses_pbr_variant
def load_file(path: str, parallel: bool = True, optimize: bool = True, **kwargs):
    """Load a Mitsuba XML scene (keyword arguments override its ``<default>`` values) or a
    pbrt-v4 scene (``.pbrt``, ``.pbrt.gz``: keywords ``spp``, ``res``, ``width``,
    ``height``, ``maxdepth``, ``approximate``; see :mod:`pbr.scene.pbrt`). ``parallel``
    and ``optimize`` are Mitsuba's keywords, ignored (see :func:`load_dict`)."""
    return load_xml_file(path, None, **kwargs)


@backend.uses_pbr_variant
def load_string(text: str, parallel: bool = True, optimize: bool = True, **kwargs):
    """Load a scene from Mitsuba XML text (``mi.load_string``); keyword arguments override
    its ``<default>`` values; relative file names are looked up in the working directory."""
    backend.ensure()   # the XML reader builds Mitsuba transforms: a variant must be set
    return load_dict(parse_string(text, **kwargs))


def load_xml_file(path: str, edit=None, **kwargs):
    """:func:`load_file`, with ``edit(d)`` applied to the parsed scene dict before it is
    loaded (the command line's film-size options); errors name ``file:line``."""
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path}: scene file not found")
    ext = ".pbrt" if path.lower().endswith(".pbrt.gz") else os.path.splitext(path)[1].lower()
    if ext not in (".xml", ".pbrt"):
        raise SceneError(f"{path}: unsupported scene format {ext!r} (supported: .xml, .pbrt)")
    backend.ensure()   # the readers build Mitsuba transforms: a variant must be set
    if ext == ".pbrt":
        d, _, lines = pbrt_convert(path, **kwargs)
    else:
        d, lines = parse_file_lines(path, **kwargs)
    if edit is not None:
        edit(d)
    try:
        return load_dict(d, base_dir=os.path.dirname(os.path.abspath(path)))
    except SceneError as e:     # name the XML element too
        raise SceneError(locate(str(e), lines)) from None
