"""Participating media: :class:`MediumSet` (one table of every medium of a scene, its
types registered in :data:`MEDIUM_TYPES`; :mod:`.mediumset`), voxel grids (:mod:`.grid`)
and the majorant walk (:mod:`.majorant`). See docs/media.md."""

from .mediumset import MEDIUM_TYPES, MediumProperties, MediumSet  # noqa: F401
