"""What ``scene.sensors()``, ``scene.shapes()`` and ``scene.emitters()`` return: the
objects a Mitsuba script expects from ``mi.Scene``, with the methods such scripts call.

- :class:`ShapeView`: Mitsuba's own shape object (pbr hands its geometry to Mitsuba), so
  ``id()``, ``bbox()``, ``is_mesh()``, ``surface_area()``, ``vertex_positions_buffer()``,
  ``write_ply()`` ... are Mitsuba's; ``emitter()``, ``is_emitter()``, ``interior_medium()``,
  ``exterior_medium()`` answer from pbr's tables (Mitsuba's copy of the shape carries
  neither pbr's emitter nor its media). ``bsdf()`` is refused: pbr's BSDFs are not
  Mitsuba objects (their parameters are in ``pbr.traverse``). ``mi_shape`` is the
  Mitsuba object itself.
- :class:`SensorView`: ``id()``, ``world_transform()``, ``film()`` (``size()``,
  ``crop_size()``, ``crop_offset()``), ``sampler()`` (``sample_count()``), ``near_clip()``,
  ``far_clip()``, ``bbox()``; ``camera`` is pbr's sensor object. ``pbr.render(scene,
  sensor=view)`` renders from it.
- :class:`EmitterView`: ``id()``, ``class_name()``, ``is_environment()``, ``shape()``.

Values are built with the types of pbr's variant module (``mitsuba.llvm_ad_spectral``
...), which needs no switch of Mitsuba's active variant.
"""

from __future__ import annotations

import importlib

import numpy as np

from .. import backend


def variant_types():
    """The module of pbr's Mitsuba variant (``mitsuba.llvm_ad_spectral``...): its types
    without making it the active variant."""
    return importlib.import_module(f"mitsuba.{backend.variant()}")


def _class_name(type_name: str) -> str:
    return "".join(w.capitalize() for w in type_name.replace("-", "_").split("_"))


class SensorList(list):
    """A scene's sensors (pbr's objects; pbr's code indexes the list). Called like
    Mitsuba's ``scene.sensors()``, it gives :class:`SensorView` objects."""

    def __call__(self) -> list:
        return [SensorView(s) for s in self]


class _Values:
    """A read-only value with Mitsuba's accessor methods (``film().size()``...)."""

    def __init__(self, **values):
        self._values = values

    def __getattr__(self, name):
        values = self.__dict__.get("_values", {})
        if name in values:
            return lambda: values[name]
        raise AttributeError(name)

    def __repr__(self):
        return f"{type(self).__name__}({', '.join(f'{k}={v}' for k, v in self._values.items())})"


class FilmView(_Values):
    """A sensor's film: ``size()``, ``crop_size()``, ``crop_offset()`` (Mitsuba's
    ``ScalarVector2u`` / ``ScalarPoint2u``)."""


class SamplerView(_Values):
    """A sensor's sampler: ``sample_count()``."""


class SensorView:
    """A scene's sensor as Mitsuba scripts use it (see the module docstring)."""

    def __init__(self, camera):
        self.camera = camera

    def id(self) -> str:
        return getattr(self.camera, "id", "sensor")

    def class_name(self) -> str:
        return type(self.camera).__name__

    def world_transform(self):
        """Camera-to-world (Mitsuba's ``Transform4f``)."""
        return variant_types().Transform4f(np.asarray(self.camera.to_world, np.float64).tolist())

    def film(self) -> FilmView:
        t = variant_types()
        film = self.camera.film
        w, h = film.size
        cw, ch = getattr(film, "crop_size", (w, h))
        ox, oy = getattr(film, "crop_offset", (0, 0))
        return FilmView(size=t.ScalarVector2u(w, h), crop_size=t.ScalarVector2u(cw, ch),
                        crop_offset=t.ScalarPoint2u(ox, oy))

    def sampler(self) -> SamplerView:
        return SamplerView(sample_count=self.camera.sampler.sample_count)

    def near_clip(self) -> float:
        return float(self.camera.near_clip)

    def far_clip(self) -> float:
        return float(self.camera.far_clip)

    def bbox(self):
        """The camera's position as a degenerate box (as Mitsuba's projective cameras)."""
        t = variant_types()
        o = np.asarray(self.camera.to_world, np.float64)[:3, 3].tolist()
        return t.ScalarBoundingBox3f(t.ScalarPoint3f(*o))

    def __repr__(self):
        return f"SensorView[id={self.id()!r}, {self.class_name()}]"


class EmitterView:
    """Emitter ``g`` of a scene (in ``LightSet`` order) as Mitsuba scripts use it."""

    def __init__(self, scene, g: int):
        self._scene, self._g = scene, g
        self.type, _ = scene.lights.entries[g]
        self.path = scene.lights.paths[g]

    def id(self) -> str:
        """The emitter's key (``emitter`` for one nested in a shape, as Mitsuba)."""
        return self.path.rsplit(".", 1)[-1]

    def class_name(self) -> str:
        return _class_name(self.type)

    def is_environment(self) -> bool:
        return bool(self._scene.lights.families[self.type].infinite)

    def shape(self):
        """The shape an area emitter sits on (a :class:`ShapeView`), else None."""
        for i, e in enumerate(self._scene.shape_emitter):
            if e == self._g + 1:
                return ShapeView(self._scene, i)
        return None

    def __repr__(self):
        return f"EmitterView[id={self.id()!r}, {self.type}]"


class ShapeView:
    """Shape ``i`` of a scene: Mitsuba's shape object with pbr's emitter and media (see
    the module docstring). Other attributes are the Mitsuba shape's."""

    def __init__(self, scene, i: int):
        self._scene, self._i = scene, i
        self.mi_shape = scene.geometry.mi_shape(i)
        self.path = scene.shape_paths[i]

    def __getattr__(self, name):
        return getattr(self.__dict__["mi_shape"], name)

    def id(self) -> str:
        return str(self._scene.shape_ids[self._i])

    def is_emitter(self) -> bool:
        return self._scene.shape_emitter[self._i] > 0

    def emitter(self):
        e = self._scene.shape_emitter[self._i]
        return EmitterView(self._scene, e - 1) if e else None

    def _medium(self, side: int):
        m = self._scene.media_of_shape[self._i][side]
        return self._scene.media.media[m - 1].path if m else None

    def interior_medium(self):
        """The key path of the interior medium (pbr's media are not Mitsuba objects), or None."""
        return self._medium(0)

    def exterior_medium(self):
        """The key path of the exterior medium, or None."""
        return self._medium(1)

    def is_medium_transition(self) -> bool:
        return any(self._scene.media_of_shape[self._i])

    def bsdf(self):
        raise NotImplementedError(
            f"{self.id()}.bsdf(): pbr's BSDFs are not Mitsuba objects; their parameters are "
            f"pbr.traverse(scene) keys (e.g. '{self.id()}.bsdf.<name>' or '<bsdf id>.<name>')")

    def __repr__(self):
        return f"ShapeView[id={self.id()!r}, {self.mi_shape.class_name()}]"
