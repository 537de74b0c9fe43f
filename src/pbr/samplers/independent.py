"""``independent``: uniform random numbers from one PCG32 stream per camera sample.

Each sample's stream is seeded by hashing (seed, global sample index) with TEA, so
renders split into passes, or repeated with the same seed, use the same numbers. The
seed is an opaque kernel input: changing it does not recompile the kernel. It may be a
Python int or a ``mi.UInt32`` of width 1 (what ``dr.freeze`` needs: an int would be
baked into the recording)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .base import SAMPLERS, SampleStream, Sampler


class IndependentStream(SampleStream):
    """A PCG32 stream: every dimension is a fresh uniform number."""

    _fields = {"rng": "PCG32"}
    varying = ("rng.state",)

    def next_1d(self) -> mi.Float:
        return self.rng.next_float32()

    def next_uint32(self) -> mi.UInt32:
        return self.rng.next_uint32()


@SAMPLERS.register("independent")
class IndependentSampler(Sampler):
    """``independent``: uniform random numbers from one PCG32 stream per camera sample
    (Mitsuba's and pbrt-v4's ``independent``).

    ============  ====  =======  ==================================================
    name          type  default  meaning
    ============  ====  =======  ==================================================
    sample_count  int   4        samples per pixel (pbrt-v4's ``pixelsamples`` too)
    seed          int   0        offset added to the seed a render is given
    ============  ====  =======  ==================================================
    """

    name = "independent"

    def __init__(self, props=None):
        super().__init__(props)
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

    def start(self, pixel, index, spp, size, seed):
        return IndependentStream(rng=self.make_rng(pixel * spp + index, self.render_seed(seed)))
