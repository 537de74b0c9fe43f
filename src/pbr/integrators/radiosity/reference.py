"""An independent reference for a radiosity solution: pbr's ``path`` integrator at the
patch centroids.

For each patch a probe ray starts a small distance in front of its centroid and looks
straight at it; ``PathIntegrator.sample`` returns the radiance leaving the centroid
toward the probe (for a Lambertian surface, in every direction), estimated with full
global illumination (``max_depth`` -1: unlimited, Russian roulette). The wavelengths are
the bin centres themselves, four per path, so the estimates compare bin by bin with the
solution with no colour conversion in between. A probe whose ray lands on another patch
(a centroid covered by touching geometry) is reported invalid.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ...samplers import IndependentSampler, IndependentStream
from ...plugins.props import Props
from ...spectrum import SampledWavelengths
from ..base import PRIMAL
from ..path import PathIntegrator
from .formfactors import MAX_LANES


def path_at_centroids(scene, patches, bins, spp: int, seed: int = 0, max_depth: int = -1, subset=None,
                      offset: float = 1e-3):
    """(mean (M, K), standard error (M, K), valid (M,)) of the path-traced radiance at
    the centroids of the patches ``subset`` (default: all). ``offset`` is the probe's
    distance from the surface, relative to the scene's extent."""
    path = PathIntegrator(Props({"type": "path", "max_depth": max_depth}, "radiosity.reference"))
    path.prepare(scene)
    sub = np.arange(patches.count) if subset is None else np.asarray(subset, np.int64)
    groups = bins.groups()
    G, M = len(groups), len(sub)
    lam_tab = [mi.Float([g[k] for g in groups]) for k in range(4)]
    mean = np.zeros((M, 4 * G))
    m2 = np.zeros((M, 4 * G))
    valid = np.ones(M, bool)
    per_chunk = max(1, MAX_LANES // (spp * G))
    delta = offset * patches.extent
    for c0 in range(0, M, per_chunk):
        ids = sub[c0:c0 + per_chunk]
        m = len(ids)
        idx = dr.arange(mi.UInt32, m * G * spp)
        row = idx // spp                       # (patch, group) pairs, group-minor
        local, group = row // G, row % G
        patch = dr.gather(mi.UInt32, mi.UInt32(ids.astype(np.uint32)), local)
        c = np.float32
        cen = mi.Point3f(*[mi.Float(patches.centroid[ids, k].astype(c)) for k in range(3)])
        nrm = mi.Vector3f(*[mi.Float(patches.normal[ids, k].astype(c)) for k in range(3)])
        n = dr.gather(mi.Vector3f, nrm, local)
        o = dr.fma(n, delta, dr.gather(mi.Point3f, cen, local))
        ray = mi.Ray3f(o, -n)
        wl = SampledWavelengths(mi.Spectrum([dr.gather(mi.Float, t, group) for t in lam_tab]), mi.Spectrum(1.0))
        rng = IndependentStream(rng=IndependentSampler.make_rng(idx + dr.opaque(mi.UInt32, c0 * G * spp),
                                                                 dr.opaque(mi.UInt32, seed)))
        si, shape = scene.geometry.intersect(ray, True)
        hit_patch, _ = patches.patch_of_hit(shape, si.prim_index, si.p, si.is_valid())
        ok = si.is_valid() & (hit_patch == patch)
        L, _ = path.sample(scene, rng, ray, wl, PRIMAL, None, None, mi.Bool(True))
        L = dr.select(ok, L, 0.0)
        dr.eval(L, ok)
        s1 = np.stack([np.array(dr.block_sum(L[k], spp)) for k in range(4)], axis=-1) / spp   # (m G, 4)
        s2 = np.stack([np.array(dr.block_sum(L[k] * L[k], spp)) for k in range(4)], axis=-1) / spp
        okp = np.array(dr.block_sum(mi.Float(ok), spp)).reshape(m, G)[:, 0] == spp
        mean[c0:c0 + m] = s1.reshape(m, 4 * G)
        m2[c0:c0 + m] = s2.reshape(m, 4 * G)
        valid[c0:c0 + m] = okp
    K = bins.count
    var = np.maximum(m2 - mean * mean, 0.0) / max(spp - 1, 1)
    return mean[:, :K], np.sqrt(var[:, :K]), valid
