"""Sobol'-based samplers: pbrt-v4's ``sobol`` (one global sequence over the film),
``paddedsobol`` and ``zsobol`` (per-pixel (0,2)-sequences padded across dimensions), and
Mitsuba's ``ldsampler`` (Kollig and Keller's scrambled, shuffled (0,2)-sequence).

All take a power-of-two number of samples per pixel (other counts are rounded up to
one, with a warning): a (0,2)-sequence is stratified in every elementary interval only
over power-of-two prefixes."""

from __future__ import annotations

import functools

import drjit as dr
import mitsuba as mi
import numpy as np

from .base import (SAMPLERS, SampleStream, Sampler, cranley_patterson, hash_u32, log2_int, parse_randomization,
                   stream_class, u32_to_unit)
from .lowdiscrepancy import SOBOL_BITS, SOBOL_DIMENSIONS, scramble_bits, sobol_bits, sobol_matrices, tables
from ..sampling import mix32


def _randomize(v: mi.UInt32, dim, seed: mi.UInt32, randomization: str) -> mi.Float:
    """A Sobol' fraction of dimension ``dim`` randomised, as a float in [0, 1)."""
    if randomization == "cranleypatterson":
        return cranley_patterson(u32_to_unit(v), dim, seed)
    if randomization == "none":
        return u32_to_unit(v)
    return u32_to_unit(scramble_bits(v, hash_u32(dim, seed), randomization))


def _check_bits(path: str, name: str, nbits: int, what: str) -> None:
    if nbits > SOBOL_BITS:
        raise ValueError(f"{path}: the {name!r} sampler indexes {what} with {nbits} bits, more than the "
                         f"{SOBOL_BITS} of its generator matrices: lower the resolution or the spp")


class _PowerOfTwo(Sampler):
    """Samplers whose sample count is rounded up to a power of two."""

    def round_spp(self, spp, warn=False):
        return self._rounded(spp, 1 << log2_int(spp), "a power-of-two sample count", warn)


class _ScrambledSobol(_PowerOfTwo):
    """The Sobol'-based samplers (``sobol``, ``paddedsobol``, ``zsobol``): 16 samples per
    pixel by default and a ``randomization`` (default ``fastowen``, as pbrt-v4)."""

    def __init__(self, props=None):
        super().__init__(props, default_count=16)
        self.randomization = parse_randomization(props, "fastowen")
        if props:
            props.finish()


# ------------------------------------------------------------------------------ sobol

class SobolStream(SampleStream):
    """A sample of the global Sobol' sequence: ``index`` is its index in the sequence."""

    _fields = {"index": "UInt32", "dim": "UInt32", "seed": "UInt32"}
    varying = ("dim",)
    # constants (class attributes of the per-render subclass): m (the film is covered by
    # 2^m x 2^m pixels), nbits (index bits), randomization

    def pixel_2d(self):
        # Dimensions 0 and 1: their first m digits are the pixel's coordinates (the index
        # was chosen so), the digits after them the position inside the pixel, which is
        # randomised like the other dimensions (pbrt-v4 leaves it unscrambled; scrambled,
        # renders with different seeds are independent estimates, as pbr.validate needs).
        m, r = self.m, self.randomization
        u = [_randomize(sobol_bits(self.index, d, self.nbits) << m, d, self.seed, r) for d in (0, 1)]
        return mi.Point2f(u[0], u[1])

    def next_1d(self):
        d = dr.select(self.dim >= SOBOL_DIMENSIONS, 2, self.dim)
        self.dim = d + 1
        return _randomize(sobol_bits(self.index, d, self.nbits), d, self.seed, self.randomization)


@functools.lru_cache(maxsize=None)
def _pixel_solver(m: int) -> tuple:
    """For a 2^m x 2^m film: (T, Ainv) with T[j] the first m digits that index bit j
    gives dimension 1 (an m-bit int, digit 1 in bit m-1), and Ainv the columns of the
    inverse over GF(2) of the m x m matrix of T[m..2m-1], which solves for the index bits
    m..2m-1 that put dimension 1 in a given pixel row (the (0,2)-property makes it
    invertible)."""
    cols = sobol_matrices()[1]
    T = [int(c) >> (32 - m) for c in cols]
    A = np.array([[(T[m + i] >> b) & 1 for i in range(m)] for b in range(m)], np.uint8)
    inv = np.eye(m, dtype=np.uint8)
    A = A.copy()
    for c in range(m):                       # Gauss-Jordan elimination over GF(2)
        r = c + int(np.nonzero(A[c:, c])[0][0])
        A[[c, r]], inv[[c, r]] = A[[r, c]], inv[[r, c]]
        for rr in range(m):
            if rr != c and A[rr, c]:
                A[rr] ^= A[c]
                inv[rr] ^= inv[c]
    ainv_cols = [sum(int(inv[i, r]) << i for i in range(m)) for r in range(m)]
    return T, ainv_cols


def sobol_pixel_index(px: mi.UInt32, py: mi.UInt32, index: mi.UInt32, m: int) -> mi.UInt32:
    """The index in the global Sobol' sequence of the ``index``-th sample of pixel
    (px, py) of a 2^m x 2^m film: bits 0..m-1 put dimension 0 in column px (the van der
    Corput digits are the index bits reversed), bits m..2m-1 put dimension 1 in row py
    (solved over GF(2)), the bits above count the pixel's samples."""
    if m == 0:
        return mi.UInt32(index)
    T, ainv = _pixel_solver(m)
    low = dr.brev(px) >> (32 - m)
    known = mi.UInt32(0)
    for j in range(m):
        known ^= dr.select(((low >> j) & 1) != 0, mi.UInt32(T[j]), 0)
    for t in range(SOBOL_BITS - 2 * m):
        known ^= dr.select(((index >> t) & 1) != 0, mi.UInt32(T[2 * m + t]), 0)
    rhs = py ^ known
    mid = mi.UInt32(0)
    for r in range(m):
        mid ^= dr.select(((rhs >> r) & 1) != 0, mi.UInt32(ainv[r]), 0)
    return (index << (2 * m)) | (mid << m) | low


@SAMPLERS.register("sobol")
class SobolSampler(_ScrambledSobol):
    """``sobol``: pbrt-v4's ``SobolSampler``, one Sobol' sequence over the whole film:
    dimensions 0 and 1 (unscrambled) place the samples in the pixels and inside them, the
    other dimensions (up to 1024, then wrapping to 2) are randomised per dimension.

    ==============  ======  ========  ==========================================================
    name            type    default   meaning
    ==============  ======  ========  ==========================================================
    sample_count    int     16        samples per pixel, rounded up to a power of two
                                      (pbrt-v4's ``pixelsamples`` too)
    seed            int     0         offset added to the seed a render is given
    randomization   string  fastowen  'none', 'permutedigits' (random XOR per dimension),
                                      'fastowen' (hash-based Owen scrambling), 'owen' (Owen
                                      scrambling), 'cranleypatterson' (random shift per dimension)
    ==============  ======  ========  ==========================================================
    """

    name = "sobol"
    progressive = True

    def start(self, pixel, index, spp, size, seed):
        w, h = size
        m = log2_int(max(w, h))
        nbits = 2 * m + log2_int(spp)
        _check_bits(self.path, self.name, nbits, f"{1 << m}^2 pixels x {spp} samples")
        cls = stream_class(SobolStream, m=m, nbits=nbits, randomization=self.randomization)
        px, py = pixel % w, pixel // w
        return cls(index=sobol_pixel_index(px, py, index, m), dim=mi.UInt32(2), seed=self.render_seed(seed))


# ------------------------------------------------------------------------ paddedsobol

class PaddedSobolStream(SampleStream):
    """A per-pixel (0,2)-sequence sample: every dimension (pair) shuffles the pixel's
    sample order and scrambles its own copy of Sobol' dimensions 0 (and 1)."""

    _fields = {"pixel": "UInt32", "index": "UInt32", "dim": "UInt32", "seed": "UInt32"}
    varying = ("dim",)

    def _shuffled(self):
        h = hash_u32(self.pixel, self.dim, self.seed)
        return mi.permute_kensler(self.index, self.spp, h), h

    def next_1d(self):
        i, h = self._shuffled()
        d = self.dim
        self.dim = d + 1
        return _randomize(sobol_bits(i, 0, self.nbits), d, h, self.randomization)

    def next_2d(self):
        i, h = self._shuffled()
        d = self.dim
        self.dim = d + 2
        return mi.Point2f(_randomize(sobol_bits(i, 0, self.nbits), d, h, self.randomization),
                          _randomize(sobol_bits(i, 1, self.nbits), d + 1, h, self.randomization))


@SAMPLERS.register("paddedsobol")
class PaddedSobolSampler(_ScrambledSobol):
    """``paddedsobol``: pbrt-v4's ``PaddedSobolSampler``: per pixel, each 1D or 2D draw
    takes the first one or two Sobol' dimensions at a shuffled sample index, randomised
    independently for every pixel and dimension ("padding" 2D (0,2)-sequences).

    ==============  ======  ========  ==========================================================
    name            type    default   meaning
    ==============  ======  ========  ==========================================================
    sample_count    int     16        samples per pixel, rounded up to a power of two
                                      (pbrt-v4's ``pixelsamples`` too)
    seed            int     0         offset added to the seed a render is given
    randomization   string  fastowen  'none', 'permutedigits', 'fastowen', 'owen' or
                                      'cranleypatterson' (see ``sobol``)
    ==============  ======  ========  ==========================================================
    """

    name = "paddedsobol"

    def start(self, pixel, index, spp, size, seed):
        cls = stream_class(PaddedSobolStream, spp=spp, nbits=log2_int(spp), randomization=self.randomization)
        return cls(pixel=mi.UInt32(pixel), index=mi.UInt32(index), dim=mi.UInt32(0), seed=self.render_seed(seed))


# ----------------------------------------------------------------------------- zsobol

def morton2(x: mi.UInt32, y: mi.UInt32) -> mi.UInt32:
    """Interleaved bits of 16-bit ``x`` (even bits) and ``y`` (odd bits): the Z-order index."""
    def spread(v):
        v = (v | (v << 8)) & 0x00FF00FF
        v = (v | (v << 4)) & 0x0F0F0F0F
        v = (v | (v << 2)) & 0x33333333
        return (v | (v << 1)) & 0x55555555
    return spread(x) | (spread(y) << 1)


class ZSobolStream(SampleStream):
    """A sample of one Sobol' (0,2)-sequence laid over the film in Morton (Z) order, its
    base-4 index digits permuted per dimension (Ahmed and Wonka 2020, pbrt-v4's
    ``ZSobolSampler``): neighbouring pixels get well-distributed, decorrelated points."""

    _fields = {"morton": "UInt32", "dim": "UInt32", "seed": "UInt32"}
    varying = ("dim",)

    def _index(self):
        """The sequence index of this sample for the current dimension."""
        odd = self.log2_spp & 1
        table = tables()["perm4"]
        out = mi.UInt32(0)
        salt = self.dim * 0x55555555
        for i in range(self.n4 - 1, odd - 1, -1):
            shift = 2 * i - odd
            digit = (self.morton >> shift) & 3
            higher = self.morton >> (shift + 2)
            p = (mix32(higher ^ salt) >> 24) % 24
            packed = dr.gather(mi.UInt32, table, p)
            out |= ((packed >> (2 * digit)) & 3) << shift
        if odd:
            out |= (self.morton & 1) ^ (mix32((self.morton >> 1) ^ salt) & 1)
        return out

    def next_1d(self):
        i, d = self._index(), self.dim
        self.dim = d + 1
        return _randomize(sobol_bits(i, 0, self.nbits), d, self.seed, self.randomization)

    def next_2d(self):
        i, d = self._index(), self.dim
        self.dim = d + 2
        return mi.Point2f(_randomize(sobol_bits(i, 0, self.nbits), d, self.seed, self.randomization),
                          _randomize(sobol_bits(i, 1, self.nbits), d + 1, self.seed, self.randomization))


@SAMPLERS.register("zsobol")
class ZSobolSampler(_ScrambledSobol):
    """``zsobol``: pbrt-v4's ``ZSobolSampler`` (its default sampler): one (0,2)-sequence
    shared by all pixels in Morton order with per-dimension permuted base-4 digits, so
    that each pixel gets a (0,2)-sequence and neighbouring pixels' errors are blue noise.

    ==============  ======  ========  ==========================================================
    name            type    default   meaning
    ==============  ======  ========  ==========================================================
    sample_count    int     16        samples per pixel, rounded up to a power of two
                                      (pbrt-v4's ``pixelsamples`` too)
    seed            int     0         offset added to the seed a render is given
    randomization   string  fastowen  'none', 'permutedigits', 'fastowen', 'owen' or
                                      'cranleypatterson' (see ``sobol``)
    ==============  ======  ========  ==========================================================
    """

    name = "zsobol"

    def start(self, pixel, index, spp, size, seed):
        w, h = size
        res_bits = log2_int(max(w, h))
        k = log2_int(spp)
        nbits = 2 * res_bits + k
        _check_bits(self.path, self.name, nbits, f"{1 << res_bits}^2 pixels x {spp} samples")
        cls = stream_class(ZSobolStream, log2_spp=k, n4=res_bits + (k + 1) // 2, nbits=nbits,
                           randomization=self.randomization)
        morton = (morton2(pixel % w, pixel // w) << k) | index
        return cls(morton=morton, dim=mi.UInt32(0), seed=self.render_seed(seed))


# -------------------------------------------------------------------------- ldsampler

class LDStream(SampleStream):
    """Mitsuba's ``ldsampler`` stream: per draw, the pixel's sample order is shuffled (a
    permutation per dimension) and the (0,2)-sequence XOR-scrambled (per pixel)."""

    _fields = {"index": "UInt32", "dim": "UInt32", "key": "UInt32"}
    varying = ("dim",)

    def _shuffled(self):
        return mi.permute_kensler(self.index, self.spp, self.key + self.dim)

    def next_1d(self):
        i = self._shuffled()
        self.dim = self.dim + 1
        return u32_to_unit(sobol_bits(i, 0, self.nbits) ^ hash_u32(self.key, 0x48BC48EB))

    def next_2d(self):
        i = self._shuffled()
        self.dim = self.dim + 1
        return mi.Point2f(u32_to_unit(sobol_bits(i, 0, self.nbits) ^ hash_u32(self.key, 0x98BC51AB)),
                          u32_to_unit(sobol_bits(i, 1, self.nbits) ^ hash_u32(self.key, 0x1B873593)))


@SAMPLERS.register("ldsampler")
class LowDiscrepancySampler(Sampler):
    """``ldsampler``: Mitsuba's low-discrepancy sampler (Kollig and Keller 2002): every
    1D and 2D draw uses the same (0,2)-sequence (van der Corput and Sobol' dimension 1),
    XOR-scrambled per pixel, with the pixel's sample order shuffled per draw.

    ============  ====  =======  ===============================================================
    name          type  default  meaning
    ============  ====  =======  ===============================================================
    sample_count  int   4        samples per pixel, rounded up to a square power of two (4, 16,
                                 64, 256, ...), as Mitsuba does
    seed          int   0        offset added to the seed a render is given
    ============  ====  =======  ===============================================================
    """

    name = "ldsampler"

    def __init__(self, props=None):
        super().__init__(props)
        if props:
            props.finish()

    def round_spp(self, spp, warn=False):
        res = 2
        while res * res < spp:
            res *= 2
        return self._rounded(spp, res * res, "a square power-of-two sample count", warn)

    def start(self, pixel, index, spp, size, seed):
        cls = stream_class(LDStream, spp=spp, nbits=log2_int(spp))
        return cls(index=mi.UInt32(index), dim=mi.UInt32(0), key=hash_u32(pixel, self.render_seed(seed)))
