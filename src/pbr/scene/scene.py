"""The assembled scene: geometry (in Mitsuba), and pbr's texture, BSDF, light and medium
tables, with what the loader recorded about each shape."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..geometry import Geometry
from ..plugins.tables import own_table_memory
from ..textures import meshattr


class ShapeList:
    """Per shape, in scene order: the Mitsuba shape (or its dict), the BSDF entry, the
    emitter entry + 1 (0: none), the id, the key path, and the [interior, exterior]
    medium indices + 1 (0: vacuum)."""

    def __init__(self):
        self.geometry, self.bsdf, self.light, self.ids, self.paths, self.media = [], [], [], [], [], []
        self.groups: dict[int, str] = {}   # shape -> the shapegroup holding it (instancing)
        self.instances: list = []          # (shapegroup id, 4x4 to_world) per instance

    def __len__(self):
        return len(self.ids)

    def add(self, geometry, bsdf: int, light: int, sid: str, path: str, media) -> None:
        for column, v in zip((self.geometry, self.bsdf, self.light, self.ids, self.paths, self.media),
                             (geometry, bsdf, light, sid, path, media)):
            column.append(v)


class Scene:
    def __init__(self, textures, bsdfs, lights, media, shapes: ShapeList, sensors, integrator,
                 bsdf_textures: dict):
        self.textures = textures
        self.bsdfs = bsdfs
        self.lights = lights
        self.media = media
        self.geometry = Geometry(shapes.geometry, shapes.groups, shapes.instances)
        self.mi_scene = self.geometry.mi_scene
        self.shape_ids = shapes.ids
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
        self.sensors = sensors
        self.integrator = integrator
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

    def requires_grad(self) -> bool:
        return any(dr.grad_enabled(v) for t in self.param_owners() for v in t.params.values())

    def __repr__(self):
        w, h = self.sensors[0].film.size
        return (f"pbr.Scene({len(self.shape_ids)} shapes, {len(self.bsdfs.entries)} BSDFs, "
                f"{len(self.lights)} lights, {w}x{h}, spp={self.spp}, integrator={self.integrator.name})")
