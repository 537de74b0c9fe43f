"""The light BVH of pbrt-v4 (``BVHLightSampler``): many-light sampling by importance,
over pbrt-v4's ``LightBounds`` of every finite light. The bounds, the importance and
the tree: docs/lights.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import dispatch

N_BUCKETS = 12
# Trees at most this deep are descended by straight-line code (BVHLightSampler._loop).
UNROLL_DEPTH = 4
MAX_DEPTH = 32
LEAF_BIT = np.uint32(1 << 31)
INDEX_MASK = (1 << 30) - 1
ONE_MINUS_EPS = float(np.nextafter(np.float32(1.0), np.float32(0.0)))

KEYS = ("p_min", "p_max", "phi", "w", "cos_theta_o", "cos_theta_e", "two_sided")


# ---------------------------------------------------------------------------------------
# Bounds tables
# ---------------------------------------------------------------------------------------

class BoundsTable:
    """LightBounds of ``n`` lights as arrays; ``finite[i]`` is False for lights without
    bounds (infinite lights, or families that do not provide bounds)."""

    def __init__(self, n: int):
        self.n = n
        self.finite = np.zeros(n, bool)
        self.p_min = np.zeros((n, 3))
        self.p_max = np.zeros((n, 3))
        self.phi = np.zeros(n)
        self.w = np.tile([0.0, 0.0, 1.0], (n, 1))
        self.cos_o = np.full(n, -1.0)
        self.cos_e = np.zeros(n)
        self.two_sided = np.zeros(n, bool)

    @classmethod
    def from_items(cls, items, counts=None) -> "BoundsTable":
        """From one item per light group: ``None`` (no bounds), a dict of pbrt-v4
        LightBounds (``p_min``, ``p_max``, ``phi``, ``w``, ``cos_theta_o``, ``cos_theta_e``,
        ``two_sided``), or a dict of arrays describing ``counts[k]`` lights at once."""
        items = list(items)
        counts = [1] * len(items) if counts is None else [int(c) for c in counts]
        t = cls(int(sum(counts)))
        o = 0
        for b, c in zip(items, counts):
            if b is not None and c > 0:
                missing = [k for k in KEYS if k not in b]
                if missing:
                    raise ValueError(f"light bounds lack {missing}")
                s = slice(o, o + c)
                t.finite[s] = True
                t.p_min[s] = np.broadcast_to(np.asarray(b["p_min"], np.float64).reshape(-1, 3), (c, 3))
                t.p_max[s] = np.broadcast_to(np.asarray(b["p_max"], np.float64).reshape(-1, 3), (c, 3))
                t.phi[s] = np.asarray(b["phi"], np.float64)
                w = np.broadcast_to(np.asarray(b["w"], np.float64).reshape(-1, 3), (c, 3))
                nw = np.linalg.norm(w, axis=1, keepdims=True)
                t.w[s] = np.where(nw > 0, w / np.where(nw > 0, nw, 1.0), [0.0, 0.0, 1.0])
                t.cos_o[s] = np.clip(np.asarray(b["cos_theta_o"], np.float64), -1.0, 1.0)
                t.cos_e[s] = np.clip(np.asarray(b["cos_theta_e"], np.float64), -1.0, 1.0)
                t.two_sided[s] = np.asarray(b["two_sided"], bool)
            o += c
        bad = t.finite & ~(np.isfinite(t.phi) & np.all(np.isfinite(t.p_min), 1) & np.all(np.isfinite(t.p_max), 1))
        if np.any(bad):
            raise ValueError(f"light {int(np.flatnonzero(bad)[0])} has non-finite bounds")
        return t


# ---------------------------------------------------------------------------------------
# Cones (numpy, vectorised over rows)
# ---------------------------------------------------------------------------------------

def _angle_between(a, b):
    """Angle between unit vectors, accurate near 0 and pi."""
    return 2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))


def cone_union(wa, ca, wb, cb):
    """Smallest cone around the great circle through both axes containing cones a and b
    (pbrt-v4's DirectionCone union), row by row. Returns (axis, cos half-angle)."""
    ta = np.arccos(np.clip(ca, -1.0, 1.0))
    tb = np.arccos(np.clip(cb, -1.0, 1.0))
    td = _angle_between(wa, wb)
    a_has_b = np.minimum(td + tb, np.pi) <= ta
    b_has_a = np.minimum(td + ta, np.pi) <= tb
    to = 0.5 * (ta + td + tb)
    k = np.cross(wa, wb)
    kn = np.linalg.norm(k, axis=-1)
    whole = (to >= np.pi) | (kn == 0)
    k = k / np.where(kn > 0, kn, 1.0)[..., None]
    tr = (to - ta)[..., None]
    # Rotate a's axis toward b's by tr about their common normal (a is orthogonal to it).
    w = wa * np.cos(tr) + np.cross(k, wa) * np.sin(tr)
    w /= np.maximum(np.linalg.norm(w, axis=-1, keepdims=True), 1e-300)
    c = np.cos(to)
    w = np.where(whole[..., None], wa, w)
    c = np.where(whole, -1.0, c)
    w = np.where(b_has_a[..., None], wb, w)
    c = np.where(b_has_a, cb, c)
    w = np.where(a_has_b[..., None], wa, w)
    c = np.where(a_has_b, ca, c)
    return w, c


def _mean_axis_cones(w, cos_o, seg_starts):
    """Per contiguous segment of lights: a cone around the normalised sum of the members'
    axes wide enough to hold every member's cone."""
    s = np.add.reduceat(w, seg_starts, axis=0)
    sn = np.linalg.norm(s, axis=1)
    axis = s / np.where(sn > 1e-9, sn, 1.0)[:, None]
    seg_of = np.repeat(np.arange(len(seg_starts)), np.diff(np.append(seg_starts, len(w))))
    ang = _angle_between(w, axis[seg_of]) + np.arccos(np.clip(cos_o, -1.0, 1.0))
    spread = np.maximum.reduceat(ang, seg_starts)
    c = np.where((sn > 1e-9) & (spread < np.pi), np.cos(np.minimum(spread, np.pi)), -1.0)
    axis[sn <= 1e-9] = [0.0, 0.0, 1.0]
    return axis, c


def _cone_measure(cos_o, cos_e):
    """pbrt-v4's M_Omega: solid-angle measure of a cone of normals widened by theta_e."""
    t_o = np.arccos(np.clip(cos_o, -1.0, 1.0))
    t_e = np.arccos(np.clip(cos_e, -1.0, 1.0))
    t_w = np.minimum(t_o + t_e, np.pi)
    s_o = np.sqrt(np.maximum(0.0, 1.0 - cos_o * cos_o))
    return (2.0 * np.pi * (1.0 - cos_o)
            + 0.5 * np.pi * (2.0 * t_w * s_o - np.cos(t_o - 2.0 * t_w) - 2.0 * t_o * s_o + cos_o))


def _surface_area(lo, hi):
    d = np.maximum(hi - lo, 0.0)
    return 2.0 * (d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0])


# ---------------------------------------------------------------------------------------
# Construction
# ---------------------------------------------------------------------------------------

class LightBVH:
    """Flattened tree (numpy). Node ``k``: bounds ``p_min/p_max/phi/w/cos_o/cos_e/two``,
    ``leaf[k]``, and ``child[k]`` = the first of two adjacent children (interior) or the
    light's index in the input (leaf). ``trail[i]``: bit trail of input light ``i``."""

    def __init__(self, p_min, p_max, phi, w, cos_o, cos_e, two_sided):
        n = len(phi)
        if n == 0:
            raise ValueError("a light BVH needs at least one light")
        N = 2 * n - 1
        self.p_min = np.zeros((N, 3)); self.p_max = np.zeros((N, 3))
        self.phi = np.zeros(N); self.w = np.zeros((N, 3))
        self.cos_o = np.zeros(N); self.cos_e = np.zeros(N)
        self.two = np.zeros(N, bool); self.leaf = np.zeros(N, bool)
        self.child = np.zeros(N, np.int64)
        self.depth = np.zeros(N, np.int64)
        self.trail = np.zeros(n, np.uint64)
        c = 0.5 * (p_min + p_max)

        order = np.arange(n)
        starts, ends, nodes = np.array([0]), np.array([n]), np.array([0])
        depth, next_node, levels = 0, 1, []
        while len(starts):
            sizes = ends - starts
            offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            seg_of = np.repeat(np.arange(len(starts)), sizes)
            pos = starts[seg_of] + (np.arange(len(seg_of)) - offs[seg_of])
            li = order[pos]
            self.depth[nodes] = depth
            # Node bounds: unions over the members.
            self.p_min[nodes] = np.minimum.reduceat(p_min[li], offs, axis=0)
            self.p_max[nodes] = np.maximum.reduceat(p_max[li], offs, axis=0)
            self.phi[nodes] = np.add.reduceat(phi[li], offs)
            self.cos_e[nodes] = np.minimum.reduceat(cos_e[li], offs)
            self.two[nodes] = np.maximum.reduceat(two_sided[li].astype(np.int8), offs) > 0
            self.w[nodes], self.cos_o[nodes] = _mean_axis_cones(w[li], cos_o[li], offs)
            leaf = sizes == 1
            self.leaf[nodes[leaf]] = True
            self.child[nodes[leaf]] = li[offs[leaf]]
            inner = np.flatnonzero(~leaf)
            if not len(inner):
                break
            # Split every interior segment of this level.
            in_light = ~leaf[seg_of]
            pos_i, li_i, seg_i = pos[in_light], li[in_light], seg_of[in_light]
            local = np.full(len(starts), -1)
            local[inner] = np.arange(len(inner))
            side = self._split(li_i, local[seg_i], starts[inner], sizes[inner], pos_i, depth,
                               c, p_min, p_max, phi, w, cos_o, cos_e, two_sided,
                               self.p_min[nodes[inner]], self.p_max[nodes[inner]])
            perm = np.lexsort((side, seg_i))
            order[pos_i] = li_i[perm]
            n_left = np.bincount(local[seg_i], weights=(side == 0), minlength=len(inner)).astype(np.int64)
            right = li_i[side == 1]
            self.trail[right] |= np.uint64(1) << np.uint64(depth)
            c0 = next_node + 2 * np.arange(len(inner))
            next_node += 2 * len(inner)
            self.child[nodes[inner]] = c0
            levels.append((nodes[inner], c0))
            mid = starts[inner] + n_left
            starts = np.concatenate([starts[inner], mid])
            ends = np.concatenate([mid, ends[inner]])
            nodes = np.concatenate([c0, c0 + 1])
            depth += 1
        # Tighten interior cones bottom-up with the union of the children's cones.
        for par, c0 in reversed(levels):
            wu, cu = cone_union(self.w[c0], self.cos_o[c0], self.w[c0 + 1], self.cos_o[c0 + 1])
            better = cu > self.cos_o[par]
            self.w[par[better]] = wu[better]
            self.cos_o[par[better]] = cu[better]
        self.n_nodes = N
        self.max_depth = int(self.depth.max())

    @staticmethod
    def _split(li, seg, starts, sizes, pos, depth, c, p_min, p_max, phi, w, cos_o, cos_e, two,
               box_lo, box_hi):
        """Side (0 left, 1 right) of every light of the interior segments of one level."""
        S = len(starts)
        # Lights come grouped by segment (each segment holds at least two).
        firsts = np.flatnonzero(np.concatenate([[True], seg[1:] != seg[:-1]]))
        cmin = np.minimum.reduceat(c[li], firsts, axis=0)
        cmax = np.maximum.reduceat(c[li], firsts, axis=0)
        ext = cmax - cmin
        diag = box_hi - box_lo
        best_cost = np.full(S, np.inf)
        best_dim = np.full(S, -1)
        best_bucket = np.zeros(S, np.int64)
        buckets = []
        for d in range(3):
            valid = ext[:, d] > 0
            e = np.where(valid, ext[:, d], 1.0)
            b = np.floor(N_BUCKETS * (c[li, d] - cmin[seg, d]) / e[seg]).astype(np.int64)
            b = np.clip(b, 0, N_BUCKETS - 1)
            buckets.append(b)
            cost = _split_costs(seg, b, S, li, p_min, p_max, phi, w, cos_o, cos_e)
            with np.errstate(divide="ignore", invalid="ignore"):
                kr = np.max(diag, axis=1) / diag[:, d]
            cost = cost * kr[:, None]
            cost[~valid] = np.inf
            cost[:, 0] = np.inf          # as in pbrt-v4, the first bucket boundary is not tried
            cost[~(cost > 0)] = np.inf
            k = np.argmin(cost, axis=1)
            ck = cost[np.arange(S), k]
            better = ck < best_cost
            best_cost[better] = ck[better]
            best_dim[better] = d
            best_bucket[better] = k[better]
        # Lights go right when their bucket along the chosen axis lies after the split.
        b_all = np.stack(buckets, 1)
        dim = best_dim[seg]
        side = (b_all[np.arange(len(li)), np.maximum(dim, 0)] > best_bucket[seg]).astype(np.int64)
        n_right = np.bincount(seg, weights=side, minlength=S)
        need = np.ceil(np.log2(sizes)).astype(np.int64)
        median = (best_dim < 0) | (n_right == 0) | (n_right == sizes) | (depth + 1 + need > MAX_DEPTH)
        m = median[seg]
        rank = pos - starts[seg]
        side[m] = (rank[m] >= sizes[seg][m] // 2).astype(np.int64)
        return side


def _split_costs(seg, b, S, li, p_min, p_max, phi, w, cos_o, cos_e):
    """Cost (without the axis ratio) of splitting after each bucket, for every segment:
    shape (S, N_BUCKETS - 1); inf where a side is empty."""
    key = seg * N_BUCKETS + b
    perm = np.argsort(key, kind="stable")
    ks = key[perm]
    first = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
    uk = ks[first]
    lp = li[perm]
    nb = S * N_BUCKETS
    B_phi = np.zeros(nb); B_lo = np.full((nb, 3), np.inf); B_hi = np.full((nb, 3), -np.inf)
    B_ce = np.ones(nb); B_w = np.tile([0.0, 0.0, 1.0], (nb, 1)); B_co = np.ones(nb)
    B_phi[uk] = np.add.reduceat(phi[lp], first)
    B_lo[uk] = np.minimum.reduceat(p_min[lp], first, axis=0)
    B_hi[uk] = np.maximum.reduceat(p_max[lp], first, axis=0)
    B_ce[uk] = np.minimum.reduceat(cos_e[lp], first)
    B_w[uk], B_co[uk] = _mean_axis_cones(w[lp], cos_o[lp], first)
    shp = (S, N_BUCKETS)
    B_phi = B_phi.reshape(shp); B_lo = B_lo.reshape(shp + (3,)); B_hi = B_hi.reshape(shp + (3,))
    B_ce = B_ce.reshape(shp); B_w = B_w.reshape(shp + (3,)); B_co = B_co.reshape(shp)

    def sweep(idx):
        """Running unions over buckets in the order ``idx``; the cost after each step."""
        phi_a = np.zeros(S); lo = np.full((S, 3), np.inf); hi = np.full((S, 3), -np.inf)
        ce = np.ones(S); wa = np.tile([0.0, 0.0, 1.0], (S, 1)); ca = np.ones(S)
        out = np.full((S, N_BUCKETS), np.inf)
        for j in idx:
            has = B_phi[:, j] > 0
            fresh = has & (phi_a == 0)
            wu, cu = cone_union(wa, ca, B_w[:, j], B_co[:, j])
            wa = np.where(fresh[:, None], B_w[:, j], np.where(has[:, None], wu, wa))
            ca = np.where(fresh, B_co[:, j], np.where(has, cu, ca))
            phi_a = phi_a + B_phi[:, j]
            lo = np.minimum(lo, B_lo[:, j]); hi = np.maximum(hi, B_hi[:, j])
            ce = np.where(has, np.minimum(ce, B_ce[:, j]), ce)
            cost = phi_a * _cone_measure(ca, ce) * _surface_area(lo, hi)
            out[:, j] = np.where(phi_a > 0, cost, np.inf)
        return out

    below = sweep(range(N_BUCKETS))                   # buckets 0..j
    above = sweep(range(N_BUCKETS - 1, -1, -1))       # buckets j..end
    return below[:, :-1] + above[:, 1:]


# ---------------------------------------------------------------------------------------
# Sampling (Dr.Jit)
# ---------------------------------------------------------------------------------------

def _cos_sub(sin_a, cos_a, sin_b, cos_b):
    """cos(max(0, a - b))."""
    return dr.select(cos_a > cos_b, 1.0, cos_a * cos_b + sin_a * sin_b)


def _sin_sub(sin_a, cos_a, sin_b, cos_b):
    """sin(max(0, a - b))."""
    return dr.select(cos_a > cos_b, 0.0, sin_a * cos_b - cos_a * sin_b)


def importance(p, n, has_n, A, B, C):
    """pbrt-v4's LightBounds importance of a node for the point ``p`` with normal ``n``
    (ignored where ``has_n`` is False). What depends on the node alone is read from its
    table row (:func:`node_rows`): A = (centre of the bounds, half their diagonal),
    B = (w, phi, negative if two-sided), C = (cos_o, sin_o, cos_e, the node's word)."""
    pc = mi.Vector3f(A.x, A.y, A.z)
    half_diag = A.w
    w = mi.Vector3f(B.x, B.y, B.z)
    phi, two = dr.abs(B.w), B.w < 0
    cos_o, sin_o, cos_e = C.x, C.y, C.z
    v = p - pc
    dc2 = dr.squared_norm(v)
    # pbrt-v4 clamps the squared distance by half the box diagonal (a length).
    d2 = dr.maximum(dr.maximum(dc2, half_diag), 1e-30)
    inv_dc = dr.select(dc2 > 0, dr.rsqrt(dc2), 0.0)
    wi = v * inv_dc
    cos_w = dr.dot(w, wi)
    cos_w = dr.select(two, dr.abs(cos_w), cos_w)
    sin_w = dr.safe_sqrt(1.0 - cos_w * cos_w)
    # Directions from p subtended by the box's bounding sphere.
    # (sin theta_b = r / |v| outside the sphere: no division, one square root fewer)
    inside = dc2 < half_diag * half_diag
    sin_b = dr.select(inside, 0.0, dr.minimum(half_diag * inv_dc, 1.0))
    cos_b = dr.select(inside, -1.0, dr.safe_sqrt(1.0 - sin_b * sin_b))
    cos_x = _cos_sub(sin_w, cos_w, sin_o, cos_o)
    sin_x = _sin_sub(sin_w, cos_w, sin_o, cos_o)
    cos_p = _cos_sub(sin_x, cos_x, sin_b, cos_b)
    imp = phi * cos_p / d2
    cos_i = dr.abs(dr.dot(wi, n))
    sin_i = dr.safe_sqrt(1.0 - cos_i * cos_i)
    imp = dr.select(has_n, imp * _cos_sub(sin_i, cos_i, sin_b, cos_b), imp)
    return dr.select(cos_p > cos_e, dr.maximum(imp, 0.0), 0.0)


def node_rows(b: "LightBVH", word: np.ndarray):
    """The three float32 rows per node that :func:`importance` reads (4 floats each):
    what depends on the node alone is computed here once, not at every visit of a
    descent (the centre and half diagonal of the bounds, sin theta_o). The two-sided
    flag is phi's sign (a node of zero power has importance 0 either way), and the
    node's ``word`` (its bits) rides in the last slot: a descent that has read both
    children's rows knows the chosen child's word without another gather."""
    f32 = np.float32
    lo, hi = b.p_min.astype(f32), b.p_max.astype(f32)
    centre = f32(0.5) * (lo + hi)
    half_diag = f32(0.5) * np.sqrt(np.sum(np.square(hi - lo), axis=1, dtype=f32))
    cos_o = b.cos_o.astype(f32)
    sin_o = np.sqrt(np.maximum(f32(1.0) - cos_o * cos_o, f32(0.0)))
    A = np.column_stack([centre, half_diag]).astype(f32)
    B = np.column_stack([b.w, np.where(b.two, -b.phi, b.phi)]).astype(f32)
    C = np.column_stack([cos_o, sin_o, b.cos_e, np.zeros(len(cos_o))]).astype(f32)
    C[:, 3] = np.asarray(word, np.uint32).view(f32)
    return [x.ravel() for x in (A, B, C)]


class BVHLightSampler:
    """pbrt-v4's ``bvh`` light sampler over ``n`` lights described by a BoundsTable."""

    kind = "bvh"

    def __init__(self, table: BoundsTable):
        self.n = table.n
        self.table = table
        use = table.finite & (table.phi > 0)
        self.inf_ids = np.flatnonzero(~table.finite)
        self.tree_ids = np.flatnonzero(use)
        n_inf, has_tree = len(self.inf_ids), len(self.tree_ids) > 0
        self.p_inf = n_inf / (n_inf + (1 if has_tree else 0)) if (n_inf or has_tree) else 0.0
        # kind per light: 0 in the tree, 1 infinite, 2 never sampled (zero power)
        kind = np.full(self.n, 2, np.uint32)
        kind[self.inf_ids] = 1
        kind[self.tree_ids] = 0
        self.kind_np = kind
        self._kind = mi.UInt32(kind)
        self._inf = mi.UInt32(self.inf_ids.astype(np.uint32)) if n_inf else None
        self.bvh = None
        self.n_nodes = 0
        if has_tree:
            t, ids = table, self.tree_ids
            # Only ratios of sibling importances matter: normalise the power (float32 range).
            scale = 1.0 / t.phi[ids].max()
            bvh = LightBVH(t.p_min[ids], t.p_max[ids], t.phi[ids] * scale, t.w[ids], t.cos_o[ids],
                           t.cos_e[ids], t.two_sided[ids])
            self.bvh = bvh
            self.n_nodes = bvh.n_nodes
            word = np.where(bvh.leaf, ids[np.where(bvh.leaf, bvh.child, 0)], bvh.child).astype(np.uint32)
            word |= np.where(bvh.leaf, LEAF_BIT, 0).astype(np.uint32)
            self.root_word = int(word[0])
            self._A, self._B, self._C = (mi.Float(r) for r in node_rows(bvh, word))
            trail = np.zeros(self.n, np.uint64)
            trail[ids] = bvh.trail
            if np.any(trail >> np.uint64(32)):
                raise RuntimeError("light BVH deeper than 32 levels")
            self._trail = mi.UInt32(trail.astype(np.uint32))

    # -- node access ----------------------------------------------------------------------
    def _importance(self, node, p, n, has_n, active):
        """(importance of ``node`` at p, the node's word)."""
        A = dr.gather(mi.Vector4f, self._A, node, active)
        B = dr.gather(mi.Vector4f, self._B, node, active)
        C = dr.gather(mi.Vector4f, self._C, node, active)
        return importance(p, n, has_n, A, B, C), dr.reinterpret_array(mi.UInt32, C.w)

    def _step(self, word, p, n, has_n, active):
        """The children of inner node ``word``: their importances, words and total."""
        c0 = word & INDEX_MASK
        i0, w0 = self._importance(c0, p, n, has_n, active)
        i1, w1 = self._importance(c0 + 1, p, n, has_n, active)
        return i0, i1, w0, w1, i0 + i1

    def _loop(self, state, cond, body, labels, label):
        """The descent from the root: a symbolic loop, or for a shallow tree (at most
        ``UNROLL_DEPTH`` levels, e.g. the two lights of the materials gallery) its levels
        written out (no loop to enter and test per path vertex: 0.99x the gallery's
        kernel time, same values)."""
        if self.bvh.max_depth <= UNROLL_DEPTH:
            return dispatch.loop(state, cond, body, self.bvh.max_depth, label)
        return dr.while_loop(state, cond, body, labels=labels, label=label)

    # -- the sampler interface ------------------------------------------------------------
    def sample(self, u, ref_p, ref_n, active=True):
        """(light index, probability of choosing it at (ref_p, ref_n)); probability 0
        (light 0) where no light can contribute."""
        active = mi.Bool(active)
        u = mi.Float(u)
        light = mi.UInt32(0)
        pmf = mi.Float(0.0)
        n_inf = len(self.inf_ids)
        tree = mi.Bool(active)
        if n_inf:
            pick = active & (u < self.p_inf)
            k = dr.minimum(mi.UInt32(u * (n_inf / self.p_inf)), n_inf - 1)
            light = dr.select(pick, dr.gather(mi.UInt32, self._inf, k, pick), light)
            pmf = dr.select(pick, self.p_inf / n_inf, pmf)
            tree = active & ~pick
            u = dr.minimum((u - self.p_inf) / (1.0 - self.p_inf), ONE_MINUS_EPS)
        if not self.n_nodes:
            return light, pmf
        p, n = mi.Point3f(ref_p), mi.Normal3f(ref_n)
        has_n = dr.squared_norm(n) > 0
        if self.n_nodes == 1:
            i = self._importance(mi.UInt32(0), p, n, has_n, tree)[0]
            ok = tree & (i > 0)
            light = dr.select(ok, self.root_word & INDEX_MASK, light)
            return light, dr.select(ok, 1.0 - self.p_inf, dr.select(tree, 0.0, pmf))
        word, q = self._descend(u, p, n, has_n, tree)
        light = dr.select(tree & (q > 0), word & INDEX_MASK, light)
        pmf = dr.select(tree, q, pmf)
        return light, pmf

    def _descend(self, u, p, n, has_n, active):
        word = mi.UInt32(self.root_word)
        q = mi.Float(1.0 - self.p_inf)

        def cond(word, q, u, alive):
            return alive

        def body(word, q, u, alive):
            i0, i1, w0, w1, tot = self._step(word, p, n, has_n, alive)
            t = u * tot
            left = (t < i0) | (i1 == 0)
            dead = ~(tot > 0)
            u = dr.select(left, t / i0, (t - i0) / i1)
            u = dr.clip(u, 0.0, ONE_MINUS_EPS)
            q = dr.select(dead, 0.0, q * (dr.select(left, i0, i1) / tot))
            word = dr.select(alive, dr.select(left, w0, w1), word)
            alive = alive & ~dead & ((word & int(LEAF_BIT)) == 0)
            return word, q, u, alive

        word, q, u, _ = self._loop((word, q, mi.Float(u), mi.Bool(active)), cond, body, ("word", "q", "u", "alive"),
                                   "light_bvh_sample")
        return word, q

    def pmf(self, light, ref_p, ref_n, active=True):
        """Probability that ``sample`` at (ref_p, ref_n) returns ``light``."""
        active = mi.Bool(active)
        light = mi.UInt32(light)
        kind = dr.gather(mi.UInt32, self._kind, light, active)
        out = mi.Float(0.0)
        n_inf = len(self.inf_ids)
        if n_inf:
            out = dr.select(active & (kind == 1), self.p_inf / n_inf, out)
        if not self.n_nodes:
            return out
        tree = active & (kind == 0)
        p, n = mi.Point3f(ref_p), mi.Normal3f(ref_n)
        has_n = dr.squared_norm(n) > 0
        if self.n_nodes == 1:
            i = self._importance(mi.UInt32(0), p, n, has_n, tree)[0]
            return dr.select(tree & (i > 0), 1.0 - self.p_inf, out)
        trail = dr.gather(mi.UInt32, self._trail, light, tree)

        def cond(word, q, trail, alive):
            return alive

        def body(word, q, trail, alive):
            i0, i1, w0, w1, tot = self._step(word, p, n, has_n, alive)
            right = (trail & 1) == 1
            dead = ~(tot > 0)
            q = dr.select(dead, 0.0, q * (dr.select(right, i1, i0) / tot))
            word = dr.select(alive, dr.select(right, w1, w0), word)
            alive = alive & (q > 0) & ((word & int(LEAF_BIT)) == 0)
            return word, q, trail >> 1, alive

        _, q, _, _ = self._loop((mi.UInt32(self.root_word), mi.Float(1.0 - self.p_inf), trail, mi.Bool(tree)),
                                cond, body, ("word", "q", "trail", "alive"), "light_bvh_pmf")
        return dr.select(tree, q, out)

    # -- reference (numpy, float64) for tests -------------------------------------------
    def pmf_all_np(self, p, n=None) -> np.ndarray:
        """Probabilities of every light at one point, in float64 (tests/diagnostics)."""
        out = np.zeros(self.n)
        n_inf = len(self.inf_ids)
        if n_inf:
            out[self.inf_ids] = self.p_inf / n_inf
        if not self.n_nodes:
            return out
        b = self.bvh
        imp = _importance_np(np.asarray(p, float), None if n is None else np.asarray(n, float), b)
        q = np.zeros(b.n_nodes)
        q[0] = (1.0 - self.p_inf) if (b.n_nodes > 1 or imp[0] > 0) else 0.0
        for k in range(b.n_nodes):          # parents precede children
            if b.leaf[k]:
                out[self.tree_ids[b.child[k]]] = q[k]
                continue
            c0 = b.child[k]
            tot = imp[c0] + imp[c0 + 1]
            if tot > 0:
                q[c0], q[c0 + 1] = q[k] * imp[c0] / tot, q[k] * imp[c0 + 1] / tot
        return out


def _importance_np(p, n, b: LightBVH):
    """importance() for every node of ``b`` at one point, in numpy (float64)."""
    pc = 0.5 * (b.p_min + b.p_max)
    v = p - pc
    dc2 = np.sum(v * v, 1)
    half = 0.5 * np.linalg.norm(b.p_max - b.p_min, axis=1)
    d2 = np.maximum(np.maximum(dc2, half), 1e-30)
    wi = v / np.where(dc2 > 0, np.sqrt(dc2), np.inf)[:, None]
    cw = np.sum(b.w * wi, 1)
    cw = np.where(b.two, np.abs(cw), cw)
    sw = np.sqrt(np.maximum(0, 1 - cw * cw))
    r2 = half * half
    cb = np.where(dc2 < r2, -1.0, np.sqrt(np.maximum(0, 1 - r2 / np.maximum(dc2, 1e-30))))
    sb = np.sqrt(np.maximum(0, 1 - cb * cb))
    so = np.sqrt(np.maximum(0, 1 - b.cos_o ** 2))

    def csub(sa, ca, sb_, cb_):
        return np.where(ca > cb_, 1.0, ca * cb_ + sa * sb_)

    cx = csub(sw, cw, so, b.cos_o)
    sx = np.where(cw > b.cos_o, 0.0, sw * b.cos_o - cw * so)
    cp = csub(sx, cx, sb, cb)
    imp = b.phi * cp / d2
    if n is not None and np.any(n != 0):
        ci = np.abs(wi @ n)
        si = np.sqrt(np.maximum(0, 1 - ci * ci))
        imp = imp * csub(si, ci, sb, cb)
    return np.where(cp > b.cos_e, np.maximum(imp, 0.0), 0.0)


def ensure_table(bounds, n: int) -> BoundsTable:
    if isinstance(bounds, BoundsTable):
        return bounds
    if bounds is None:
        return BoundsTable(n)
    return BoundsTable.from_items(bounds)


__all__ = ["BoundsTable", "LightBVH", "BVHLightSampler", "cone_union", "importance", "ensure_table"]
