"""BSDF families (one module each, registered in :data:`BSDF_TYPES` where they are
defined) and :class:`BSDFSet`, the per-scene dispatch over them (:mod:`.bsdfset`).
The interface every family implements is in :mod:`.base`."""

from .base import BSDF_TYPES, BSDFSample, BSDFType, ShadingContext, DIFFUSE, GLOSSY  # noqa: F401
from . import (conductor, dielectric, diffuse, diffusetransmission, hair, layered, measured,  # noqa: F401
               null, plastic, principled, roughplastic, subsurface)
from .bsdfset import NO_BACK, WRAPPERS, BSDFSet, bsdf_names  # noqa: F401
