"""``pmj02bn``: pbrt-v4's progressive multi-jittered (0,2) sampler with blue-noise offsets.

2D draws read points of precomputed *pmj02bn* sequences (Christensen, Kensler and
Kilpatrick 2018): every prefix of 2^k points has exactly one point in each elementary
interval of area 2^-k (all shapes 2^-a x 2^-(k-a)), and points are placed as far as
possible from the earlier ones (best candidate: blue noise). pbr generates its sets
itself (:func:`generate_pmj02bn`; :func:`main` rebuilds ``data/pmj02bn_5x4096.npy``):
5 sets of 4096 points, where pbrt-v4 ships 5 sets of 65536.

As in pbrt-v4: the film position takes set 0, sorted into the pixels of a tile (each pixel
of a tile^2 block gets its own sub-square's points); the 2D draw of dimension d takes set
d / 2 (mod 5) at the sample index permuted per pixel and dimension (pbrt-v4 permutes
only past the last set); a 1D draw puts the pixel's samples in N strata (a permuted index) plus an
offset. The offsets (a toroidal shift per pixel and dimension) are pbrt-v4's blue-noise
texture values; pbr's are an R2 (plastic-constant) dither of the pixel, which is blue noise
across pixels, shifted by a hash of (dimension, seed): uniform for every pixel over the
seeds, so that renders with different seeds are independent, unbiased estimates.
"""

from __future__ import annotations

import functools
import os

import drjit as dr
import mitsuba as mi
import numpy as np

from .base import SAMPLERS, SampleStream, Sampler, hash_u32, stream_class, u32_to_unit

N_SETS = 5
N_POINTS = 4096
_DATA = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data", "pmj02bn_5x4096.npy")
ONE_MINUS_EPSILON = 0.99999994


# ------------------------------------------------------------------------ generation

def _valid(occ, xq, yq, size, m, rng, candidates, check=True):
    """Up to ``candidates`` random points in the square [xq, xq + size) x [yq, yq + size)
    (in units of 2^-m) whose elementary intervals of area 2^-m are all empty (``occ[a]``:
    the 2^a x 2^(m-a) flags); a point's intervals depend only on its cell of side 2^-m."""
    xs = xq + np.arange(size)
    ys = yq + np.arange(size)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    ok = np.ones(X.shape, bool)
    if check:
        for a in range(m + 1):
            ok &= ~occ[a][X >> (m - a), Y >> a]
    cells = np.argwhere(ok)
    pick = cells[rng.integers(0, len(cells), candidates)] if len(cells) else cells
    return (np.stack([xs[pick[:, 0]], ys[pick[:, 1]]], -1) + rng.random((len(pick), 2))) / (1 << m)


def _spread(cands, placed):
    """Each candidate's smallest squared toroidal distance to the ``placed`` points."""
    d = np.abs(cands[:, None, :] - placed[None, :, :])
    d = np.minimum(d, 1.0 - d)
    return (d ** 2).sum(-1).min(1)


def _mark(occ, p, m):
    xi, yi = int(p[0] * (1 << m)), int(p[1] * (1 << m))
    for a in range(m + 1):
        occ[a][xi >> (m - a), yi >> a] = True


def generate_pmj02bn(n: int, rng: np.random.Generator, candidates: int = 8, check: bool = True) -> np.ndarray:
    """``n`` (a power of 2) points of a progressive multi-jittered (0,2) sequence with
    best-candidate placement (Christensen et al. 2018), as (n, 2) float64 in [0, 1).

    From 4^k points (one per cell of a 2^k grid), the next 4^k go to the sub-quadrant
    diagonally opposite each point's (in its cell), the 2 * 4^k after them to the two
    sub-quadrants left (which of them first: the choice whose point lies farther from the
    points so far), each at a position whose elementary intervals at the new count are
    empty, the farthest of ``candidates`` (1: plain pmj02). ``check=False`` skips the
    interval test: the points are then only multi-jittered by cell, which the tests use
    to see their check fail."""
    pts = np.zeros((n, 2))
    pts[0] = rng.random(2)
    count, k = 1, 0                     # count = 4^k points, in a 2^k grid
    while count < n:
        for odd in (False, True):       # 4^k -> 2 * 4^k, then -> 4^(k+1)
            target = count * 2
            if target > n:
                break
            m = target.bit_length() - 1
            occ = [np.zeros((1 << a, 1 << (m - a)), bool) for a in range(m + 1)]
            for p in pts[:count]:
                _mark(occ, p, m)
            sub = 1 << (m - k - 1)       # a sub-quadrant's side, in units of 2^-m
            placed = list(pts[:count])

            def put(out, quadrant, cands=None):
                if cands is None:
                    cands = _valid(occ, quadrant[0] * sub, quadrant[1] * sub, sub, m, rng, candidates, check)
                if len(cands) == 0:
                    raise RuntimeError(f"pmj02: no valid position for point {out}")
                p = cands[int(np.argmax(_spread(cands, np.array(placed))))]
                pts[out] = p
                placed.append(p)
                _mark(occ, p, m)

            half = count // 2
            for s in range(count if not odd else half):
                c = np.floor(pts[s] * (2 << k)).astype(int)      # its sub-quadrant
                if not odd:
                    put(count + s, (c[0] ^ 1, c[1] ^ 1))
                    continue
                # the two sub-quadrants left: x flipped or y flipped, the farther first
                options = [((c[0] ^ 1, c[1]), (c[0], c[1] ^ 1)), ((c[0], c[1] ^ 1), (c[0] ^ 1, c[1]))]
                found = [(q, _valid(occ, q[0][0] * sub, q[0][1] * sub, sub, m, rng, candidates, check))
                         for q in options]
                score = [_spread(v, np.array(placed)).max() if len(v) else -1.0 for _, v in found]
                q, cands = found[int(np.argmax(score))]
                put(count + s, q[0], cands)
                put(count + half + s, q[1])
            count = target
        k += 1
    return pts


# ------------------------------------------------------------------------ the sampler

@functools.lru_cache(maxsize=None)
def pmj02bn_sets() -> np.ndarray:
    """(5, 4096, 2) uint32: the points of the shipped sets as 32-bit fixed-point fractions."""
    return np.load(_DATA)


@functools.lru_cache(maxsize=None)
def pixel_tile(spp: int) -> tuple:
    """(tile, samples): set 0's points sorted into a tile x tile block of pixels (tile =
    2^(6 - log4 spp), spp rounded up to a power of 4), the first ``spp`` points in each
    pixel's sub-square, as positions inside that pixel: (tile^2 * spp, 2) uint32."""
    spp4 = _pow4_at_least(spp)[1]
    tile = 1
    while tile * tile * spp4 < N_POINTS:
        tile *= 2
    pts = pmj02bn_sets()[0].astype(np.uint64)
    cell = pts * tile >> 32                      # the pixel of each point
    frac = ((pts * tile) & 0xFFFFFFFF).astype(np.uint32)
    offset = cell[:, 0] + cell[:, 1] * tile
    out = np.zeros((tile * tile, spp, 2), np.uint32)
    stored = np.zeros(tile * tile, int)
    for i in range(N_POINTS):
        o = int(offset[i])
        if stored[o] < spp:
            out[o, stored[o]] = frac[i]
            stored[o] += 1
    assert np.all(stored == spp)
    return tile, out.reshape(-1, 2)


def _pow4_at_least(spp: int) -> tuple:
    """(j, 4^j): the smallest power of 4 >= ``spp``."""
    j = 0
    while 4 ** j < spp:
        j += 1
    return j, 4 ** j


def tables() -> dict:
    """The Dr.Jit tables of the current variant (``pbr.freeze`` hands them to ``dr.freeze``
    as state): ``sets`` (flat, x and y interleaved) and ``tiles``: the pixel tables of
    :func:`pixel_tile` for spp = 1, 4, ..., 4096, each 2 * 4096 entries, one after the other
    (a render of spp reads the table of spp rounded up to a power of 4, its first spp
    points per pixel)."""
    return _tables(mi.variant())


@functools.lru_cache(maxsize=None)
def _tables(variant: str) -> dict:
    levels = np.concatenate([pixel_tile(4 ** j)[1].ravel() for j in range(7)])
    return {"sets": mi.UInt32(pmj02bn_sets().ravel()), "tiles": mi.UInt32(levels)}


def _wrap(u):
    u = dr.select(u >= 1.0, u - 1.0, u)
    return dr.minimum(u, ONE_MINUS_EPSILON)


class PMJ02BNStream(SampleStream):
    """A pixel sample of ``pmj02bn``: 2D draws read the pmj02bn sets at a permuted index,
    1D draws permute the pixel's strata; both shifted by the pixel's offset for that
    dimension."""

    _fields = {"px": "UInt32", "py": "UInt32", "index": "UInt32", "dim": "UInt32", "seed": "UInt32"}
    varying = ("dim",)
    # constants: spp, spp4 (spp rounded up to a power of 4 = 4^level), tile (pixel tile side)

    def _offset(self, dim):
        """The pixel's toroidal shift for ``dim``: an R2 dither of the pixel (blue noise
        across pixels) plus a hash of (dimension, seed), modulo 1."""
        r2 = mi.Float(self.px) * 0.7548776662466927 + mi.Float(self.py) * 0.5698402909980532
        v = r2 - dr.floor(r2) + u32_to_unit(hash_u32(dim, self.seed, 0x5BD1E995))
        return dr.select(v >= 1.0, v - 1.0, v)

    def _permuted(self, dim):
        return mi.permute_kensler(self.index, self.spp, hash_u32(self.px, self.py, dim, self.seed))

    def next_1d(self):
        d = self.dim
        self.dim = d + 1
        i = self._permuted(d)
        return dr.minimum((mi.Float(i) + self._offset(d)) * (1.0 / self.spp), ONE_MINUS_EPSILON)

    def next_2d(self):
        d = self.dim
        self.dim = d + 2
        # pbrt-v4 permutes the index only past the last set; permuting it always
        # decorrelates draws that read the same index of different sets (measured on
        # bench_samplers' direct scene: 3.4x lower relMSE at 1024 spp, the same at 16)
        i = self._permuted(d)
        at = (((d // 2) % N_SETS) * N_POINTS + i) * 2
        sets = tables()["sets"]
        x = u32_to_unit(dr.gather(mi.UInt32, sets, at))
        y = u32_to_unit(dr.gather(mi.UInt32, sets, at + 1))
        return mi.Point2f(_wrap(x + self._offset(d)), _wrap(y + self._offset(d + 1)))

    def pixel_2d(self):
        # set 0 sorted into the pixels of a tile (pbrt-v4's GetPixel2D), shifted per pixel
        # by a hash of the seed (pbrt-v4 leaves it unshifted; shifted, renders with
        # different seeds are independent estimates, as pbr.validate needs)
        at = (self.level * 2 * N_POINTS
              + (((self.py % self.tile) * self.tile + self.px % self.tile) * self.spp4 + self.index) * 2)
        table = tables()["tiles"]
        x = u32_to_unit(dr.gather(mi.UInt32, table, at))
        y = u32_to_unit(dr.gather(mi.UInt32, table, at + 1))
        return mi.Point2f(_wrap(x + self._offset(0)), _wrap(y + self._offset(1)))


class _TooMany(ValueError):
    """More samples per pixel than the point sets hold."""


@SAMPLERS.register("pmj02bn")
class PMJ02BNSampler(Sampler):
    """``pmj02bn``: pbrt-v4's ``PMJ02BNSampler``: 2D draws from progressive multi-jittered
    (0,2) point sets with blue-noise placement, 1D draws stratified with a permuted index,
    each shifted per pixel and dimension (pbr: an R2 dither plus a hash of the seed, where
    pbrt-v4 reads a blue-noise texture). Best with a power of 4 samples per pixel; at most
    4096 (pbr's sets have 4096 points; pbrt-v4's 65536).

    ============  ====  =======  ================================================================
    name          type  default  meaning
    ============  ====  =======  ================================================================
    sample_count  int   16       samples per pixel, at most 4096; a power of 4 is best (pbrt-v4's
                                 ``pixelsamples`` too)
    seed          int   0        offset added to the seed a render is given
    ============  ====  =======  ================================================================
    """

    name = "pmj02bn"

    def __init__(self, props=None):
        try:
            super().__init__(props, default_count=16)
        except _TooMany as e:
            if props is None:
                raise
            raise props.error("pixelsamples" if props.has("pixelsamples") else "sample_count", e.why) from None
        if props:
            props.finish()

    def round_spp(self, spp, warn=False):
        if spp > N_POINTS:
            why = (f"the 'pmj02bn' sampler takes at most {N_POINTS} samples per pixel (its point sets have "
                   f"{N_POINTS} points), got {spp}")
            e = _TooMany(f"{self.path}: {why}")
            e.why = why
            raise e
        return spp

    def start(self, pixel, index, spp, size, seed):
        self.round_spp(spp)
        w = size[0]
        level, spp4 = _pow4_at_least(spp)
        tile = 1 << (6 - level)
        cls = stream_class(PMJ02BNStream, spp=spp, spp4=spp4, level=level, tile=tile)
        return cls(px=pixel % w, py=pixel // w, index=mi.UInt32(index), dim=mi.UInt32(2),
                   seed=self.render_seed(seed))


def main(path: str = _DATA, seed: int = 20180627) -> None:
    """Generate the shipped sets and save them (about a minute with NumPy:
    ``python -c "from pbr.samplers.pmj02bn import main; main()"``)."""
    rng = np.random.default_rng(seed)
    sets = [generate_pmj02bn(N_POINTS, rng) for _ in range(N_SETS)]
    fixed = np.minimum(np.floor(np.stack(sets) * 2.0 ** 32), 2 ** 32 - 1).astype(np.uint32)
    np.save(path, fixed)

