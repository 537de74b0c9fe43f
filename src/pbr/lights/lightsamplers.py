"""Light samplers: choose one light for next-event estimation.

``uniform`` picks each light with equal probability (Mitsuba's behaviour); ``power``
picks lights in proportion to their emitted power (pbrt-v4's ``power``), so a light of
zero power is never chosen; ``bvh`` (pbrt-v4's default, see :mod:`pbr.lights.bvh`) picks
lights by their importance for the shading point through a light BVH. Each has
``sample(u, ref_p, ref_n, active) -> (light, probability)`` and ``pmf(light, ref_p,
ref_n, active)``, the probability that ``sample`` returns ``light``; the integrator
needs it to weight emitter hits by MIS.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..plugins.props import SceneError
from .bvh import BVHLightSampler, BoundsTable, ensure_table

LIGHT_SAMPLERS = ("uniform", "power", "bvh")


class LightSampler:
    def __init__(self, kind: str, powers: np.ndarray):
        self.kind = kind
        n = len(powers)
        p = np.maximum(np.asarray(powers, dtype=np.float64), 0.0)
        self.uniform = kind == "uniform" or n == 0 or not p.sum() > 0
        self.n = n
        if self.uniform:
            self.pmf_np = np.full(n, 1.0 / max(n, 1))
            return
        cdf = np.cumsum(p / p.sum())
        cdf32 = (cdf / cdf[-1]).astype(np.float32)
        cdf32[-1] = 1.0
        # The probability of a light is the width of its interval of the float32 CDF, so
        # that sample() and pmf() agree exactly (a light too faint to own an interval has
        # probability 0 and is left to BSDF sampling).
        self.pmf_np = np.diff(np.concatenate([[0.0], cdf32.astype(np.float64)]))
        self._pmf = mi.Float(self.pmf_np.astype(np.float32))
        self._cdf = mi.Float(cdf32)

    def sample(self, u: mi.Float, ref_p=None, ref_n=None, active=True):
        """(light index, probability). ``ref_p``/``ref_n`` (the shading point) are unused
        by these samplers; the BVH sampler's probabilities depend on them."""
        if self.n == 1:
            return mi.UInt32(0), mi.Float(1.0)
        if self.uniform:
            u = mi.Float(u)
            return dr.minimum(mi.UInt32(u * self.n), self.n - 1), dr.full(mi.Float, 1.0 / max(self.n, 1), dr.width(u))
        idx = dr.binary_search(0, self.n - 1, lambda i: dr.gather(mi.Float, self._cdf, i, active) <= u)
        idx = dr.minimum(idx, self.n - 1)
        return idx, dr.gather(mi.Float, self._pmf, idx, active)

    def pmf(self, idx, ref_p=None, ref_n=None, active=True):
        if self.n == 1:
            return mi.Float(1.0)
        if self.uniform:
            return dr.full(mi.Float, 1.0 / max(self.n, 1), dr.width(idx))
        return dr.gather(mi.Float, self._pmf, idx, active)


def make_light_sampler(kind: str, powers, bounds=None):
    """The light sampler named by an integrator's ``light_sampler`` parameter.

    ``powers``: emitted power per light (``power``); ``bounds``: per light a pbrt-v4
    LightBounds dict or None (infinite lights), or a :class:`pbr.lights.bvh.BoundsTable`
    (``bvh``)."""
    if kind not in LIGHT_SAMPLERS:
        raise ValueError(f"unknown light sampler {kind!r} (choose from {', '.join(LIGHT_SAMPLERS)})")
    powers = np.asarray(powers, dtype=np.float64).reshape(-1)
    if kind != "bvh" or len(powers) == 1:
        # One light: the BVH would choose it wherever its importance bound is positive,
        # and elsewhere its contribution is 0 anyway; choosing it always is the same
        # estimator without the per-vertex importance (Mitsuba's choice: 5-10% of the
        # render time of one-light scenes, measured by benchmarks/profile_kernels.py).
        return LightSampler("uniform" if kind == "bvh" else kind, powers)
    table = ensure_table(bounds, len(powers))
    # Scenes are rebuilt on every params.update(): reuse the tree while the bounds stay.
    # The key is the bounds' bytes themselves (exact; hashlib would load OpenSSL, 3.5 MiB).
    key = (mi.variant(),) + tuple(np.ascontiguousarray(a).tobytes() for a in (
        table.finite, table.p_min, table.p_max, table.phi, table.w, table.cos_o, table.cos_e, table.two_sided))
    if key not in _BVH_CACHE:
        if len(_BVH_CACHE) >= 4:
            _BVH_CACHE.pop(next(iter(_BVH_CACHE)))
        _BVH_CACHE[key] = BVHLightSampler(table)
    return _BVH_CACHE[key]


_BVH_CACHE: dict = {}


class LightTable:
    """Emitters expanded into the lights the samplers see: emitter ``g`` (an entry of
    :class:`pbr.lights.LightSet`) is lights ``first[g] .. first[g] + counts[g] - 1``
    (several for an area emitter on a triangle mesh: one per triangle). ``local[k]`` is
    light ``k``'s index within its family; ``powers`` and ``bounds`` are per light."""

    def __init__(self, entries, families, scene):
        counts, local, powers, items = [], [], [], []
        for t, i in entries:
            fam = families[t]
            c = int(fam.count(i)) if hasattr(fam, "count") else 1
            f0 = int(fam.first(i)) if hasattr(fam, "first") else i
            counts.append(c)
            local.append(np.arange(f0, f0 + c))
            powers.append(np.broadcast_to(np.asarray(fam.power(i, scene), dtype=np.float64).reshape(-1), (c,)))
            items.append(fam.bounds(i, scene))
        self.counts = np.array(counts, dtype=np.int64)
        self.first = np.concatenate([[0], np.cumsum(self.counts)[:-1]]).astype(np.int64)
        self.n = int(self.counts.sum())
        self.local = np.concatenate(local) if local else np.zeros(0, np.int64)
        self.powers = np.concatenate(powers) if powers else np.zeros(0)
        if self.n and not np.all(np.isfinite(self.powers)):
            raise SceneError("scene: a light has a non-finite power")
        try:
            self.bounds = BoundsTable.from_items(items, counts)
        except ValueError as e:
            raise SceneError(f"scene: {e}") from None
