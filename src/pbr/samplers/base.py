"""The sampler interface: a sampler plugin starts one *sample stream* per camera sample.

pbrt-v4's ``Sampler::StartPixelSample(p, index, dim)`` as a vectorised call: a plugin's
:meth:`Sampler.start` takes per-lane pixel and sample indices and returns a
:class:`SampleStream`, a Dr.Jit struct (loop state of the integrators' symbolic loops)
whose ``next_1d`` / ``next_2d`` give the next dimensions of that pixel sample's point.

Dimension allocation follows pbrt-v4: the camera draws the wavelength (1D), the film
position (``pixel_2d``) and the lens (2D); a path tracer then draws the same number of
dimensions at every bounce (light choice 1D, light position 2D, BSDF lobe 1D, BSDF
direction 2D, Russian roulette 1D), so a dimension always feeds the same integrand and
low-discrepancy points reach the integrands that benefit. Integrators draw with
``next_float32()`` (the name of ``mi.PCG32``'s method: every stream is usable where a
PCG32 was) or ``next_1d()`` / ``next_2d()``.

A stream depends only on (pixel, sample index, spp, seed): renders split into passes,
adaptive renderers that start streams for any subset of (pixel, index) pairs, and
repeated renders with the same seed see the same numbers. Reverse-mode renders replay a
path by copying the stream (:meth:`SampleStream.copy`) and give ``seed_grad`` to a
second set of streams, which decorrelates the adjoint from the primal image (every
randomised sampler scrambles by the seed; with ``randomization='none'`` the points do not
depend on the seed at all).
"""

from __future__ import annotations

import functools
import warnings

import drjit as dr
import mitsuba as mi

from ..backend import Struct
from ..plugins.props import Props
from ..plugins.registry import Registry
from ..sampling import mix32

SAMPLERS = Registry("sampler")
# pbrt-v4's randomisations of low-discrepancy points (its 'randomization' parameter), and
# Cranley-Patterson rotation (a random toroidal shift per dimension).
RANDOMIZATIONS = ("none", "permutedigits", "fastowen", "owen", "cranleypatterson")


def seed_array(seed) -> mi.UInt32:
    """``seed`` (a Python int or a width-1 ``mi.UInt32``) as an opaque ``mi.UInt32``."""
    if isinstance(seed, int):
        return dr.opaque(mi.UInt32, seed & 0xFFFFFFFF)
    if not (isinstance(seed, mi.UInt32) and dr.width(seed) == 1):
        raise TypeError(f"seed: expected a Python int or a mi.UInt32 of width 1, got {type(seed).__name__}")
    return seed


def hash_u32(*values) -> mi.UInt32:
    """A per-lane 32-bit hash of ``values`` (``mi.UInt32`` arrays or Python ints)."""
    h = mi.UInt32(0x9E3779B9)
    for k, v in enumerate(values):
        h = mix32(h ^ (v if isinstance(v, mi.UInt32) else mi.UInt32(v & 0xFFFFFFFF)) ^ (0x85EBCA6B * (k + 1) & 0xFFFFFFFF))
    return h


def u32_to_unit(v: mi.UInt32) -> mi.Float:
    """A 32-bit fixed-point fraction as a float in [0, 1) (its top 24 bits, exactly)."""
    return mi.Float(v >> 8) * (1.0 / (1 << 24))


class SampleStream(Struct):
    """One camera sample's stream of sample dimensions (a Dr.Jit struct: the fields named
    in ``_fields`` are per-lane arrays; constants are class attributes, because Dr.Jit
    rebuilds loop state with ``type(stream)()``)."""

    def __init__(self, **fields):
        # Only the given fields: Dr.Jit builds empty instances and fills them in.
        for k, v in fields.items():
            if k not in self._fields:
                raise TypeError(f"{type(self).__name__}(): unexpected field {k!r}")
            setattr(self, k, v)

    def next_1d(self) -> mi.Float:
        raise NotImplementedError

    def next_float32(self) -> mi.Float:
        """The next 1D dimension (``mi.PCG32``'s method name, which integrators call)."""
        return self.next_1d()

    def next_uint32(self) -> mi.UInt32:
        """A 32-bit key from the next dimension (``mi.PCG32``'s method: integrators that
        seed streams of their own from it, e.g. ``whitted``'s branches)."""
        return mix32(dr.reinterpret_array(mi.UInt32, self.next_1d()))

    def next_2d(self) -> mi.Point2f:
        """The next two dimensions as a 2D point (a stratified pair where the sampler has one)."""
        u = self.next_1d()
        return mi.Point2f(u, self.next_1d())

    def pixel_2d(self) -> mi.Point2f:
        """The position inside the pixel (the filter's sample): the sampler's best 2D pair."""
        return self.next_2d()

    # The arrays a draw changes, as field names or "field.attribute" (a PCG32's "state";
    # its "inc" is the stream's constant id); None: every field.
    varying = None

    def _varying(self) -> tuple:
        return self.varying or tuple(type(self).DRJIT_STRUCT)

    def loop_state(self) -> tuple:
        """The arrays a draw changes (:attr:`varying`): what a symbolic loop that draws
        from this stream carries. The stream itself stays outside the loop state, so its
        constant arrays do not make Dr.Jit trace the loop body twice."""
        out = []
        for name in self._varying():
            obj, _, attr = name.rpartition(".")
            out.append(getattr(getattr(self, obj) if obj else self, attr))
        return tuple(out)

    def set_loop_state(self, state: tuple) -> None:
        """Set the arrays :meth:`loop_state` returned (at the start of a loop iteration,
        and after the loop)."""
        for name, v in zip(self._varying(), state):
            obj, _, attr = name.rpartition(".")
            setattr(getattr(self, obj) if obj else self, attr, v)

    def copy(self) -> "SampleStream":
        """A stream with copies of this one's arrays (symbolic loops update their state in
        place: a path replay needs real copies, not references)."""
        return _copy(self)

    def assign(self, other: "SampleStream") -> None:
        """Set this stream's arrays to copies of ``other``'s (replay from a copy)."""
        for k in type(self).DRJIT_STRUCT:
            setattr(self, k, _copy(getattr(other, k)))


def _copy(v):
    if hasattr(type(v), "DRJIT_STRUCT"):
        out = type(v)()
        for k in type(v).DRJIT_STRUCT:
            setattr(out, k, _copy(getattr(v, k)))
        return out
    return type(v)(v)


def stream_class(base: type, **constants) -> type:
    """A subclass of ``base`` with ``constants`` as class attributes (the per-render
    constants of a stream: Dr.Jit rebuilds loop state with ``type(stream)()``, which
    keeps class attributes and drops instance ones); one class per set of constants."""
    return _stream_class(base, tuple(sorted(constants.items())))


@functools.lru_cache(maxsize=None)
def _stream_class(base: type, constants: tuple) -> type:
    return type(base.__name__, (base,), dict(constants))


class Sampler:
    """Base of the sampler plugins: ``sample_count`` (Mitsuba's name; pbrt-v4's
    ``pixelsamples`` is accepted too) and ``seed``, which offsets the seed a render is
    given (``pbr.render(seed=...)``).

    Subclasses implement :meth:`start`; :meth:`round_spp` is the sample count a render of
    ``spp`` samples per pixel uses (patterns of a fixed size round it, as Mitsuba and
    pbrt-v4 do, with a warning)."""

    name = ""
    # Whether stream i of a pixel is the same whatever the pixel's spp: a progressive
    # sampler (an adaptive renderer can add samples 0..n to a pixel without a budget).
    progressive = False

    def __init__(self, props: Props | None = None, default_count: int = 4):
        self.path = props.path if props else "sampler"
        count = default_count
        if props is not None:
            if props.has("pixelsamples") and props.has("sample_count"):
                raise props.error("sample_count", "give either 'sample_count' (Mitsuba) or 'pixelsamples' "
                                  "(pbrt-v4), not both")
            if props.has("pixelsamples"):
                count = props.int("pixelsamples", min=1)
            else:
                count = props.int("sample_count", default_count, min=1)
        self.seed = props.int("seed", 0) if props else 0
        self.requested = count
        self.sample_count = self.round_spp(count, warn=True)

    def round_spp(self, spp: int, warn: bool = False) -> int:
        """The number of samples per pixel a render asking for ``spp`` takes."""
        return spp

    def _rounded(self, spp: int, rounded: int, why: str, warn: bool) -> int:
        if warn and rounded != spp:
            warnings.warn(f"{self.path}: the {self.name!r} sampler takes {why}: {spp} samples per pixel "
                          f"rounded to {rounded}", RuntimeWarning, stacklevel=4)
        return rounded

    def render_seed(self, seed: mi.UInt32) -> mi.UInt32:
        """The render's seed offset by this sampler's ``seed`` parameter."""
        return seed + self.seed if self.seed else seed

    def start(self, pixel: mi.UInt32, index: mi.UInt32, spp: int, size: tuple, seed: mi.UInt32) -> SampleStream:
        """Streams of the camera samples (``pixel`` = y * width + x, sample ``index`` in
        0..spp-1 of that pixel) of a ``size`` = (width, height) film; ``seed`` is the
        render's opaque seed. Every argument but ``spp`` and ``size`` is per lane."""
        raise NotImplementedError


def log2_int(n: int) -> int:
    return max(0, (n - 1).bit_length()) if n > 0 else 0


def round_up_pow2(n: int) -> int:
    return 1 << log2_int(n)


def parse_randomization(props: Props | None, default: str, allowed=RANDOMIZATIONS) -> str:
    """pbrt-v4's ``randomization`` parameter (one of ``allowed``)."""
    if props is None:
        return default
    return props.string("randomization", default, choices=allowed)


def cranley_patterson(u: mi.Float, dim, seed: mi.UInt32) -> mi.Float:
    """``u`` shifted by a random offset per dimension (and seed), modulo 1."""
    v = u + u32_to_unit(hash_u32(dim, seed, 0x2545F491))
    return dr.select(v >= 1.0, v - 1.0, v)
