"""``independent``: uniform random numbers from one PCG32 stream per camera sample.

Each sample's stream is seeded by hashing (seed, global sample index) with TEA, so
renders split into passes, or repeated with the same seed, use the same numbers. The
seed is an opaque kernel input: changing it does not recompile the kernel."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .scene.props import Props


class IndependentSampler:
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


SAMPLERS = {"independent": IndependentSampler}
