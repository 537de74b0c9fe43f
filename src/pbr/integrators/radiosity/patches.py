"""Patches: the scene's mesh triangles, optionally subdivided, as radiosity elements.

Every shape must be a triangle mesh in Mitsuba (``rectangle``, ``cube``, ``obj``,
``ply``); other shapes (spheres, disks, cylinders, curves) are rejected rather than
tessellated, because the camera rays of the render pass hit Mitsuba's exact shape and
must find their patch. Vertex positions are the world-space buffers Mitsuba traces.

A triangle of area ``A`` is split into ``n^2`` congruent sub-triangles, ``n = ceil(sqrt(A
/ max_area))``, by cutting each edge into ``n`` equal segments (so a hit's barycentric
coordinates give its sub-triangle in closed form, see :meth:`Patches.patch_of_hit`).
Sub-triangles in row ``j`` (from edge v0-v1 toward v2) alternate "up" (grid corners
(i, j), (i+1, j), (i, j+1)) and "down" ((i+1, j+1), (i, j+1), (i+1, j)); the local index
of (i, j) is ``j (2n - j) + 2 i (+ 1 if down)``. Both keep the winding of the parent.

Each patch is one-sided, like pbr's ``diffuse`` BSDF and ``area`` emitter: its front is
the side of the parent's geometric normal (Mitsuba's ``flip_normals`` flips it). Shading
normals are ignored by the solution.

Vertices of the subdivided meshes are welded per shape by their exact barycentric
position on the parent mesh's vertices (edges shared by triangles with the same ``n``
share their new vertices), so per-vertex values (smooth display, export) average
across the triangles of a mesh but not across shapes or mesh seams.
"""

from __future__ import annotations

from functools import lru_cache

import drjit as dr
import mitsuba as mi
import numpy as np

from ...bsdfs import NO_BACK
from ...bsdfs.base import ShadingContext
from ...plugins.props import SceneError
from ...spectrum import SampledWavelengths

MAX_SPLIT = 4096            # edge segments per triangle (n^2 patches)


@lru_cache(maxsize=None)
def _template(n: int) -> np.ndarray:
    """(n^2, 3 corners, 2) grid coordinates (a, b) of a triangle's sub-triangles, in
    local-index order; the point is v0 + a/n (v1 - v0) + b/n (v2 - v0)."""
    out = []
    for j in range(n):
        for i in range(n - j):
            out.append(((i, j), (i + 1, j), (i, j + 1)))
            if i + j + 2 <= n:
                out.append(((i + 1, j + 1), (i, j + 1), (i + 1, j)))
    return np.array(out, dtype=np.int64)


def _vec(t, a):
    """A Dr.Jit vector type from an (n, dim) numpy array."""
    return t(*[mi.Float(np.ascontiguousarray(a[:, k], dtype=np.float32)) for k in range(a.shape[1])])


def _mesh(shape):
    """World-space vertices (V, 3) and faces (F, 3) of a Mitsuba mesh."""
    v = np.array(shape.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
    f = np.array(shape.faces_buffer(), dtype=np.int64).reshape(-1, 3)
    return v, f


def split_counts(A: np.ndarray, max_area: float) -> np.ndarray:
    """Edge segments ``n`` of each triangle of area ``A`` (``n^2`` patches) for
    ``max_area`` (0: no split)."""
    if max_area > 0:
        return np.clip(np.ceil(np.sqrt(A / max_area) - 1e-9), 1, MAX_SPLIT).astype(np.int64)
    return np.ones(len(A), np.int64)


def max_area_for(scene, budget: int) -> float:
    """The smallest ``max_area`` whose subdivision of the scene's mesh triangles has at
    most ``budget`` patches (0, no split, when the triangles alone reach the budget):
    the default of the ``radiosity`` integrator (``patch_budget``). Shapes that are not
    meshes are skipped here (``Patches`` rejects them)."""
    areas = []
    for shape in scene.mi_scene.shapes():
        if shape.is_mesh():
            v, f = _mesh(shape)
            areas.append(0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1))
    A = np.concatenate(areas) if areas else np.zeros(0)
    if len(A) == 0 or len(A) >= budget:
        return 0.0
    lo, hi = 0.0, float(A.max())       # hi: no triangle split (len(A) <= budget patches)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if int(np.sum(split_counts(A, mid) ** 2)) <= budget:
            hi = mid
        else:
            lo = mid
    return hi


class Patches:
    """The patches of a scene (numpy arrays, one row per patch) and the Dr.Jit tables
    that map a surface hit to its patch.

    ``p`` (N, 3, 3) corners, ``normal`` (N, 3) front normals, ``area`` (N,),
    ``centroid`` (N, 3), ``shape`` (N,) pbr shape index, ``prim`` (N,) parent triangle
    in its mesh, ``bary`` (N, 2) barycentric coordinates of the centroid in the parent,
    ``vertices`` (V, 3) and ``faces`` (N, 3): the welded subdivided meshes.
    """

    def __init__(self, scene, max_area: float = 0.0):
        shapes = scene.mi_scene.shapes()
        to_mi = self.mi_index = scene.geometry.mi_index
        cols = {k: [] for k in ("p", "normal", "area", "shape", "prim", "bary", "key")}
        tri_n, tri_off, shape_tri = [], [], []
        TP = []
        n_patch = n_tri = 0
        for s in range(len(to_mi)):
            shape = shapes[int(to_mi[s])]
            if not shape.is_mesh():
                raise SceneError(f"{scene.shape_paths[s]}: the radiosity integrator needs triangle meshes "
                                 f"(rectangle, cube, obj, ply); a {shape.class_name().lower()} is not one")
            v, f = _mesh(shape)
            shape_tri.append(n_tri)
            n_tri += len(f)
            P = v[f]                                            # (F, 3, 3)
            cr = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
            a2 = np.linalg.norm(cr, axis=1)
            sign = -1.0 if shape.has_flipped_normals() else 1.0   # flips normals, not the winding
            nrm = sign * cr / np.where(a2 > 0, a2, 1.0)[:, None]
            A = 0.5 * a2
            n = split_counts(A, max_area)
            counts = n * n
            first = np.concatenate([[0], np.cumsum(counts)[:-1]])   # the shape's patches, by triangle
            tri_n.append(n)
            tri_off.append(n_patch + first)
            TP.append(P)
            total = int(counts.sum())
            out = {"p": np.empty((total, 3, 3)), "key": np.empty((total, 3, 8), np.int64),
                   "bary": np.empty((total, 2)), "prim": np.repeat(np.arange(len(f)), counts)}
            for m in np.unique(n):
                tris = np.nonzero(n == m)[0]
                tpl = _template(int(m))                           # (m^2, 3, 2)
                ab = tpl / float(m)
                Pt = P[tris]                                      # (T, 3, 3)
                e1, e2 = Pt[:, 1] - Pt[:, 0], Pt[:, 2] - Pt[:, 0]
                dest = (first[tris][:, None] + np.arange(m * m)[None]).ravel()
                out["p"][dest] = (Pt[:, None, None, 0] + ab[None, :, :, 0, None] * e1[:, None, None]
                                  + ab[None, :, :, 1, None] * e2[:, None, None]).reshape(-1, 3, 3)
                out["key"][dest] = self._vertex_keys(s, f[tris], tpl, int(m)).reshape(-1, 3, 8)
                out["bary"][dest] = np.tile(ab.mean(axis=1), (len(tris), 1))
            out["normal"] = nrm[out["prim"]]
            out["area"] = (A / counts)[out["prim"]]
            out["shape"] = np.full(total, s)
            for k in cols:
                cols[k].append(out[k])
            n_patch += total
        cat = {k: np.concatenate(v) for k, v in cols.items()}
        self.count = n_patch
        self.p = cat["p"]
        self.normal = cat["normal"]
        self.area = cat["area"]
        self.shape = cat["shape"].astype(np.int64)
        self.prim = cat["prim"].astype(np.int64)
        self.bary = cat["bary"]
        self.centroid = self.p.mean(axis=1)
        keys = cat["key"].reshape(-1, 8)
        uniq, first, inv = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        self.faces = inv.reshape(-1, 3)
        self.vertices = self.p.reshape(-1, 3)[first]
        self.n_vertices = len(uniq)
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.extent = float(np.linalg.norm(hi - lo)) or 1.0
        self._tables(np.array(shape_tri, np.int64), np.concatenate(tri_n), np.concatenate(tri_off),
                     np.concatenate(TP))

    @staticmethod
    def _vertex_keys(s, corners, tpl, m):
        """Integer keys of grid points: (shape, (vertex id, weight) x 3 sorted by id,
        denominator), with the weights over the parent's mesh vertices reduced by their
        gcd, so that equal points of neighbouring triangles get equal keys."""
        a, b = tpl[..., 0], tpl[..., 1]
        w = np.stack([m - a - b, a, b], axis=-1)                  # (m^2, 3 pts, 3 weights)
        g = np.gcd(np.gcd(w[..., 0], w[..., 1]), np.gcd(w[..., 2], m))
        w = w // g[..., None]
        d = m // g
        T = len(corners)
        ids = np.broadcast_to(corners[:, None, None, :], (T,) + w.shape).copy()
        W = np.broadcast_to(w, (T,) + w.shape).copy()
        ids[W == 0] = -1
        srt = np.argsort(ids, axis=-1, kind="stable")
        ids = np.take_along_axis(ids, srt, -1)
        W = np.take_along_axis(W, srt, -1)
        out = np.empty((T,) + w.shape[:2] + (8,), np.int64)
        out[..., 0] = s
        out[..., 1:7:2] = ids
        out[..., 2:7:2] = W
        out[..., 7] = np.broadcast_to(d, (T,) + d.shape)
        return out

    # -- Dr.Jit tables ---------------------------------------------------------------------
    def _tables(self, shape_tri, tri_n, tri_off, TP):
        f32 = np.float32
        self.shape_tri = mi.UInt32(shape_tri.astype(np.uint32))
        self.tri_n = mi.UInt32(tri_n.astype(np.uint32))
        self.tri_patch = mi.UInt32(tri_off.astype(np.uint32))
        self.tri_p = [_vec(mi.Point3f, TP[:, k]) for k in range(3)]
        self.dr_p = [_vec(mi.Point3f, self.p[:, k]) for k in range(3)]
        self.dr_normal = _vec(mi.Normal3f, self.normal)
        self.dr_area = mi.Float(self.area.astype(f32))
        self.dr_faces = [mi.UInt32(self.faces[:, k].astype(np.uint32)) for k in range(3)]

    def patch_of_hit(self, shape, prim, p, active):
        """(patch index, barycentric weights of ``p`` on the patch's three corners) of a
        hit at ``p`` on triangle ``prim`` of pbr shape ``shape``. The barycentric
        coordinates in the parent are solved from ``p`` and its corners."""
        tri = dr.gather(mi.UInt32, self.shape_tri, shape, active) + prim
        n = dr.gather(mi.UInt32, self.tri_n, tri, active)
        off = dr.gather(mi.UInt32, self.tri_patch, tri, active)
        p0, p1, p2 = (dr.gather(mi.Point3f, t, tri, active) for t in self.tri_p)
        e1, e2, d = p1 - p0, p2 - p0, p - p0
        d00, d01, d11 = dr.dot(e1, e1), dr.dot(e1, e2), dr.dot(e2, e2)
        d20, d21 = dr.dot(d, e1), dr.dot(d, e2)
        inv = dr.rcp(dr.maximum(d00 * d11 - d01 * d01, 1e-30))
        b1 = (d11 * d20 - d01 * d21) * inv
        b2 = (d00 * d21 - d01 * d20) * inv
        nf = mi.Float(n)
        u, v = b1 * nf, b2 * nf
        j = mi.UInt32(dr.clip(dr.floor(v), 0.0, nf - 1.0))
        i = dr.minimum(mi.UInt32(dr.clip(dr.floor(u), 0.0, nf - 1.0)), n - 1 - j)
        fu, fv = u - mi.Float(i), v - mi.Float(j)
        down = (fu + fv > 1.0) & (i + j + 2 <= n)
        local = j * (2 * n - j) + 2 * i + dr.select(down, 1, 0)
        w = (dr.select(down, fu + fv - 1.0, 1.0 - fu - fv), dr.select(down, 1.0 - fu, fu),
             dr.select(down, 1.0 - fv, fv))
        return off + local, w

    # -- per-patch spectra -------------------------------------------------------------------
    def centroid_interactions(self, scene) -> mi.SurfaceInteraction3f:
        """Surface interactions at the patch centroids (Mitsuba's own interpolation of
        texture coordinates and shading frames), seen from the front (``wi`` = +z)."""
        shapes = scene.mi_scene.shapes()
        names = ("p", "n", "uv", "s", "t", "sn")
        F = {k: np.zeros((self.count, 2 if k == "uv" else 3)) for k in names}
        for s in np.unique(self.shape):
            idx = np.nonzero(self.shape == s)[0]
            shape = shapes[int(self.mi_index[s])]
            m = len(idx)
            pi = dr.zeros(mi.PreliminaryIntersection3f, m)
            pi.t = dr.full(mi.Float, 1.0, m)
            pi.prim_uv = _vec(mi.Point2f, self.bary[idx])
            pi.prim_index = mi.UInt32(self.prim[idx].astype(np.uint32))
            ray = mi.Ray3f(_vec(mi.Point3f, self.centroid[idx] + self.normal[idx]),
                           _vec(mi.Vector3f, -self.normal[idx]))
            si = shape.compute_surface_interaction(ray, pi, int(mi.RayFlags.All), True)
            for k, a in zip(names, (si.p, si.n, si.uv, si.sh_frame.s, si.sh_frame.t, si.sh_frame.n)):
                dim = F[k].shape[1]       # (values constant over a shape come back width 1)
                F[k][idx] = np.broadcast_to(np.array(a, dtype=np.float64).reshape(dim, -1), (dim, m)).T
        si = dr.zeros(mi.SurfaceInteraction3f, self.count)
        si.p = _vec(mi.Point3f, F["p"])
        si.n = _vec(mi.Normal3f, F["n"])
        si.uv = _vec(mi.Point2f, F["uv"])
        si.sh_frame = mi.Frame3f(_vec(mi.Vector3f, F["s"]), _vec(mi.Vector3f, F["t"]), _vec(mi.Vector3f, F["sn"]))
        si.wi = mi.Vector3f(0.0, 0.0, 1.0)
        si.prim_index = mi.UInt32(self.prim.astype(np.uint32))
        si.shape = dr.gather(mi.ShapePtr, scene.mi_scene.shapes_dr(),
                             mi.UInt32(self.mi_index[self.shape].astype(np.uint32)))
        si.t = dr.full(mi.Float, 1.0, self.count)
        return si

    def spectra(self, scene, bins) -> tuple[np.ndarray, np.ndarray]:
        """(emitted radiance Le, reflectance rho), each (N, K): the front side's values at
        each patch centroid and bin centre. The reflectance is pi times the BSDF value
        for normal incidence and exitance, so only Lambertian BSDFs give the albedo
        (the integrator checks that every BSDF is ``diffuse``)."""
        N, G = self.count, len(bins.groups())
        si0 = self.centroid_interactions(scene)
        idx = dr.arange(mi.UInt32, N * G)
        patch, group = idx % N, idx // N
        si = dr.gather(mi.SurfaceInteraction3f, si0, patch)
        si.wi = mi.Vector3f(0.0, 0.0, 1.0)
        lam = [dr.gather(mi.Float, mi.Float([g[k] for g in bins.groups()]), group) for k in range(4)]
        wl = SampledWavelengths(mi.Spectrum(lam), mi.Spectrum(1.0))
        shape = dr.gather(mi.UInt32, mi.UInt32(self.shape.astype(np.uint32)), patch)
        bsdf = dr.gather(mi.UInt32, scene.shape_bsdf, shape)
        f, _ = scene.bsdfs.eval_pdf(bsdf, ShadingContext(si, wl), mi.Vector3f(0, 0, 1), True)
        light = scene.lights.light_of_hit(scene, shape, si, True)
        Le = scene.lights.L(light - 1, si, wl, light > 0)
        rho, Le = np.array(f * dr.pi), np.array(Le)                  # (4, N G)

        def binned(a):
            a = a.reshape(4, G, N).transpose(2, 1, 0).reshape(N, 4 * G)
            return a[:, :bins.count].astype(np.float64)
        return binned(Le), binned(rho)


def check_materials(scene) -> None:
    """SceneError unless every shape is a plain one-sided ``diffuse`` reflector, the
    lights are ``area`` emitters and no shape bounds a medium (naming the key path)."""
    bs = scene.bsdfs
    shape_bsdf = np.array(scene.shape_bsdf, dtype=np.int64)
    transition = np.array(scene.shape_transition, dtype=bool)
    for s, b in enumerate(shape_bsdf):
        where = scene.shape_paths[s]
        fam, _, back, opacity = bs.entries[b]
        kind = ("blendbsdf" if b in bs.blend_of else "normalmap/bumpmap" if b in bs.perturb_of
                else "twosided" if back != NO_BACK else "mask" if opacity != NO_BACK else fam)
        if kind != "diffuse":
            raise SceneError(f"{where}.bsdf: the radiosity integrator needs 'diffuse' BSDFs, got {kind!r}")
        if transition[s]:
            raise SceneError(f"{where}: the radiosity integrator does not support media (interior/exterior)")
    if len(scene.media):
        raise SceneError("scene: the radiosity integrator does not support participating media")
    for where, (t, _) in zip(scene.lights.paths, scene.lights.entries):
        if t != "area":
            raise SceneError(f"{where}: the radiosity integrator supports only 'area' emitters, got {t!r}")
