"""``independent``: uniform random numbers from one PCG32 stream per camera sample.

Each sample's stream is seeded by hashing (seed, global sample index) with TEA, so
renders split into passes, or repeated with the same seed, use the same numbers. The
seed is an opaque kernel input: changing it does not recompile the kernel. It may be a
Python int or a ``mi.UInt32`` of width 1 (what ``dr.freeze`` needs: an int would be
baked into the recording)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .plugins.props import Props
from .plugins.registry import Registry

SAMPLERS = Registry("sampler")


def seed_array(seed) -> mi.UInt32:
    """``seed`` (a Python int or a width-1 ``mi.UInt32``) as an opaque ``mi.UInt32``."""
    if isinstance(seed, int):
        return dr.opaque(mi.UInt32, seed & 0xFFFFFFFF)
    if not (isinstance(seed, mi.UInt32) and dr.width(seed) == 1):
        raise TypeError(f"seed: expected a Python int or a mi.UInt32 of width 1, got {type(seed).__name__}")
    return seed


@SAMPLERS.register("independent")
class IndependentSampler:
    """``independent``: uniform random numbers from one PCG32 stream per camera sample.

    ============  ====  =======  ==================================================
    name          type  default  meaning
    ============  ====  =======  ==================================================
    sample_count  int   4        samples per pixel
    seed          int   0        accepted (renders take their seed from pbr.render)
    ============  ====  =======  ==================================================
    """

    def __init__(self, props: Props | None = None):
        self.sample_count = props.int("sample_count", 4, min=1) if props else 4
        self.seed = props.int("seed", 0) if props else 0
        if props:
            props.finish()

    @staticmethod
    def make_rng(sample_index: mi.UInt32, seed: mi.UInt32) -> mi.PCG32:
        v0, v1 = mi.sample_tea_32(sample_index, seed, 4)
        rng = mi.PCG32(dr.width(sample_index))
        # seed() (unlike the constructor) adds no per-lane offset: a sample's stream
        # depends only on (seed, sample index), not on how samples are split into passes.
        rng.seed(mi.UInt64(v0), mi.UInt64(v1))
        return rng

