"""Samplers (pbrt-v4's chapter 8, Mitsuba's ``sampler`` plugins): the interface and
dimension allocation are in :mod:`.base`; one module per family registers its types."""

from .base import SAMPLERS, SampleStream, Sampler, seed_array  # noqa: F401
from .independent import IndependentSampler, IndependentStream  # noqa: F401
from . import halton, sobol, stratified  # noqa: F401  (register their types)
from .lowdiscrepancy import tables  # noqa: F401
