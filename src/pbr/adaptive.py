"""Adaptive sampling: per-pixel sample counts chosen for a target relative error.

``pbr.render(scene, target_relative_error=e, time_budget=s, return_info=True)`` renders
in two phases:

1. a *pilot* of ``pilot_spp`` samples in every pixel estimates each pixel's per-sample
   relative variance ``v`` (of its luminance Y, from the film sums of w^2 Y^2, w^2 Y, w^2
   made in the rendering kernel);
2. the *image*: fresh samples (other sample indices), ``ceil(v / e^2)`` in each pixel
   (the count at which the standard error of its mean is ``e`` times its value), at least
   ``min_spp`` and at most ``spp``, in passes over the pixels that still need samples,
   until every pixel has its count or ``time_budget`` seconds are spent.

The image is made of the image-phase samples only. Their number in a pixel depends on
the pilot's samples (and on the clock), never on their own values, so each pixel's mean
is unbiased: no early-stop bias (a pixel that stops when its own samples look converged
is biased low where rare bright paths, caustics or fireflies, were not yet found). The
pilot's samples are spent on the decision alone. A pixel's count is computed from the
largest pilot variance in its 3x3 neighbourhood (still the pilot only), so that a pixel
whose pilot missed a caustic its neighbours found is not left at ``min_spp``.

Filters do not spread samples: pbr's film is filter importance sampling (pbr.filters),
each camera sample counts in its own pixel only, with weight f/pdf; so a pixel's count
changes nothing in its neighbours.

The result (:class:`AdaptiveInfo`) reports each pixel's estimated relative standard
error of the image (from the image's own samples), its sample count, and the time.
"""

from __future__ import annotations

import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from . import memory
from .integrators.base import _develop, _progress, max_samples_per_pass

#: Relative errors are of Y / max(Y, FLOOR * mean Y): pixels darker than 1% of the
#: image's mean are held to an absolute error (else black pixels would need infinite spp).
FLOOR = 1e-2
_STATS = 3          # the moment channels _pass_sums appends: w^2 Y^2, w^2 Y, w^2


class AdaptiveInfo:
    """What an adaptive render did and its estimate. Arrays are (H, W) numpy.

    ``spp``: image samples per pixel; ``relative_error``: each pixel's estimated
    relative standard error (of its luminance; see ``FLOOR``) from the image's samples;
    ``needed_spp``: the count the pilot asked for (before ``spp``'s cap and the time
    budget); ``pilot_spp``, ``target``, ``time_budget``, ``seconds`` (wall time of the
    render, pilot included), ``passes``, ``samples`` (camera samples, pilot included)."""

    def __init__(self, **kw):
        self.__dict__.update(kw)

    @property
    def above_target(self) -> float:
        """Fraction of pixels whose estimated relative error is above the target."""
        if self.target is None:
            return float("nan")
        return float(np.mean(self.relative_error > self.target))

    @property
    def mean_spp(self) -> float:
        """Mean samples per pixel, the pilot's included (what a uniform render is compared at)."""
        return self.samples / self.spp.size

    def summary(self) -> str:
        e = self.relative_error
        tgt = "none" if self.target is None else f"{self.target:g}"
        return (f"adaptive render: target relative error {tgt}, {self.seconds:.2f} s, {self.passes} passes, "
                f"mean {self.mean_spp:.1f} spp (pilot {self.pilot_spp}; image spp {int(self.spp.min())}.."
                f"{int(self.spp.max())}); estimated relative error median {np.median(e):.4f}, "
                f"95th percentile {np.percentile(e, 95):.4f}, max {e.max():.4f}"
                + ("" if self.target is None else f"; {100 * self.above_target:.1f}% of pixels above the target"))

    def __repr__(self):
        return f"<AdaptiveInfo {self.summary()}>"


def _count(name, v, lo):
    if isinstance(v, bool) or not isinstance(v, int) or v < lo:
        raise ValueError(f"render: {name} must be an integer >= {lo}, got {v!r}")
    return v


class Adaptive:
    """An adaptive render's settings (see the module); :meth:`film` is the integrator's
    film for it (``SamplingIntegrator._film`` hands over while ``integrator.adaptive``
    is set: :func:`adaptive_render`)."""

    def __init__(self, target_relative_error=None, time_budget=None, pilot_spp=16, min_spp=4):
        if target_relative_error is not None and not (isinstance(target_relative_error, (int, float))
                                                      and 0 < target_relative_error < math.inf):
            raise ValueError(f"render: target_relative_error must be a positive number (e.g. 0.05 for 5%), got "
                             f"{target_relative_error!r}")
        if time_budget is not None and not (isinstance(time_budget, (int, float)) and 0 < time_budget):
            raise ValueError(f"render: time_budget must be a positive number of seconds, got {time_budget!r}")
        self.target = None if target_relative_error is None else float(target_relative_error)
        self.time_budget = None if time_budget is None else float(time_budget)
        self.pilot_spp = _count("pilot_spp", pilot_spp, 2) if self.target is not None else 0
        self.min_spp = _count("min_spp", min_spp, 1)
        self.info = None

    # -- statistics ----------------------------------------------------------------------
    @staticmethod
    def _luminance_stats(acc):
        """(Y, variance of Y's mean, effective sample count) per pixel from film sums
        (w X, w Y, w Z, w, ..., w^2 Y^2, w^2 Y, w^2): the ratio estimator Y = sum wY /
        sum w and its linearised variance sum w^2 (Y_i - Y)^2 / (sum w)^2, scaled by
        n / (n - 1) with Kish's effective count n = (sum w)^2 / sum w^2."""
        sw = acc[:, 3]
        s2, s1, sw2 = acc[:, -3], acc[:, -2], acc[:, -1]
        ok = sw > 0
        sw_safe = np.where(ok, sw, 1.0)
        y = np.where(ok, acc[:, 1] / sw_safe, 0.0)
        var = np.maximum(s2 - 2 * y * s1 + y * y * sw2, 0.0) / (sw_safe * sw_safe)
        n = np.where(sw2 > 0, sw * sw / np.where(sw2 > 0, sw2, 1.0), 0.0)
        var = np.where(n > 1, var * n / np.maximum(n - 1, 1e-9), np.where(ok, np.inf, 0.0))
        return y, var, n

    @staticmethod
    def _denominator(y):
        m = float(np.mean(y))
        return np.maximum(y, FLOOR * m if m > 0 else 1e-30)

    # -- the film ------------------------------------------------------------------------
    def film(self, integ, scene, sensor, seed, spp, radiance, progress=None):
        """The image (as ``_film`` develops it) from per-pixel sample counts; sets ``info``."""
        if integ.job is not None:
            raise NotImplementedError(f"{integ.path}: an adaptive render cannot be split into passes "
                                      f"(pbr.distributed)")
        if dr.flag(dr.JitFlag.FreezingScope):
            raise NotImplementedError("render: adaptive sampling (target_relative_error, time_budget, return_info) "
                                      "reads the film after each pass, which pbr.freeze cannot record")
        t0 = time.perf_counter()
        cam = scene.sensors[sensor]
        w, h = cam.film.size
        npx = w * h
        cap = int(spp) if spp else cam.sampler.sample_count
        n0 = self.pilot_spp
        stride = n0 + cap               # sample indices of a pixel: pilot [0, n0), image [n0, n0 + cap)
        budget = max_samples_per_pass()
        passes, samples = 0, 0
        bar = _progress(2, progress, desc="pbr adaptive render")

        def run(pixels, k, offset):
            """Film sums (float64, one row per pixel of ``pixels``) of ``k`` samples each from
            sample index ``offset`` (a multiple of k)."""
            nonlocal passes, samples
            n = npx if pixels is None else len(pixels)
            memory.check_render(n, 1, k, 4, f"sensor {sensor}")
            with dr.suspend_grad():
                px = None if pixels is None else mi.UInt32(pixels.astype(np.uint32))
                s = integ._pass_sums(scene, cam, w, h, stride, k, offset // k, seed, radiance, pixels=px, moments=True)
                out = np.asarray(s, dtype=np.float64)
            passes += 1
            samples += n * k
            return out.reshape(n, -1)

        # 1. The pilot: every pixel, n0 samples, in passes of at most `budget` samples.
        need = np.full(npx, cap, dtype=np.int64)
        if n0:
            acc0 = None
            k = _pow2_floor(max(1, min(n0, budget // npx)))
            while n0 % k:
                k //= 2
            for o in range(0, n0, k):
                s = run(None, k, o)
                acc0 = s if acc0 is None else acc0 + s
            y, var, n = self._luminance_stats(acc0)
            v = var * np.maximum(n, 1) / self._denominator(y) ** 2       # per-sample relative variance
            v = _dilate(v.reshape(h, w)).ravel()
            with np.errstate(over="ignore", invalid="ignore"):
                need = np.ceil(np.minimum(v / self.target ** 2, 2.0 ** 62))
            need = np.nan_to_num(need, nan=cap, posinf=cap)
            need = np.clip(need, self.min_spp, cap).astype(np.int64)
        if bar:
            bar.update(1)

        # 2. The image: fresh samples while a pixel has fewer than it needs (all pixels
        # that still need samples have had the same number so far: they share offsets).
        acc, done, offset = None, np.zeros(npx, dtype=np.int64), n0
        needed = need.copy()
        while True:
            active = np.flatnonzero(done < need)
            if active.size == 0:
                break
            if (self.time_budget is not None and acc is not None
                    and time.perf_counter() - t0 >= self.time_budget):
                break
            # k samples each (a power of two): what the least needy active pixel still
            # lacks, or more, up to what they have had (no pixel gets over twice its count)
            # and to what half of them lack (the others' surplus is bounded by k).
            have = int(done[active[0]])
            left = need[active] - have
            k = max(int(left.min()), min(have, int(np.median(left))))
            k = _pow2_floor(max(1, min(k, budget // active.size, cap - have)))
            if offset:
                k = min(k, offset & -offset)       # the pass index is offset / k
            pixels = None if active.size == npx else active
            s = run(pixels, k, offset)
            if acc is None:
                acc = np.zeros((npx, s.shape[1]))
            acc[active] += s
            done[active] += k
            offset += k
        if bar:
            bar.update(1)
            bar.close()
        y, var, _ = self._luminance_stats(acc)
        rel = np.sqrt(var) / self._denominator(y)
        self.info = AdaptiveInfo(target=self.target, time_budget=self.time_budget, pilot_spp=n0,
                                 spp=done.reshape(h, w), needed_spp=needed.reshape(h, w),
                                 relative_error=rel.reshape(h, w), seconds=time.perf_counter() - t0,
                                 passes=passes, samples=samples)
        film = mi.Float(acc[:, :-_STATS].astype(np.float32).ravel())
        return _develop(film, w, h)


def _pow2_floor(n: int) -> int:
    return 1 << (max(int(n), 1).bit_length() - 1)


def _dilate(a):
    """Each pixel's largest value over its 3x3 neighbourhood."""
    p = np.pad(a, 1, mode="edge")
    h, w = a.shape
    return np.max([p[i:i + h, j:j + w] for i in range(3) for j in range(3)], axis=0)


def adaptive_render(integrator, plan: Adaptive):
    """Within the block, ``integrator``'s film is ``plan``'s."""
    return integrator.passes_planned_by("adaptive", plan, "it cannot sample adaptively")
