"""Samplers (pbrt-v4's chapter 8, Mitsuba's ``sampler`` plugins): the interface and
dimension allocation are in :mod:`.base`; one module per family registers its types."""

from .base import SAMPLERS, SampleStream, Sampler, seed_array  # noqa: F401
from .independent import IndependentSampler, IndependentStream  # noqa: F401
from . import halton, lowdiscrepancy, pmj02bn, sobol, stratified  # noqa: F401  (register their types)


def tables() -> dict:
    """The samplers' Dr.Jit tables of the current variant (``pbr.freeze`` hands them to
    ``dr.freeze`` as state): low-discrepancy tables and the pmj02bn point sets."""
    return {**lowdiscrepancy.tables(), "pmj02bn": pmj02bn.tables()}
