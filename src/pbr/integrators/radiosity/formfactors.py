"""Form factors by ray casting through pbr's geometry bridge (Mitsuba's ray tracer).

The form factor F_ij of receiver i toward source j is the fraction of the light leaving
i (uniformly over its area, cosine-distributed in direction) that reaches j's front:

    F_ij = 1/A_i  int_{A_i} int_{A_j} cos(theta_i) cos(theta_j) / (pi r^2) V dA_j dA_i,

so the radiance i gathers is  H_i = sum_j F_ij L_j  (irradiance / pi) and rows sum to at
most 1 (the rest reaches back faces or leaves the scene). Two estimators:

* **point to patch** (:func:`pair_estimates`, the dense matrix and progressive
  refinement's columns): a point x on i (stratified over i), then a direction toward j
  sampled uniformly in the solid angle j subtends from x (Arvo's spherical triangles),
  weighted ``Omega max(0, cos theta_x) / pi`` and by a shadow ray to the point it aims
  at. The estimate is bounded by Omega / pi, also for patches that share an edge, where
  sampling points on j by area has infinite variance. Where j subtends less than
  :data:`SPHERICAL_MIN` sr, float32 loses Arvo's precision and a point on j is sampled by
  area instead (there r is large, so that estimate is well behaved). Each pair's random
  numbers depend only on (receiver, source, seed), so a column recomputed on the fly
  equals the matrix's.
* **cosine rays** (:func:`shoot`, stochastic Jacobi and the energy audit): rays from
  uniform points of a patch in cosine-distributed directions, each landing on the front
  of a patch, on a back face, or nowhere.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ...samplers import IndependentSampler
from ...sampling import square_to_cosine_hemisphere

SPHERICAL_MIN = 0.02            # sr
MAX_LANES = 1 << 22             # lanes per kernel launch
FRONT_EPS = 1e-6                # facing test tolerance, relative to the scene's extent


# ------------------------------------------------------------------ spherical triangles

def solid_angle(a, b, c):
    """Solid angle of the spherical triangle of unit vectors a, b, c (Van Oosterom and
    Strackee's formula, accurate for small triangles)."""
    num = dr.abs(dr.dot(a, dr.cross(b, c)))
    den = 1.0 + dr.dot(a, b) + dr.dot(b, c) + dr.dot(c, a)
    return 2.0 * dr.atan2(num, den)


def sample_spherical_triangle(a, b, c, u: mi.Point2f):
    """Arvo's uniform sampling of the spherical triangle (a, b, c) (unit vectors):
    (direction, the triangle's area = 1 / pdf as the sampler computes it)."""
    n_ab = dr.normalize(dr.cross(a, b))
    n_bc = dr.normalize(dr.cross(b, c))
    n_ca = dr.normalize(dr.cross(c, a))
    alpha = dr.acos(dr.clip(-dr.dot(n_ab, n_ca), -1.0, 1.0))
    beta = dr.acos(dr.clip(-dr.dot(n_bc, n_ab), -1.0, 1.0))
    gamma = dr.acos(dr.clip(-dr.dot(n_ca, n_bc), -1.0, 1.0))
    area = dr.maximum(alpha + beta + gamma - dr.pi, 0.0)
    # The sub-triangle of area u0 * area: its third vertex c' on the arc a-c.
    s, t = dr.sincos(u.x * area - alpha)
    sa, ca = dr.sincos(alpha)
    uu = t - ca
    vv = s + sa * dr.dot(a, b)
    q = dr.clip(((vv * t - uu * s) * ca - vv) / ((vv * s + uu * t) * sa), -1.0, 1.0)
    c_perp = c - dr.dot(c, a) * a
    c_perp = dr.select(dr.squared_norm(c_perp) > 0, dr.normalize(c_perp), 0.0)
    c2 = q * a + dr.safe_sqrt(1.0 - q * q) * c_perp
    # A point on the arc b-c' with the right density.
    z = 1.0 - u.y * (1.0 - dr.dot(c2, b))
    w_perp = c2 - dr.dot(c2, b) * b
    w_perp = dr.select(dr.squared_norm(w_perp) > 0, dr.normalize(w_perp), 0.0)
    w = z * b + dr.safe_sqrt(1.0 - z * z) * w_perp
    return dr.normalize(w), area


# ------------------------------------------------------------------------- helpers

def _surface(p, n):
    """A bare surface interaction at p with geometric normal n (to spawn rays)."""
    si = dr.zeros(mi.SurfaceInteraction3f, dr.width(p))
    si.p, si.n = p, n
    return si


def _uniform_point(P, u):
    b = mi.warp.square_to_uniform_triangle(u)
    return dr.fma(P[1] - P[0], b.x, dr.fma(P[2] - P[0], b.y, P[0]))


def facing(patches, recv: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Pairs that can exchange light: part of each lies strictly in front of the other."""
    eps = FRONT_EPS * patches.extent
    P, n = patches.p, patches.normal
    a = np.einsum("pkj,pj->pk", P[src] - P[recv, 0][:, None], n[recv]).max(axis=1)
    b = np.einsum("pkj,pj->pk", P[recv] - P[src, 0][:, None], n[src]).max(axis=1)
    return (a > eps) & (b > eps) & (recv != src)


# ------------------------------------------------------------------- point to patch

@dr.syntax
def pair_estimates(patches, geo, recv: mi.UInt32, src: mi.UInt32, samples: int, seed) -> mi.Float:
    """Mean of ``samples`` point-to-patch estimates of F[recv, src], one lane per pair
    (a symbolic loop over the samples; ``seed`` an opaque UInt32)."""
    rng = IndependentSampler.make_rng(recv * patches.count + src, seed)
    Pr = [dr.gather(mi.Point3f, t, recv) for t in patches.dr_p]
    Ps = [dr.gather(mi.Point3f, t, src) for t in patches.dr_p]
    nr = dr.gather(mi.Normal3f, patches.dr_normal, recv)
    ns = dr.gather(mi.Normal3f, patches.dr_normal, src)
    A_s = dr.gather(mi.Float, patches.dr_area, src)
    # Points on the receiver are stratified (jittered m x m grid, the remaining samples
    # uniform): the integrand varies most with the receiving point, near shared edges.
    m = int(np.sqrt(samples))
    total = mi.Float(0.0)
    k = mi.UInt32(0)
    while k < samples:
        cell = mi.Point2f(mi.Float(k % m), mi.Float(k // m))
        u = mi.Point2f(rng.next_float32(), rng.next_float32())
        u = dr.select(k < m * m, (cell + u) * (1.0 / m), u)
        x = _uniform_point(Pr, u)
        u = mi.Point2f(rng.next_float32(), rng.next_float32())
        a, b, c = (dr.normalize(q - x) for q in Ps)
        spherical = solid_angle(a, b, c) > SPHERICAL_MIN
        # Solid-angle sampling: a direction, and the point of j's plane it aims at.
        w_s, area_s = sample_spherical_triangle(a, b, c, u)
        y_s = dr.fma(w_s, dr.dot(Ps[0] - x, ns) / dr.dot(w_s, ns), x)
        est_s = area_s * dr.maximum(dr.dot(nr, w_s), 0.0) * dr.inv_pi
        # Area sampling.
        y_a = _uniform_point(Ps, u)
        d = y_a - x
        r2 = dr.squared_norm(d)
        w_a = d * dr.rsqrt(r2)
        est_a = A_s * dr.maximum(dr.dot(nr, w_a), 0.0) * dr.maximum(-dr.dot(ns, w_a), 0.0) * dr.inv_pi / r2
        w = dr.select(spherical, w_s, w_a)
        y = dr.select(spherical, y_s, y_a)
        est = dr.select(spherical, est_s, est_a)
        ok = (est > 0) & (dr.dot(w, ns) < 0) & dr.isfinite(est)
        ok &= geo.unoccluded(_surface(x, nr), y, ok)
        total += dr.select(ok, est, 0.0)
        k += 1
    return total * (1.0 / samples)


def form_factor_matrix(patches, geo, samples: int, seed: int = 0, progress=None) -> np.ndarray:
    """Dense (N, N) float32 matrix F[receiver, source]; ``progress(fraction)`` is called
    as blocks of receivers are queued."""
    N = patches.count
    F = np.zeros((N, N), np.float32)
    rows_per_block = max(1, min(N, (1 << 20) // max(N, 1)))     # bounds the facing test's memory
    pending_r, pending_s = [], []

    def flush():
        if not pending_r:
            return
        r = np.concatenate(pending_r)
        s = np.concatenate(pending_s)
        pending_r.clear()
        pending_s.clear()
        step = MAX_LANES
        for o in range(0, len(r), step):
            rr, ss = r[o:o + step], s[o:o + step]
            v = pair_estimates(patches, geo, mi.UInt32(rr.astype(np.uint32)), mi.UInt32(ss.astype(np.uint32)),
                               samples, dr.opaque(mi.UInt32, seed & 0xFFFFFFFF))
            F[rr, ss] = np.array(v, dtype=np.float32)

    queued = 0
    for r0 in range(0, N, rows_per_block):
        rr, ss = np.divmod(np.arange(r0 * N, min(N, r0 + rows_per_block) * N, dtype=np.int64), N)
        keep = facing(patches, rr, ss)
        pending_r.append(rr[keep])
        pending_s.append(ss[keep])
        queued += int(keep.sum())
        if queued >= MAX_LANES:
            flush()
            queued = 0
        if progress:
            progress(min(N, r0 + rows_per_block) / N)
    flush()
    return F


def form_factor_column(patches, geo, src: int, samples: int, seed: int = 0) -> np.ndarray:
    """F[:, src] (float64, N), computed on the fly with the matrix's random numbers."""
    N = patches.count
    recv = np.arange(N, dtype=np.int64)
    recv = recv[facing(patches, recv, np.full(N, src, np.int64))]
    col = np.zeros(N)
    if len(recv):
        v = pair_estimates(patches, geo, mi.UInt32(recv.astype(np.uint32)),
                           dr.full(mi.UInt32, 0, len(recv)) + dr.opaque(mi.UInt32, src),
                           samples, dr.opaque(mi.UInt32, seed & 0xFFFFFFFF))
        col[recv] = np.array(v, dtype=np.float64)
    return col


# -------------------------------------------------------------------- cosine rays

def shoot(patches, geo, src: np.ndarray, seed: int) -> np.ndarray:
    """Cast one cosine-distributed ray from a uniform point of each patch in ``src``.
    Returns where each landed: a patch index (its front), ``N`` (a back face) or
    ``N + 1`` (nothing)."""
    N = patches.count
    out = np.empty(len(src), np.int64)
    for o in range(0, len(src), MAX_LANES):
        s = mi.UInt32(src[o:o + MAX_LANES].astype(np.uint32))
        idx = dr.arange(mi.UInt32, dr.width(s)) + dr.opaque(mi.UInt32, o)
        rng = IndependentSampler.make_rng(idx, dr.opaque(mi.UInt32, seed & 0xFFFFFFFF))
        P = [dr.gather(mi.Point3f, t, s) for t in patches.dr_p]
        n = dr.gather(mi.Normal3f, patches.dr_normal, s)
        x = _uniform_point(P, mi.Point2f(rng.next_float32(), rng.next_float32()))
        d = mi.Frame3f(n).to_world(square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32())))
        si, shape = geo.intersect(_surface(x, n).spawn_ray(d), True)
        hit = si.is_valid()
        patch, _ = patches.patch_of_hit(shape, si.prim_index, si.p, hit)
        front = hit & (dr.dot(d, dr.gather(mi.Normal3f, patches.dr_normal, patch, hit)) < 0)
        dst = dr.select(front, patch, dr.select(hit, N, N + 1))
        out[o:o + MAX_LANES] = np.array(dst, dtype=np.int64)
    return out


def tally(src: np.ndarray, dst: np.ndarray, N: int):
    """Distinct (source, destination) pairs of :func:`shoot`'s rays and their counts."""
    keys, counts = np.unique(np.asarray(src, np.int64) * (N + 2) + dst, return_counts=True)
    return keys // (N + 2), keys % (N + 2), counts


def deposit(src: np.ndarray, dst: np.ndarray, counts: np.ndarray, carry: np.ndarray, size: int) -> np.ndarray:
    """(size, K) sums over pairs of ``counts * carry[src]`` into rows ``dst`` (< size)."""
    keep = dst < size
    s, d, w = src[keep], dst[keep], counts[keep].astype(np.float64)
    return np.stack([np.bincount(d, weights=w * carry[s, k], minlength=size) for k in range(carry.shape[1])],
                    axis=1)
