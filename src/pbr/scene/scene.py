"""The assembled scene: geometry (in Mitsuba), and pbr's texture, BSDF, light and medium
tables, with what the loader recorded about each shape.

A :class:`Scene` also answers the calls Mitsuba scripts make on ``mi.Scene``:
``scene.sensors()``, ``scene.shapes()``, ``scene.emitters()``, ``scene.bbox()``
(:mod:`.views`)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..geometry import Geometry
from ..plugins.tables import own_table_memory
from ..textures import meshattr
from .params import rename_key_paths
from .views import EmitterView, SensorList, ShapeView


class ShapeList:
    """Per shape, in scene order: the Mitsuba shape (or its dict), the BSDF entry, the
    emitter entry + 1 (0: none), the id, the key path, and the [interior, exterior]
    medium indices + 1 (0: vacuum)."""

    def __init__(self):
        self.geometry, self.bsdf, self.light, self.ids, self.paths, self.media = [], [], [], [], [], []
        self.groups: dict[int, str] = {}   # shape -> the shapegroup holding it (instancing)
        self.instances: list = []          # (shapegroup id, 4x4 to_world, motion or None) per instance
        self.motions: dict = {}            # moving shape -> its AnimatedTransform (motion blur)

    def __len__(self):
        return len(self.ids)

    def add(self, geometry, bsdf: int, light: int, sid: str, path: str, media) -> None:
        for column, v in zip((self.geometry, self.bsdf, self.light, self.ids, self.paths, self.media),
                             (geometry, bsdf, light, sid, path, media)):
            column.append(v)


class Scene:
    def __init__(self, textures, bsdfs, lights, media, shapes: ShapeList, sensors, integrator,
                 bsdf_textures: dict, key_paths: dict | None = None):
        """``key_paths``: declared key path -> ``mi.traverse``'s, for the parameter owners
        (:func:`.params.mitsuba_key_paths`)."""
        self.textures = textures
        self.bsdfs = bsdfs
        self.lights = lights
        self.media = media
        self.geometry = Geometry(shapes.geometry, shapes.groups, shapes.instances, shapes.motions)
        self.mi_scene = self.geometry.mi_scene
        self.shape_ids = shapes.ids
        # Mitsuba's shapes take pbr's ids (Geometry named them by position), so that
        # scene.shapes()[i].id() and mi.traverse keys of the geometry read as the scene's.
        for i in self.top_level_shapes():
            self.geometry.mi_shape(i).set_id(str(shapes.ids[i]))
        self.shape_emitter = list(shapes.light)   # emitter index + 1 per shape (0: none)
        self.media_of_shape = list(shapes.media)  # [interior, exterior] medium index + 1
        self.shape_paths = shapes.paths        # key paths, e.g. "scene.red-wall"
        meshattr.bind(self.textures, shapes.geometry, shapes.bsdf, shapes.ids, bsdf_textures)
        # Texture slots only BSDFs read (in kernels): lights and media also read theirs on
        # the host when building (power estimates, majorants).
        self.bsdf_slots = frozenset().union(*bsdf_textures.values())
        self.shape_bsdf = mi.UInt32(shapes.bsdf)
        self.shape_light = mi.UInt32(shapes.light)     # light index + 1; 0: not emissive
        # Medium index + 1 inside / outside each shape (0: vacuum or no transition).
        self.shape_interior = mi.UInt32([a for a, _ in shapes.media])
        self.shape_exterior = mi.UInt32([b for _, b in shapes.media])
        self.shape_transition = mi.Bool([a > 0 or b > 0 for a, b in shapes.media])
        # A list (pbr's code indexes it) that can also be called like Mitsuba's method.
        self.sensors = SensorList(sensors)
        self.integrator = integrator
        rename_key_paths(self.param_owners(), key_paths or {})
        self.build()

    def build(self) -> None:
        """(Re)build every parameter table from the current parameter values, and prepare
        the scene's integrator for them (its light sampler is built here, outside any
        render, so that a render inside ``dr.freeze`` builds nothing)."""
        self.textures.build()
        self.bsdfs.build(self.textures)
        self.media.build(self.textures)
        self.lights.build(self)
        own_table_memory(self)
        if self.textures.needs_footprint:   # textures filter over the cameras' pixel footprints:
            for cam in self.sensors:         # find their ray differentials now, not in a render
                if hasattr(cam, "min_differentials"):
                    cam.min_differentials()
        self.integrator.prepare(self)

    # Mitsuba's keys whose change leaves everything but the shapes' positions as it was.
    MOVING_KEYS = frozenset({"vertex_positions", "vertex_normals", "to_world"})

    def geometry_changed(self, moved: list) -> None:
        """After Mitsuba rebuilt the shapes of ``moved`` ((shape, changed key names) pairs)
        and its acceleration structure: rebuild what depends on them, not the whole
        scene. Moved vertices or transforms change only the lights of emissive shapes
        (their triangle tables) and what the integrator derives from the geometry
        (``prepare``); other changes (faces, uvs) rebuild every table."""
        if not all(names <= self.MOVING_KEYS for _, names in moved):
            self.build()
            return
        emissive = {str(self.shape_ids[i]) for i in self.top_level_shapes() if self.shape_emitter[i]}
        if any(obj.id() in emissive for obj, _ in moved):
            self.lights.build(self)
            own_table_memory(self)
        self.integrator.prepare(self)

    @property
    def spp(self) -> int:
        """Samples per pixel requested by the first sensor's sampler."""
        return self.sensors[0].sampler.sample_count

    def param_owners(self) -> list:
        """Every object whose ``params`` are scene parameters (see ``pbr.traverse``)."""
        owners = list(self.textures.param_owners())
        for group in (self.bsdfs.families, self.lights.families):
            for fam in group.values():
                owners += getattr(fam, "param_owners", lambda: [])()
        return owners + self.media.param_owners()

    # -- Mitsuba's Scene methods ------------------------------------------------------
    def shapes(self) -> list:
        """The top-level shapes in scene order, as :class:`~.views.ShapeView` (Mitsuba's
        shape object, with pbr's emitter and media)."""
        return [ShapeView(self, i) for i in self.top_level_shapes()]

    def top_level_shapes(self) -> list:
        """Indices of the shapes that are not inside a ``shapegroup`` (those are Mitsuba's
        ``scene.shapes()``; a group's shapes are reached through its instances)."""
        return [i for i in range(len(self.shape_ids)) if self.geometry.mi_index[i] >= 0]

    def emitters(self) -> list:
        """The emitters in scene order (area emitters where their shape was declared),
        as :class:`~.views.EmitterView`."""
        return [EmitterView(self, g) for g in range(len(self.lights.entries))]

    def bbox(self):
        """Bounding box of the geometry (Mitsuba's ``ScalarBoundingBox3f``; moving shapes
        over their whole motion)."""
        return self.geometry.bbox()

    def requires_grad(self) -> bool:
        """Whether a parameter (pbr's, a shape's geometry) has gradients enabled."""
        return (any(dr.grad_enabled(v) for t in self.param_owners() for v in t.params.values())
                or self.geometry_requires_grad())

    def geometry_requires_grad(self) -> bool:
        """Whether a shape's geometry (vertices, transform) or a camera's pose has
        gradients enabled."""
        return (any(s.parameters_grad_enabled() for s in self.mi_scene.shapes())
                or any(getattr(c, "to_world_ad", None) is not None and dr.grad_enabled(c.to_world_ad)
                       for c in self.sensors))

    def __repr__(self):
        w, h = self.sensors[0].film.size
        return (f"pbr.Scene({len(self.shape_ids)} shapes, {len(self.bsdfs.entries)} BSDFs, "
                f"{len(self.lights)} lights, {w}x{h}, spp={self.spp}, integrator={self.integrator.name})")
