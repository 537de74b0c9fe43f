"""Low-discrepancy points, vectorised: Sobol' generator matrices and samples, radical
inverses (Halton), and their randomisations (pbrt-v4's chapter 8: digit permutation,
Owen scrambling, its hash-based fast approximation, Cranley-Patterson rotation).

The Sobol' generator matrices are built from Joe and Kuo's direction numbers (the first
1024 dimensions, ``data/sobol_joe_kuo_1024.txt``, as SciPy ships them): a matrix column
is a 32-bit fixed-point fraction, the first digit in the top bit, so a sample of index
``a`` in dimension ``d`` is the XOR of the columns of ``d`` where ``a`` has a 1 bit.
"""

from __future__ import annotations

import functools
import itertools
import os

import drjit as dr
import mitsuba as mi
import numpy as np

from ..sampling import mix32

SOBOL_DIMENSIONS = 1024
PRIMES = 1000              # Halton dimensions (pbrt-v4's PrimeTableSize)
SOBOL_BITS = 32
_DATA = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data", "sobol_joe_kuo_1024.txt")


@functools.lru_cache(maxsize=None)
def sobol_matrices() -> np.ndarray:
    """(1024, 32) uint32: column j of dimension d's generator matrix (digit 1 = top bit).

    Dimension 0 is the van der Corput sequence (column j = 2^(31-j)); dimension d > 0
    follows the Bratley-Fox recurrence of its primitive polynomial x^s + a_1 x^(s-1) +
    ... + a_(s-1) x + 1 over its initial direction integers m_1..m_s:
    m_k = 2 a_1 m_(k-1) ^ 4 a_2 m_(k-2) ^ ... ^ 2^s m_(k-s) ^ m_(k-s)."""
    with open(_DATA) as f:
        rows = [list(map(int, line.split())) for line in f if line.strip() and not line.startswith("#")]
    out = np.zeros((SOBOL_DIMENSIONS, SOBOL_BITS), np.uint64)
    for d, (poly, *m_init) in enumerate(rows[:SOBOL_DIMENSIONS]):
        if d == 0:
            m = [1] * SOBOL_BITS
        else:
            s = poly.bit_length() - 1
            a = [(poly >> (s - k)) & 1 for k in range(1, s)]     # a_1 .. a_(s-1)
            m = list(m_init[:s])
            for k in range(s, SOBOL_BITS):
                v = m[k - s] ^ (m[k - s] << s)
                for i, ai in enumerate(a, start=1):
                    if ai:
                        v ^= m[k - i] << i
                m.append(v)
        for j in range(SOBOL_BITS):
            out[d, j] = m[j] << (SOBOL_BITS - 1 - j)
    assert np.all(out < (1 << 32))
    return out.astype(np.uint32)


def tables() -> dict:
    """The samplers' Dr.Jit tables of the current variant (cached per variant: Dr.Jit
    arrays belong to a backend): ``sobol`` (the generator matrices, flat, dimension-major),
    ``primes`` (Halton's bases), ``perm4`` (the 24 permutations of 4 digits, packed 2 bits
    each, for zsobol). ``pbr.freeze`` hands them to ``dr.freeze`` as state: arrays made
    before a recording must be its inputs."""
    return _tables(mi.variant())


@functools.lru_cache(maxsize=None)
def _tables(variant: str) -> dict:
    perm4 = [sum(d << (2 * k) for k, d in enumerate(p)) for p in itertools.permutations(range(4))]
    return {"sobol": mi.UInt32(sobol_matrices().ravel()), "primes": mi.UInt32(primes(PRIMES)),
            "perm4": mi.UInt32(perm4)}


def sobol_table() -> mi.UInt32:
    return tables()["sobol"]


def sobol_bits(index: mi.UInt32, dim, nbits: int) -> mi.UInt32:
    """The unscrambled 32-bit Sobol' fraction of ``index`` (< 2^nbits) in dimension ``dim``
    (a Python int: the columns are constants; or a per-lane ``mi.UInt32``: gathered)."""
    v = mi.UInt32(0)
    if isinstance(dim, int):
        cols = sobol_matrices()[dim]
        for j in range(nbits):
            v ^= dr.select(((index >> j) & 1) != 0, mi.UInt32(int(cols[j])), 0)
        return v
    table, base = sobol_table(), dim * SOBOL_BITS
    for j in range(nbits):
        v ^= dr.gather(mi.UInt32, table, base + j, ((index >> j) & 1) != 0)
    return v


# ------------------------------------------------------------------ randomisations

def fast_owen(v: mi.UInt32, seed: mi.UInt32) -> mi.UInt32:
    """Hash-based approximation of an Owen scramble (Burley 2020, after Laine and Karras):
    on the bit-reversed value, each bit is flipped by a hash of the bits below it (carries
    and multiplications by even constants only move information upward)."""
    x = dr.brev(v)
    x += seed
    x ^= x * 0x6C50B47C
    x ^= x * 0xB82F1E52
    x ^= x * 0xC7AFE638
    x ^= x * 0x8D22F6E6
    return dr.brev(x)


def owen(v: mi.UInt32, seed: mi.UInt32, bits: int = 24) -> mi.UInt32:
    """Owen scrambling of the first ``bits`` digits: digit k is flipped by a hash of the
    k digits above it and the seed (the nested uniform scramble, one random bit per node
    of the binary tree)."""
    out = v ^ (mix32(seed) & 0x80000000)
    for k in range(1, bits):
        prefix = v >> (32 - k)            # the k digits above digit k
        flip = mix32(prefix ^ mix32(seed ^ (k * 0x9E3779B9 & 0xFFFFFFFF))) & 1
        out ^= flip << (31 - k)
    return out


def scramble_bits(v: mi.UInt32, seed: mi.UInt32, randomization: str) -> mi.UInt32:
    """A base-2 fraction randomised by pbrt-v4's strategy ``randomization`` ('none',
    'permutedigits': XOR with the seed, 'fastowen', 'owen'); 'cranleypatterson' is
    applied to the float (:func:`..base.cranley_patterson`), not here."""
    if randomization == "permutedigits":
        return v ^ seed
    if randomization == "fastowen":
        return fast_owen(v, seed)
    if randomization == "owen":
        return owen(v, seed)
    return v


# ------------------------------------------------------------------ radical inverses

@functools.lru_cache(maxsize=None)
def primes(n: int = 1000) -> np.ndarray:
    """The first ``n`` primes (the bases of the Halton dimensions)."""
    limit = 8000
    sieve = np.ones(limit, bool)
    sieve[:2] = False
    for i in range(2, int(limit ** 0.5) + 1):
        if sieve[i]:
            sieve[i * i::i] = False
    return np.nonzero(sieve)[0][:n].astype(np.uint32)


def radical_inverse(index: mi.UInt32, base: mi.UInt32, perm_seed=None, owen_seed=None) -> mi.Float:
    """The radical inverse of ``index`` in per-lane prime ``base``: its base-b digits
    mirrored about the radix point. With ``perm_seed`` each digit position has its own
    random permutation of the digits (pbrt-v4's 'permutedigits'); with ``owen_seed`` the
    permutation of a digit depends on the digits before it too (Owen scrambling). Both
    continue past the index's last digit (a permuted 0 is not 0) until float precision."""
    scrambled = perm_seed is not None or owen_seed is not None
    # (lanes masked off by an enclosing loop gather base 0: no division by 0 there)
    base = dr.maximum(base, 2)
    inv_b = 1.0 / mi.Float64(base)   # not dr.rcp: approximate on CUDA (base 5: 0.4 came out 0.39999986 on an H100)
    idx = mi.UInt32(index)
    value = mi.Float64(0.0)
    scale = mi.Float64(inv_b)
    prefix = mi.UInt32(0)
    k = mi.UInt32(0)

    def cond(idx, value, scale, prefix, k):
        # scrambled digits go on to float32's resolution (2^-24; the result is a float)
        return (idx > 0) | (scrambled & (scale > 6e-8))

    def body(idx, value, scale, prefix, k):
        q = idx // base
        digit = idx - q * base
        if perm_seed is not None:
            digit = _permute_digit(digit, base, mix32(perm_seed ^ (k * 0x9E3779B9)))
        elif owen_seed is not None:
            h = mix32(owen_seed ^ mix32(prefix ^ (k * 0x9E3779B9)))
            prefix = prefix * 0x01000193 ^ (idx - q * base) + 1
            digit = _permute_digit(digit, base, h)
        value += mi.Float64(digit) * scale
        return q, value, scale * inv_b, prefix, k + 1

    idx, value, scale, prefix, k = dr.while_loop((idx, value, scale, prefix, k), cond, body, labels=(
        "idx", "value", "scale", "prefix", "k"), label="radical_inverse")
    return dr.minimum(mi.Float(value), 0.99999994)


def _permute_digit(digit: mi.UInt32, base: mi.UInt32, seed: mi.UInt32) -> mi.UInt32:
    """A pseudo-random permutation of 0..base-1 (per-lane base), chosen by ``seed``:
    digit -> (digit * a + c) mod base with a multiplier a in 1..base-1 (a bijection for a
    prime base) and an offset c from the two halves of one hash (bases < 2^16)."""
    h = mix32(seed)
    a = (h & 0xFFFF) % (base - 1) + 1
    c = (h >> 16) % base
    return (digit * a + c) % base
