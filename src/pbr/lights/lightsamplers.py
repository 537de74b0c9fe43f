"""Light samplers: choose one light for next-event estimation.

``uniform`` picks each light with equal probability (Mitsuba's behaviour); ``power``
picks lights in proportion to their emitted power (pbrt-v4's ``power``), so a light of
zero power is never chosen. ``pmf(light)`` returns the probability that ``sample``
returns ``light``; the integrator needs it to weight emitter hits by MIS.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

LIGHT_SAMPLERS = ("uniform", "power")


class LightSampler:
    def __init__(self, kind: str, powers: np.ndarray):
        self.kind = kind
        n = len(powers)
        if kind == "uniform" or n == 0:
            pmf = np.full(n, 1.0 / max(n, 1))
        else:
            p = np.maximum(np.asarray(powers, dtype=np.float64), 0.0)
            pmf = p / p.sum() if p.sum() > 0 else np.full(n, 1.0 / n)
        self.pmf_np = pmf
        self.n = n
        cdf = np.cumsum(pmf)
        cdf /= cdf[-1] if n else 1.0
        self._pmf = mi.Float(pmf.astype(np.float32))
        self._cdf = mi.Float(cdf.astype(np.float32))

    def sample(self, u: mi.Float, ref_p=None, ref_n=None, active=True):
        """(light index, probability). ``ref_p``/``ref_n`` (the shading point) are unused
        by these samplers; the BVH sampler's probabilities depend on them."""
        if self.n == 1:
            return mi.UInt32(0), mi.Float(1.0)
        idx = dr.binary_search(0, self.n - 1, lambda i: dr.gather(mi.Float, self._cdf, i, active) <= u)
        idx = dr.minimum(idx, self.n - 1)
        return idx, dr.gather(mi.Float, self._pmf, idx, active)

    def pmf(self, idx, ref_p=None, ref_n=None, active=True):
        if self.n == 1:
            return mi.Float(1.0)
        return dr.gather(mi.Float, self._pmf, idx, active)


def make_light_sampler(kind: str, powers, bounds):
    """The light sampler named by an integrator's ``light_sampler`` parameter."""
    return LightSampler(kind, powers)
