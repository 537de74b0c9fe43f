"""Light families (one module each, registered in :data:`LIGHT_TYPES` where they are
defined), the light samplers (:mod:`.lightsamplers`, :mod:`.bvh`) and :class:`LightSet`,
the per-scene dispatch over the families (:mod:`.lightset`). The interface every family
implements, and the helpers several share, are in :mod:`.base`."""

from .base import LIGHT_TYPES, LightSample, LightType, LeSample  # noqa: F401
from . import area, directional, directionalarea, goniometric, infinite, point, projector, spot  # noqa: F401
from .lightsamplers import LIGHT_SAMPLERS, LightTable, make_light_sampler  # noqa: F401
from .lightset import LightSet  # noqa: F401
