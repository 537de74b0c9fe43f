"""``halton``: pbrt-v4's Halton sampler, one Halton sequence over the whole film."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .base import SAMPLERS, SampleStream, Sampler, cranley_patterson, hash_u32, parse_randomization, stream_class
from .lowdiscrepancy import PRIMES, radical_inverse, tables

# Pixel coordinates are taken modulo this (pbrt-v4's MaxHaltonResolution): the sequence
# repeats its pixel pattern every 128 x 128 pixels.
MAX_RESOLUTION = 128


def _inverse_radical(v: mi.UInt32, base: int, digits: int) -> mi.UInt32:
    """The index whose first ``digits`` base-``base`` digits, mirrored, are ``v``."""
    out = mi.UInt32(0)
    for _ in range(digits):
        q = v // base
        out = out * base + (v - q * base)
        v = q
    return out


class HaltonStream(SampleStream):
    """A sample of the film's Halton sequence: ``index`` is its index in the sequence;
    dimension d uses the radical inverse in the d-th prime."""

    _fields = {"index": "UInt32", "dim": "UInt32", "seed": "UInt32"}
    varying = ("dim",)

    def pixel_2d(self):
        # Dimensions 0 and 1 (bases 2 and 3) without their first digits, which the index
        # was chosen to make the pixel's coordinates: the position inside the pixel,
        # randomised like the other dimensions (pbrt-v4 leaves it unscrambled; scrambled,
        # renders with different seeds are independent estimates, as pbr.validate needs).
        return mi.Point2f(self._sample(self.index >> self.exp2, mi.UInt32(2), 0),
                          self._sample(self.index // self.scale3, mi.UInt32(3), 1))

    def next_1d(self):
        d = dr.select(self.dim >= PRIMES, 2, self.dim)
        self.dim = d + 1
        return self._sample(self.index, dr.gather(mi.UInt32, tables()["primes"], d), d)

    def _sample(self, index, base, d):
        r = self.randomization
        h = hash_u32(d, self.seed)
        u = radical_inverse(index, base, perm_seed=h if r == "permutedigits" else None,
                            owen_seed=h if r == "owen" else None)
        return cranley_patterson(u, d, self.seed) if r == "cranleypatterson" else u


def _mult_inverse(a: int, n: int) -> int:
    return pow(a, -1, n)


@SAMPLERS.register("halton")
class HaltonSampler(Sampler):
    """``halton``: pbrt-v4's ``HaltonSampler``: dimension d of a sample is the radical
    inverse of its index in the d-th prime; the indices of a pixel's samples are chosen
    (through the Chinese remainder theorem) so that dimensions 0 and 1, scaled by 2^j >=
    and 3^k >= min(resolution, 128), fall in that pixel.

    ==============  ======  =============  =====================================================
    name            type    default        meaning
    ==============  ======  =============  =====================================================
    sample_count    int     16             samples per pixel (pbrt-v4's ``pixelsamples`` too)
    seed            int     0              offset added to the seed a render is given
    randomization   string  permutedigits  'none', 'permutedigits' (a random permutation of the
                                           digits per digit position and dimension), 'owen'
                                           (Owen scrambling), 'cranleypatterson' (random shift)
    ==============  ======  =============  =====================================================
    """

    name = "halton"
    progressive = True

    def __init__(self, props=None):
        super().__init__(props, default_count=16)
        self.randomization = parse_randomization(props, "permutedigits",
                                                 ("none", "permutedigits", "owen", "cranleypatterson"))
        if props:
            props.finish()

    def start(self, pixel, index, spp, size, seed):
        w, h = size
        scales, exps = [], []
        for base, res in ((2, w), (3, h)):
            scale, exp = 1, 0
            while scale < min(res, MAX_RESOLUTION):
                scale *= base
                exp += 1
            scales.append(scale)
            exps.append(exp)
        stride = scales[0] * scales[1]
        if spp * stride >= 1 << 32:
            raise ValueError(f"{self.path}: the 'halton' sampler indexes {spp} samples x {stride} pixels with "
                             f"more than 32 bits: lower the spp")
        offset = mi.UInt32(0)
        if stride > 1:
            coords = ((pixel % w) % MAX_RESOLUTION, (pixel // w) % MAX_RESOLUTION)
            for i, base in enumerate((2, 3)):
                if scales[i] == 1:
                    continue
                inv = _mult_inverse(scales[1 - i] % scales[i], scales[i])
                digits = _inverse_radical(coords[i], base, exps[i])
                offset += digits * ((stride // scales[i]) * inv % stride)
                offset = offset % stride
        cls = stream_class(HaltonStream, exp2=exps[0], scale3=scales[1], randomization=self.randomization)
        return cls(index=offset + index * stride, dim=mi.UInt32(2), seed=self.render_seed(seed))
