"""``load_dict`` / ``load_file``: Mitsuba 3 scene descriptions -> :class:`pbr.scene.Scene`.

Same dict conventions as ``mitsuba.load_dict``: plugin ``type`` names and parameter
names, ids (the dict key, or an explicit ``id``), references ``{'type': 'ref', 'id': ..}``
and nested objects. Unknown types and parameters raise :class:`SceneError` naming the
key path (``scene.small-box.bsdf.reflectance``).
"""

from __future__ import annotations

import os

from .. import backend
from .props import Props, SceneError

BSDF_LIKE = {"diffuse", "conductor", "roughconductor", "dielectric", "thindielectric", "roughdielectric",
             "plastic", "roughplastic", "twosided", "mask", "blendbsdf", "null", "bumpmap", "normalmap",
             "principled", "principledthin", "coateddiffuse", "coatedconductor", "diffusetransmission",
             "measured", "hair", "mix"}
EMITTER_LIKE = {"area", "point", "spot", "projector", "directional", "constant", "envmap", "directionalarea",
                "projection", "goniometric", "distant", "portalenvmap"}
TEXTURE_LIKE = {"rgb", "spectrum", "blackbody", "d65", "uniform", "checkerboard", "bitmap", "scale", "mesh_attribute"}


class Loader:
    def __init__(self, d: dict, base_dir: str | None = None):
        from ..textures import TextureSet
        from ..bsdfs import BSDFSet
        from ..lights import LightSet
        from ..media import MediumSet
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

    def _deref(self, v: dict, path: str) -> tuple[dict, str]:
        if v.get("type") == "ref":
            p = Props(v, path, self)
            oid = p.string("id")
            p.mark("name")
            p.finish()
            return self.resolve_ref(oid, path), self.ids[oid][1]
        return v, path

    # -- plugins -------------------------------------------------------------------------
    def bsdf(self, v: dict, path: str) -> int:
        v, path = self._deref(v, path)
        if id(v) not in self._bsdf_cache:
            first = len(self.textures.items)
            self._reading.append(set())   # slots of nested BSDFs parsed earlier
            try:
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
        from ..media import MEDIUM_LIKE
        v, path = self._deref(v, path)
        if v.get("type") not in MEDIUM_LIKE:
            raise SceneError(f"{path}: expected a medium ({', '.join(sorted(MEDIUM_LIKE))}), "
                             f"got type {v.get('type')!r}")
        if id(v) not in self._medium_cache:
            self._medium_cache[id(v)] = self.media.add(self, Props(v, path, self))
        return self._medium_cache[id(v)]

    def is_medium(self, v) -> bool:
        """Whether a child dict is a medium or a reference to one."""
        from ..media import MEDIUM_LIKE
        if not isinstance(v, dict):
            return False
        if v.get("type") == "ref":
            target = self.ids.get(v.get("id"))
            return target is not None and target[0].get("type") in MEDIUM_LIKE
        return v.get("type") in MEDIUM_LIKE

    def load(self):
        from .scene import Scene
        from ..geometry import shape_to_mitsuba, SHAPE_PARAMS
        from ..cameras import SENSORS
        from ..integrators import INTEGRATORS

        sensors, integrator_props, shapes = [], None, []
        shape_bsdf, shape_light, shape_ids, shape_media = [], [], [], []
        default_bsdf = default_black = None
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
                p = Props(v, path, self)
                p.mark("id")
                geo = shape_to_mitsuba(p, self.resolve_path)
                sidx = len(shapes)
                if p.has("bsdf"):
                    b = self.bsdf(p.raw("bsdf"), p.key("bsdf"))
                else:
                    nested = [k for k, c in p.children() if c["type"] in BSDF_LIKE or c["type"] == "ref"]
                    if nested:
                        for k in nested[1:]:
                            raise p.error(k, "a shape takes at most one BSDF")
                        p.mark(nested[0])
                        b = self.bsdf(p.raw(nested[0]), p.key(nested[0]))
                    elif any(c["type"] in EMITTER_LIKE for _, c in p.children()):
                        # Mitsuba: an emitting shape without a BSDF gets a black diffuse one.
                        if default_black is None:
                            default_black = self.bsdfs.add(
                                self, Props({"type": "diffuse", "reflectance": 0.0}, f"{path}.bsdf", self))
                        b = default_black
                    else:
                        if default_bsdf is None:
                            default_bsdf = self.bsdfs.add(self, Props({"type": "diffuse"}, f"{path}.bsdf", self))
                        b = default_bsdf
                light = 0
                em_keys = [k for k, c in p.children() if c["type"] in EMITTER_LIKE]
                for k in em_keys:
                    c = p.raw(k)
                    if c["type"] not in ("area", "directionalarea"):
                        raise p.error(k, f"a shape can only carry an 'area' or 'directionalarea' emitter, "
                                         f"got {c['type']!r}")
                    if light:
                        raise p.error(k, "a shape takes at most one emitter")
                    light = self.lights.add(self, Props(c, p.key(k), self), sidx) + 1
                media = [0, 0]
                for j, k in enumerate(("interior", "exterior")):
                    if p.has(k):
                        media[j] = self.medium(p.raw(k), p.key(k)) + 1
                p.finish()
                shape_media.append(media)
                shapes.append(geo)
                shape_bsdf.append(b)
                shape_light.append(light)
                shape_ids.append(v.get("id", key))
            elif t == "mix" and ("tex1" in v or "tex2" in v):
                # pbrt-v4 has both a mix texture (tex1, tex2) and a mix material.
                from ..textures import load_spectrum
                load_spectrum(self, v, path, emitter=False)
            elif t in BSDF_LIKE:
                self.bsdf(v, path)
            elif t in TEXTURE_LIKE:
                from ..textures import load_spectrum
                load_spectrum(self, v, path, emitter=False)
            elif t in EMITTER_LIKE:
                self.lights.add(self, Props(v, path, self))
            elif self.is_medium(v) and t != "ref":
                self.medium(v, path)
            else:
                raise SceneError(f"{path}: unknown plugin type {t!r}")
        if not shapes:
            raise SceneError("scene: the scene has no shapes")
        if not sensors:
            from ..cameras import PerspectiveCamera
            sensors.append(PerspectiveCamera(Props({"type": "perspective", "fov": 45.0}, "scene.sensor", self)))
        if integrator_props is None:
            integrator_props = Props({"type": "path"}, "scene.integrator", self)
        integrator = INTEGRATORS[integrator_props.type](integrator_props)
        return Scene(self, shapes, shape_bsdf, shape_light, shape_ids, sensors, integrator, shape_media)


def load_dict(d: dict, base_dir: str | None = None):
    """Build a :class:`pbr.scene.Scene` from a Mitsuba-style scene dict."""
    backend.ensure()
    return Loader(d, base_dir).load()


def load_file(path: str, **kwargs):
    """Load a Mitsuba XML scene; keyword arguments override its ``<default>`` values."""
    from .xml import parse_file
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path}: scene file not found")
    ext = os.path.splitext(path)[1].lower()
    if ext != ".xml":
        raise SceneError(f"{path}: unsupported scene format {ext!r} (supported: .xml)")
    d = parse_file(path, **kwargs)
    return load_dict(d, base_dir=os.path.dirname(os.path.abspath(path)))
