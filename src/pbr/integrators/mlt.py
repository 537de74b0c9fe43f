"""``mlt``: Metropolis light transport in primary sample space over bidirectional path
tracing (pbrt-v4's ``MLTIntegrator``: Kelemen et al.'s PSSMLT with Veach's multiplexing
of BDPT strategies). Mitsuba 3 has none. The method (strategy selection, mutations,
expected-value splatting, bootstrap normalisation), validation and measurements:
docs/integrators.md.

Vectorisation: the Markov chains are the lanes of the kernels; an iteration mutates,
evaluates and accepts or rejects a proposal for every chain at once. The primary samples
are a Dr.Jit array of D values per chain, dimension-major (value i of chain j at
i * chains + j, so that lanes read neighbouring addresses), read by BDPT's own subpath
loops (:mod:`pbr.integrators.bdpt`, one strategy per lane) through
:class:`PrimarySampleStream`, which has PCG32's ``next_float32`` interface. D is fixed in
advance (:func:`stream_dims`).

Every coordinate is mutated at every iteration, where pbrt-v4 mutates a coordinate lazily,
when a path first reads it, by the composition of the mutations it missed (n small steps
in a row are one normal step of deviation sigma sqrt(n) on the torus; after a large step,
a fresh value). The two give the same distribution of proposals, and so the same chain:
coordinates a path does not read do not change its contribution. Eagerly, a proposal is
one pass over the chains x D array with no per-coordinate bookkeeping (pbrt-v4 keeps an
iteration count and a backup per coordinate, and the lanes of a kernel would read
different coordinates); it costs D normal draws per chain and iteration (about 20% of
an iteration's time).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import memory
from .. import spectrum as spec
from ..backend import Struct
from ..samplers import IndependentSampler, seed_array
from ..plugins.props import Props
from ..spectrum import SampledWavelengths
from .base import INTEGRATORS, SamplingIntegrator, _progress, pbrt_max_depth
from .bdpt import (BDPTIntegrator, Strategies, CAMERA_VERTEX_DIMS, LENS_DIMS, LIGHT_START_DIMS, LIGHT_VERTEX_DIMS)
from .lightpath import SplatFilm, lens_sample

CAMERA_START_DIMS = 4          # strategy, wavelengths, film position (x, y)
BOOTSTRAP_BATCH = 1 << 17      # bootstrap samples per kernel (bounds the light-vertex store)


def stream_dims(maxdepth: int, lens: bool = False) -> tuple[int, int]:
    """Coordinates of the camera and the light stream of a primary sample (at most what
    BDPT's subpaths of ``maxdepth`` bounces draw); with a thin ``lens``, the camera ray's
    lens point and each light vertex's connection to a lens point take LENS_DIMS more."""
    extra = LENS_DIMS if lens else 0
    return (CAMERA_START_DIMS + extra + CAMERA_VERTEX_DIMS * (maxdepth + 1),
            LIGHT_START_DIMS + (LIGHT_VERTEX_DIMS + extra) * maxdepth)


class PrimarySampleStream(Struct):
    """Random numbers read from the primary samples: ``next_float32()`` returns the next
    coordinate of the lane's stream. ``index`` (the loop state) is the position in the
    dimension-major array; the array and its lane count are class attributes of the
    subclass :meth:`over` makes, because Dr.Jit rebuilds loop-state structs from their
    fields alone."""

    _fields = {"index": "UInt32"}
    samples = None      # mi.Float: coordinate i of lane j at i * lanes + j
    lanes = 0

    @classmethod
    def over(cls, samples, lanes: int):
        return type(cls)(cls.__name__, (cls,), {"samples": samples, "lanes": lanes})

    @classmethod
    def at(cls, samples, lanes: int, first_dim: int):
        """A stream over ``samples`` that starts at coordinate ``first_dim`` of each lane."""
        return cls.over(samples, lanes)(first_dim * lanes + dr.arange(mi.UInt32, lanes))

    def next_float32(self) -> mi.Float:
        u = dr.gather(mi.Float, self.samples, self.index)
        self.index += self.lanes
        return u

    next_1d = next_float32

    def loop_state(self) -> tuple:
        """The stream's loop state (``SampleStream.loop_state``): its position."""
        return (self.index,)

    def set_loop_state(self, state: tuple) -> None:
        self.index, = state

    def next_2d(self) -> mi.Point2f:
        """The next two coordinates (the sample streams' interface, which bdpt draws from)."""
        u = self.next_float32()
        return mi.Point2f(u, self.next_float32())


def uniform_samples(index: mi.UInt32, seed: mi.UInt32, dims: int) -> mi.Float:
    """Fresh primary samples (dimension-major, ``dims`` per lane) for sample numbers
    ``index``: the same numbers whenever the same (index, seed) is asked for again."""
    rng = IndependentSampler.make_rng(index, seed)
    return _fill(dims, lambda i, rng: rng.next_float32(), rng)


@dr.syntax
def _fill(dims: int, value, rng):
    """A dimension-major array of ``dims`` values per lane of ``rng`` (a PCG32), value(i,
    rng) for coordinate i, written by one kernel: a symbolic loop over the coordinates
    (scatters outside a loop would launch a kernel each). ``rng`` is loop state: value
    must draw from the ``rng`` it is given."""
    n = dr.width(rng.state)
    out = dr.zeros(mi.Float, dims * n)
    lane = dr.arange(mi.UInt32, n)
    i = mi.UInt32(0)
    while dr.hint(i < dims, label="mlt_fill"):
        dr.scatter(out, value(i, rng), i * n + lane)
        i += 1
    dr.eval(out, rng)
    return out


def mutate(x, u, large, sigma: float):
    """pbrt-v4's mutation of one coordinate with one uniform number ``u``: a fresh value on
    large steps, else a normal offset of deviation ``sigma``, wrapped into [0, 1)."""
    g = dr.erfinv(dr.clip(2.0 * u - 1.0, -0.99999994, 0.99999994)) * (sigma * math.sqrt(2.0))
    y = x + g
    y = y - dr.floor(y)
    y = dr.select(y < 1.0, y, 0.0)   # x + g - floor(...) may round up to 1
    return dr.select(large, u, y)


class LaneSplats:
    """The t = 1 contribution of each lane (a lane evaluates one strategy, so at most
    one): its XYZ and film position, written from inside BDPT's light-subpath loop."""

    def __init__(self, n: int):
        self.lane = dr.arange(mi.UInt32, n)
        self.xyz_buf = dr.zeros(mi.Float, 3 * n)
        self.pos_buf = dr.zeros(mi.Float, 2 * n)

    def record(self, pos, L, wl, active):
        xyz = spec.to_xyz(L, wl)
        for c in range(3):
            dr.scatter(self.xyz_buf, xyz[c], self.lane * 3 + c, active)
        for c in range(2):
            dr.scatter(self.pos_buf, pos[c], self.lane * 2 + c, active)

    def xyz(self):
        return mi.Array3f([dr.gather(mi.Float, self.xyz_buf, self.lane * 3 + c) for c in range(3)])

    def pos(self):
        return mi.Point2f([dr.gather(mi.Float, self.pos_buf, self.lane * 2 + c) for c in range(2)])


@dataclass
class Chains:
    """The Markov chains' state: primary samples (dimension-major), path depth, the
    current path's XYZ, film position and luminance c, and each chain's PCG32."""
    x: mi.Float
    depth: mi.UInt32
    xyz: mi.Array3f
    pos: mi.Point2f
    c: mi.Float
    rng: mi.PCG32


FREEZE = True


@INTEGRATORS.register("mlt")
class MLTIntegrator(SamplingIntegrator):
    """``mlt``: Metropolis light transport over BDPT strategies (pbrt-v4's
    ``MLTIntegrator``); lights picked by power. No participating media, no derivatives.

    ====================  =====  =======  ====================================================
    name                  type   default  meaning
    ====================  =====  =======  ====================================================
    maxdepth              int    5        pbrt-v4's bounces (0: emitters seen directly)
    max_depth             int    -        Mitsuba's depth instead (= maxdepth + 1; finite)
    bootstrapsamples      int    100000   bootstrap samples per depth (the normalisation b
                                          and the chains' start states)
    chains                int    1000     Markov chains (lanes; at most the mutation count)
    mutationsperpixel     int    100      mutations per pixel (``spp`` of pbr.render
                                          overrides it, as pbrt-v4's --spp)
    largestepprobability  float  0.3      probability of a large step (all coordinates anew)
    sigma                 float  0.01     standard deviation of a small step's offsets
    regularize            bool   false    pbrt-v4's BSDF regularisation (only false)
    ====================  =====  =======  ====================================================
    """

    pass_separable = False    # Markov chains run on across passes

    needs_camera_importance = True  # connects paths to the camera (sample_Wi / its own camera rays)
    name = "mlt"
    bytes_per_lane = 112          # the float64 splat film and its development, per pixel (pbr.memory)
    supports_films = False        # develops its own channels (RGB films only)
    traces_light_paths = True
    light_sampler_type = "power"    # next-event estimation, as bdpt

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = pbrt_max_depth(props)
        self.maxdepth = self.max_depth - 1
        self.bootstrap_samples = props.int("bootstrapsamples", 100000, min=1)
        self.chains = props.int("chains", 1000, min=1)
        self.mutations_per_pixel = props.int("mutationsperpixel", 100, min=1)
        self.large_step_probability = props.float("largestepprobability", 0.3, min=0.0, max=1.0)
        self.sigma = props.float("sigma", 0.01, min=0.0)
        if self.sigma == 0.0:
            raise props.error("sigma", "must be > 0 (the small steps' standard deviation)")
        if props.bool("regularize", False):
            raise props.error("regularize", "BSDF regularisation is not supported (only false)")
        props.finish()
        self.dims = stream_dims(max(self.maxdepth, 0))
        # The path evaluation: BDPT's subpaths, with one strategy per lane.
        self.bdpt = BDPTIntegrator(Props({"type": "bdpt", "max_depth": max(self.max_depth, 1)}, props.path))
        self._recordings = {}

    def prepare(self, scene, sensor: int = 0) -> None:
        super().prepare(scene, sensor)
        self.bdpt.prepare(scene, sensor)
        self.dims = stream_dims(max(self.maxdepth, 0), scene.sensors[sensor].needs_aperture_sample)

    # -- the path of a primary sample -------------------------------------------------
    def contribution(self, scene, camera, samples, depth):
        """(XYZ, film position, c) of the path that each lane's primary sample gives
        (``samples``: dimension-major, ``dr.width(depth)`` lanes; ``depth``: bounces):
        one BDPT strategy's MIS-weighted estimate times the number of strategies of that
        depth; c is its luminance Y (0 where the estimate is not finite: such lanes are
        counted for ``on_nonfinite``)."""
        n = dr.width(depth)
        cam_dims, _ = self.dims
        cam_rng = PrimarySampleStream.at(samples, n, 0)
        light_rng = PrimarySampleStream.at(samples, n, cam_dims)
        n_strategies = dr.select(depth == 0, 1, depth + 2)
        s = dr.minimum(mi.UInt32(cam_rng.next_float32() * mi.Float(n_strategies)), n_strategies - 1)
        t = depth + 2 - s
        wl = SampledWavelengths.sample_visible(cam_rng.next_float32())
        pos = mi.Point2f(cam_rng.next_float32(), cam_rng.next_float32())
        ray = camera.sample_ray(pos, lens_sample(camera, cam_rng))
        strategies = Strategies(self.maxdepth, s, t)
        t1 = LaneSplats(n)
        store, n_light = self.bdpt.light_subpaths(scene, camera, light_rng, wl, strategies, t1.record)
        dr.eval(t1.xyz_buf, t1.pos_buf)
        L, _ = self.bdpt.camera_subpaths(scene, camera, cam_rng, ray, wl, mi.Bool(True), store, n_light,
                                         strategies)
        xyz = (spec.to_xyz(L, wl) + t1.xyz()) * mi.Float(n_strategies)
        pos = dr.select(t == 1, t1.pos(), pos)
        xyz, = self.counter().replace([xyz])        # non-finite estimates: counted, then 0
        xyz = dr.select(xyz.y > 0, xyz, 0.0)
        return xyz, pos, xyz.y

    # -- rendering -------------------------------------------------------------------------
    def start(self, scene, sensor, index, seed):
        """Fresh primary samples for sample numbers ``index`` (``uniform_samples``; depth
        ``index % (maxdepth + 1)``) and their paths: (samples, XYZ, film position, c)."""
        samples = uniform_samples(index, seed, sum(self.dims))
        xyz, pos, c = self.contribution(scene, scene.sensors[sensor], samples, index % (self.maxdepth + 1))
        dr.eval(xyz, pos, c)
        return samples, xyz, pos, c

    def bootstrap(self, scene, sensor, seed):
        """c of the bootstrap samples 0 .. bootstrapsamples (maxdepth + 1) - 1 (numpy)."""
        n_total = self.bootstrap_samples * (self.maxdepth + 1)
        c = np.empty(n_total)
        for first in range(0, n_total, BOOTSTRAP_BATCH):
            m = min(BOOTSTRAP_BATCH, n_total - first)
            start = self._recorded(self.start, scene, sensor, m)
            c[first:first + m] = np.asarray(start(scene, sensor, dr.arange(mi.UInt32, m) + first, seed)[3],
                                            dtype=np.float64)
        return c

    def normalization(self, c):
        """pbrt-v4's b: the sum over depths of the mean bootstrap c of each depth."""
        return float(c.sum()) / self.bootstrap_samples

    def acceptance(self, c_proposed, c_current):
        """Metropolis-Hastings acceptance probability of a symmetric proposal."""
        return dr.select(c_current > 0, dr.minimum(1.0, c_proposed / c_current), 1.0)

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        """The image (``mi.TensorXf`` (H, W, 3), linear sRGB); ``spp`` (if > 0) is the
        number of mutations per pixel."""
        self.prepare(scene, sensor)
        camera = scene.sensors[sensor]
        w, h = camera.film.size
        memory.check_render(w, h, 1, 4, f"sensor {sensor}", self.bytes_per_lane)
        film = SplatFilm(camera, self.counter())
        if self.max_depth == 0 or not len(scene.lights):
            return mi.TensorXf(np.zeros((h, w, 3), np.float32))
        seed = seed_array(seed)
        mpp = int(spp) if spp else self.mutations_per_pixel

        c_boot = self.bootstrap(scene, sensor, seed)
        b = self.normalization(c_boot)
        if not b > 0:
            if not int(self.counter().count[0]):     # else overflow, not darkness: pbr.render reports it
                warnings.warn(f"mlt: none of the {c_boot.size} bootstrap paths carries light: black image "
                              "(raise 'bootstrapsamples' if the scene is lit)")
            return mi.TensorXf(np.zeros((h, w, 3), np.float32))

        total = w * h * mpp
        n = min(self.chains, total)
        rng = IndependentSampler.make_rng(dr.arange(mi.UInt32, n) + c_boot.size, seed)
        # Start states: bootstrap samples picked in proportion to c (their own primary
        # samples, so their own paths: the chains start in their stationary distribution).
        cdf = np.cumsum(c_boot)
        u = np.asarray(rng.next_float32(), dtype=np.float64)
        start = np.minimum(np.searchsorted(cdf, u * cdf[-1], side="right"), c_boot.size - 1)
        # Chains of one depth side by side: a SIMD packet's lanes then run their subpath
        # loops for about as many vertices (the order of chains is otherwise arbitrary).
        index = mi.UInt32(start[np.argsort(start % (self.maxdepth + 1), kind="stable")])
        x, xyz, pos, c = self._recorded(self.start, scene, sensor, n)(scene, sensor, index, seed)
        chains = Chains(x, index % (self.maxdepth + 1), xyz, pos, c, rng)

        iterations = -(-total // n)
        step = self._recorded(self.step, scene, sensor, n)
        bar = _progress(iterations, progress)
        for it in range(iterations):
            # Chains j < total - it * n take part (an even split of the mutations).
            active = dr.opaque(mi.UInt32, min(n, total - it * n))
            chains, film.buf = step(scene, sensor, chains, film.buf, active)
            if bar:
                bar.update(1)
        if bar:
            bar.close()
        img = film.develop(b / mpp)
        return mi.TensorXf(img.astype(np.float32))

    def step(self, scene, sensor, chains, film_buf, n_active):
        """One Metropolis-Hastings iteration of every chain (the first ``n_active``
        splat into the film sums ``film_buf``): (chains after it, film sums)."""
        camera = scene.sensors[sensor]
        n = dr.width(chains.depth)
        dims = sum(self.dims)
        lane = dr.arange(mi.UInt32, n)
        active = lane < n_active
        x, rng = chains.x, chains.rng
        large = rng.next_float32() < self.large_step_probability
        y = _fill(dims, lambda i, rng: mutate(dr.gather(mi.Float, x, i * n + lane), rng.next_float32(), large,
                                              self.sigma), rng)
        u_accept = rng.next_float32()

        xyz_p, pos_p, c_p = self.contribution(scene, camera, y, chains.depth)
        xyz, pos, c = chains.xyz, chains.pos, chains.c
        a = self.acceptance(c_p, c)
        film = SplatFilm(camera, self.counter())
        film.buf = film_buf
        film.splat_xyz(pos_p, xyz_p * dr.select(c_p > 0, a / c_p, 0.0), active & (a > 0) & (c_p > 0))
        film.splat_xyz(pos, xyz * dr.select(c > 0, (1.0 - a) / c, 0.0), active & (a < 1) & (c > 0))
        accept = active & (u_accept < a)
        xyz = dr.select(accept, xyz_p, xyz)
        pos = dr.select(accept, pos_p, pos)
        c = dr.select(accept, c_p, c)
        dr.eval(accept, xyz, pos, c, rng, film.buf)
        slot = dr.arange(mi.UInt32, dims * n) % n          # the chain of each coordinate
        x = dr.select(dr.gather(mi.Bool, accept, slot), y, x)
        dr.eval(x)
        return Chains(x, chains.depth, xyz, pos, c, rng), film.buf

    def _recorded(self, fn, scene, sensor, lanes):
        """``fn`` (:meth:`start`, :meth:`step`) recorded by ``self.recorder`` (``pbr.freeze``)
        and replayed, for as long as what a recording bakes in stays the same: the lane
        count, the camera and film (Python numbers in the kernels), the mutation
        parameters. The scene's arrays are the recording's inputs; the entry keeps the
        scene alive, so that its id is not reused. With ``FREEZE`` false (or without a
        recorder), ``fn`` itself, traced at every call."""
        if not FREEZE or self.recorder is None:
            return fn
        cam = scene.sensors[sensor]
        key = (id(scene), sensor, lanes, cam.to_world.tobytes(), cam.x_fov, cam.near_clip, cam.far_clip, cam.pp,
               cam.needs_aperture_sample, cam.aperture_radius, cam.focus_distance,
               tuple(cam.film.size), id(cam.film.rfilter), self.sigma, self.large_step_probability)
        entry = self._recordings.get((fn.__name__, lanes))
        if entry is None or entry[0] != key:
            entry = self._recordings[(fn.__name__, lanes)] = (key, self.recorder(fn, auto_opaque=False), scene)
        return entry[1]

