"""Stratified samplers: ``stratified`` (jittered strata, Mitsuba's and pbrt-v4's) and
Mitsuba's ``multijitter`` (Kensler's correlated multi-jittered sampling).

Each draw permutes the pixel's samples among the strata with a permutation of its own
(per pixel and dimension), so that the dimensions are not correlated with each other;
``jitter`` places each sample at random inside its stratum (else at its centre)."""

from __future__ import annotations

import math

import drjit as dr

import mitsuba as mi

from .base import SAMPLERS, SampleStream, Sampler, hash_u32, stream_class
from .independent import IndependentSampler


class StratifiedStream(SampleStream):
    """One sample of a pixel's strata: ``index`` is its stratum before permutation, ``key``
    the pixel's permutation seed, ``rng`` the jitter's PCG32."""

    _fields = {"index": "UInt32", "dim": "UInt32", "key": "UInt32", "rng": "PCG32"}
    # constants: count (strata in 1D), nx, ny (the 2D grid), jitter

    def _varying(self):
        return ("dim", "rng.state") if self.jitter else ("dim",)

    def _jitter(self):
        return self.rng.next_float32() if self.jitter else mi.Float(0.5)

    def _stratum(self, n, salt):
        s = mi.permute_kensler(self.index, n, hash_u32(self.key, self.dim, salt))
        self.dim = self.dim + 1
        return s

    def next_1d(self):
        s = self._stratum(self.count, 1)
        return (mi.Float(s) + self._jitter()) * (1.0 / self.count)

    def next_2d(self):
        s = self._stratum(self.count, 2)
        y = s // self.nx
        x = s - y * self.nx
        jx = self._jitter()
        jy = self._jitter()
        return mi.Point2f((mi.Float(x) + jx) * (1.0 / self.nx), (mi.Float(y) + jy) * (1.0 / self.ny))


def _start(sampler, cls, pixel, index, spp, seed, **constants):
    seed = sampler.render_seed(seed)
    cls = stream_class(cls, count=spp, jitter=sampler.jitter, **constants)
    rng = IndependentSampler.make_rng(pixel * spp + index, seed ^ 0x5851F42D)
    return cls(index=mi.UInt32(index), dim=mi.UInt32(0), key=hash_u32(pixel, seed), rng=rng)


@SAMPLERS.register("stratified")
class StratifiedSampler(Sampler):
    """``stratified``: jittered stratified sampling. A 1D draw puts the pixel's N samples
    in N equal strata, a 2D draw in an nx x ny grid; the order is shuffled per pixel and
    dimension. Mitsuba's parameters (``sample_count``, rounded up to a square, n x n grid)
    or pbrt-v4's (``xsamples`` x ``ysamples`` grid, N = xsamples * ysamples); a render with
    another spp uses the square grid of that spp rounded up, as Mitsuba does.

    ============  ====  =======  ================================================================
    name          type  default  meaning
    ============  ====  =======  ================================================================
    sample_count  int   4        samples per pixel (Mitsuba; or pbrt-v4's ``pixelsamples``), rounded
                                 up to a square
    xsamples      int   --       pbrt-v4: strata along x of the 2D grid (with ``ysamples``)
    ysamples      int   --       pbrt-v4: strata along y of the 2D grid
    jitter        bool  true     a random position inside each stratum (else its centre)
    seed          int   0        offset added to the seed a render is given
    ============  ====  =======  ================================================================
    """

    name = "stratified"

    def __init__(self, props=None):
        self.grid = None
        if props is not None and (props.has("xsamples") or props.has("ysamples")):
            if props.has("sample_count") or props.has("pixelsamples"):
                raise props.error("xsamples", "give either 'sample_count' (Mitsuba) or 'xsamples' and 'ysamples' "
                                  "(pbrt-v4), not both")
            self.grid = (props.int("xsamples", 4, min=1), props.int("ysamples", 4, min=1))
        super().__init__(props)
        if self.grid:
            self.sample_count = self.grid[0] * self.grid[1]
        self.jitter = props.bool("jitter", True) if props else True
        if props:
            props.finish()

    def round_spp(self, spp, warn=False):
        if self.grid and spp == self.grid[0] * self.grid[1]:
            return spp
        n = math.isqrt(spp - 1) + 1
        return self._rounded(spp, n * n, "a square sample count", warn)

    def start(self, pixel, index, spp, size, seed):
        nx, ny = self.grid if self.grid and spp == self.grid[0] * self.grid[1] else (math.isqrt(spp),) * 2
        return _start(self, StratifiedStream, pixel, index, spp, seed, nx=nx, ny=ny)


class MultijitterStream(StratifiedStream):
    """Correlated multi-jittered 2D draws (Kensler 2013): one sample per cell of an
    nx x ny grid and, projected on either axis, one per each of the N = nx * ny strata."""

    def next_2d(self):
        key = hash_u32(self.key, self.dim, 3)
        s = mi.permute_kensler(self.index, self.count, key)
        self.dim = self.dim + 1
        row = s // self.nx
        col = s - row * self.nx
        # columns shuffle their samples' y sub-strata, rows their x sub-strata, each with
        # one permutation for all (the correlation that avoids clumps)
        sx = mi.permute_kensler(row, self.ny, hash_u32(key, 0xA511E9B3))
        sy = mi.permute_kensler(col, self.nx, hash_u32(key, 0x63D83595))
        jx = self._jitter()
        jy = self._jitter()
        x = (mi.Float(col) + (mi.Float(sx) + jx) * (1.0 / self.ny)) * (1.0 / self.nx)
        y = (mi.Float(row) + (mi.Float(sy) + jy) * (1.0 / self.nx)) * (1.0 / self.ny)
        return mi.Point2f(x, y)


@SAMPLERS.register("multijitter")
class MultijitterSampler(Sampler):
    """``multijitter``: Mitsuba's correlated multi-jittered sampler (Kensler 2013): 2D
    draws are stratified in an nx x ny grid and in N strata along each axis; 1D draws in N
    strata. The sample count is rounded up as Mitsuba does (r = floor(cbrt(N)), N' =
    ceil(N / r^2) r^2); the 2D grid is the most square factorisation of N'.

    ============  ====  =======  ================================================================
    name          type  default  meaning
    ============  ====  =======  ================================================================
    sample_count  int   4        samples per pixel (rounded up, see above)
    jitter        bool  true     a random position inside each sub-stratum (else its centre)
    seed          int   0        offset added to the seed a render is given
    ============  ====  =======  ================================================================
    """

    name = "multijitter"

    def __init__(self, props=None):
        super().__init__(props)
        self.jitter = props.bool("jitter", True) if props else True
        if props:
            props.finish()

    def round_spp(self, spp, warn=False):
        r = max(1, round(spp ** (1.0 / 3.0)))
        while r ** 3 > spp:
            r -= 1
        r = max(r, 1)
        return self._rounded(spp, -(-spp // (r * r)) * r * r, "a sample count of the form n r^2", warn)

    def start(self, pixel, index, spp, size, seed):
        nx = max(d for d in range(1, math.isqrt(spp) + 1) if spp % d == 0)
        return _start(self, MultijitterStream, pixel, index, spp, seed, nx=nx, ny=spp // nx)


def _is_prime(n: int) -> bool:
    return n >= 2 and all(n % k for k in range(2, math.isqrt(n) + 1))


class OrthogonalStream(StratifiedStream):
    """Orthogonal-array draws (Bose's construction of strength 2 over a prime p): sample
    i = (a0, a1) in base p has in column c = 0, 1, ..., p the level a0, a1, a0 + (c-1) a1
    (mod p); any two columns take every pair of levels once. A 1D draw is one column's
    level, refined by the next column's (shuffled: a Latin hypercube of p^2 strata); two
    consecutive draws are stratified jointly in a p x p grid, as multi-jittered points.
    After p + 1 draws the columns are reused with the samples reshuffled (a new round)."""

    next_2d = SampleStream.next_2d      # two consecutive columns: stratified in p x p

    def next_1d(self):
        p, cols = self.p, self.p + 1
        c = self.dim % cols
        rnd = self.dim // cols
        key = hash_u32(self.key, self.dim, 4)
        self.dim = self.dim + 1
        i = mi.permute_kensler(self.index, self.count, hash_u32(self.key, rnd, 5))
        a0 = i // p
        a1 = i - a0 * p

        def level(col):
            return dr.select(col == 0, a0, dr.select(col == 1, a1, (a0 + (col - 1) * a1) % p))
        stratum = mi.permute_kensler(level(c), p, hash_u32(key, 0x51633E2D))
        sub = mi.permute_kensler(level((c + 1) % cols), p, hash_u32(key, 0x68BC21EB))
        return (mi.Float(stratum) + (mi.Float(sub) + self._jitter()) * (1.0 / p)) * (1.0 / p)


@SAMPLERS.register("orthogonal")
class OrthogonalSampler(Sampler):
    """``orthogonal``: Mitsuba's orthogonal array sampler (Jarosz et al. 2019), strength 2:
    every pair of dimensions within a round of p + 1 draws is stratified like correlated
    multi-jittered points, and every dimension in p^2 strata. Mitsuba reuses the array's
    columns past p + 1 dimensions (dimension j and j + p then share their strata up to a
    permutation); pbr starts a new round with the samples reshuffled instead.

    ============  ====  =======  ================================================================
    name          type  default  meaning
    ============  ====  =======  ================================================================
    sample_count  int   4        samples per pixel, rounded up to the square of a prime
    strength      int   2        the array's strength (2 only: Bose's construction)
    jitter        bool  true     a random position inside each sub-stratum (else its centre)
    seed          int   0        offset added to the seed a render is given
    ============  ====  =======  ================================================================
    """

    name = "orthogonal"

    def __init__(self, props=None):
        super().__init__(props)
        self.jitter = props.bool("jitter", True) if props else True
        if props and props.int("strength", 2) != 2:
            raise props.error("strength", "only strength 2 is supported (Bose's construction)")
        if props:
            props.finish()

    def round_spp(self, spp, warn=False):
        p = 2
        while p * p < spp or not _is_prime(p):
            p += 1
        return self._rounded(spp, p * p, "the square of a prime as sample count", warn)

    def start(self, pixel, index, spp, size, seed):
        p = math.isqrt(spp)
        return _start(self, OrthogonalStream, pixel, index, spp, seed, p=p, nx=p, ny=p)
