"""The assembled scene: geometry (in Mitsuba), and pbr's texture, BSDF and light tables."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .. import meshattr
from .tables import own_table_memory
from ..geometry import Geometry


class Scene:
    def __init__(self, loader, shapes, shape_bsdf, shape_light, shape_ids, sensors, integrator, shape_media=None):
        self.textures = loader.textures
        self.bsdfs = loader.bsdfs
        self.lights = loader.lights
        self.geometry = Geometry(shapes)
        self.mi_scene = self.geometry.mi_scene
        self.shape_ids = shape_ids
        bsdf_textures = getattr(loader, "bsdf_textures", {})
        meshattr.bind(self.textures, shapes, shape_bsdf, shape_ids, bsdf_textures)
        # Texture slots only BSDFs read (in kernels): lights and media also read theirs on
        # the host when building (power estimates, majorants).
        self.bsdf_slots = frozenset().union(*bsdf_textures.values())
        self.shape_bsdf = mi.UInt32(shape_bsdf)
        self.shape_light = mi.UInt32(shape_light)     # light index + 1; 0: not emissive
        self.media = loader.media
        shape_media = shape_media or [[0, 0]] * len(shape_ids)
        # Medium index + 1 inside / outside each shape (0: vacuum or no transition).
        self.shape_interior = mi.UInt32([a for a, _ in shape_media])
        self.shape_exterior = mi.UInt32([b for _, b in shape_media])
        self.shape_transition = mi.Bool([a > 0 or b > 0 for a, b in shape_media])
        self.sensors = sensors
        self.integrator = integrator
        self.build()

    def build(self) -> None:
        """(Re)build every parameter table from the current parameter values."""
        self.textures.build()
        self.bsdfs.build(self.textures)
        self.media.build(self.textures)
        self.lights.build(self, self.integrator.light_sampler)
        own_table_memory(self)

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
