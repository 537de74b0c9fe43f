"""``area``: a diffuse emitter attached to a shape (one-sided, or two-sided as pbrt-v4's
``twosided``); on a triangle mesh one light
per triangle (pbrt-v4), so that the light samplers see each with its power and bounds.
Sampling and bounds: docs/lights.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..textures import load_spectrum
from ..sampling import square_to_cosine_hemisphere, cosine_hemisphere_pdf
from .base import LIGHT_TYPES, LightType, LightSample, LeSample

# Mesh shapes that stay one light (Mitsuba builds a rectangle as two triangles).
SINGLE_LIGHT_MESHES = ("Rectangle",)
# How a sub-light is sampled: a triangle or a parallelogram (rectangle) by pbr's own code
# from its corners, or any other shape through Mitsuba's ``shape.sample_position``.
TRIANGLE, PARALLELOGRAM, MITSUBA = 0, 1, 2


def _is_triangle_mesh(shape) -> bool:
    return bool(shape.is_mesh()) and shape.class_name() not in SINGLE_LIGHT_MESHES


def _mesh_arrays(shape):
    """World-space vertex positions (V, 3), faces (F, 3) and, where the mesh has them,
    vertex normals and texture coordinates (else None)."""
    params = mi.traverse(shape)
    v = np.array(params["vertex_positions"], dtype=np.float64).reshape(-1, 3)
    f = np.array(params["faces"], dtype=np.int64).reshape(-1, 3)
    n = uv = None
    if shape.has_vertex_normals() and "vertex_normals" in params:
        n = np.array(params["vertex_normals"], dtype=np.float64).reshape(-1, 3)
        if len(n) != len(v):
            n = None
    if shape.has_vertex_texcoords() and "vertex_texcoords" in params:
        uv = np.array(params["vertex_texcoords"], dtype=np.float64).reshape(-1, 2)
        if len(uv) != len(v):
            uv = None
    return v, f, n, uv


def _rectangle(shape):
    """Corners p(0,0), p(1,0), p(0,1) of a Mitsuba rectangle (uv = the sample) and its
    normal."""
    ps = shape.sample_position(0.0, mi.Point2f([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]))
    P = np.array(ps.p, dtype=np.float64).T
    n = np.array(ps.n, dtype=np.float64).T[0]
    return P, n / np.linalg.norm(n)


def _shape_normal_cone(shape):
    """(axis, cos half-angle) bounding the normals of a shape sampled through Mitsuba:
    planar shapes (every sampled normal equal) get their normal, others the whole sphere."""
    u = np.random.default_rng(0).random((2, 16)).astype(np.float32)
    ps = shape.sample_position(0.0, mi.Point2f(u[0], u[1]))
    n = np.array(ps.n, dtype=np.float64).T
    if np.all(np.isfinite(n)) and np.all(n @ n[0] > 1.0 - 1e-6):
        return n[0] / np.linalg.norm(n[0]), 1.0
    return np.array([0.0, 0.0, 1.0]), -1.0


@LIGHT_TYPES.register("area")
class AreaLight(LightType):
    """``area`` (on a shape): uniform emission from the front of the surface, or from both
    sides (a triangle mesh is one light per triangle).

    ========  =======  =======  =================================================================
    name      type     default  meaning
    ========  =======  =======  =================================================================
    radiance  texture  1        emitted radiance (RGB: times D65, as Mitsuba's spectral variants)
    twosided  bool     false    emit from the back too (pbrt-v4's; twice the power)
    ========  =======  =======  =================================================================
    """

    name = "area"

    def add(self, loader, props, shape_index=None) -> int:
        slot = load_spectrum(loader, props.raw("radiance", 1.0), props.key("radiance"), emitter=True)
        two = props.bool("twosided", False)
        props.finish()
        self.instances.append({"radiance": slot, "shape": shape_index, "twosided": two})
        return len(self.instances) - 1

    # -- sub-lights --------------------------------------------------------------------
    def count(self, i: int) -> int:
        return self._count[i]

    def first(self, i: int) -> int:
        return self._first[i]

    def is_mesh(self, i: int) -> bool:
        """True where instance ``i`` is one light per triangle (hits add prim_index)."""
        return self._mesh[i]

    def build(self, scene) -> None:
        shapes = scene.mi_scene.shapes()
        consts = [scene.textures.constant_value(inst["radiance"]) for inst in self.instances]
        self._count, self._first, self._mesh = [], [], []
        self._power, self._bounds = [], []
        cols = {k: [] for k in ("radiance", "area", "other", "kind", "P", "n", "vn", "uv", "two")}
        self.other_shapes = []        # pbr shapes of the MITSUBA sub-lights
        o = 0
        for inst, L in zip(self.instances, consts):
            k = int(scene.geometry.mi_index[inst["shape"]])   # its place in Mitsuba's shapes()
            shape = shapes[k]
            sides = 2.0 if inst["twosided"] else 1.0
            if _is_triangle_mesh(shape):
                v, f, vn, uv = _mesh_arrays(shape)
                # Mitsuba's flip_normals flips both normals, not the winding.
                sg = ss = -1.0 if shape.has_flipped_normals() else 1.0
                P = v[f]                                       # (F, 3 vertices, 3)
                cr = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
                a2 = np.linalg.norm(cr, axis=1)
                ng = sg * cr / np.where(a2 > 0, a2, 1.0)[:, None]
                A = 0.5 * a2
                c = len(f)
                # The cone of the triangle's normals: its geometric normal, widened to
                # hold the vertex normals (which decide the side that emits).
                cos_o = np.ones(c)
                VN = np.zeros((c, 3, 3))
                if vn is not None:
                    VN = ss * vn[f]
                    unit = VN / np.maximum(np.linalg.norm(VN, axis=2, keepdims=True), 1e-30)
                    cos_o = np.minimum(1.0, np.einsum("fj,fkj->fk", ng, unit).min(axis=1))
                    cos_o = np.where(cos_o > 0, cos_o, -1.0)
                phi = np.where(a2 > 0, sides * np.pi * A * L, 0.0)
                self._bounds.append({"p_min": P.min(axis=1), "p_max": P.max(axis=1), "phi": phi, "w": ng,
                                     "cos_theta_o": cos_o, "cos_theta_e": np.zeros(c),
                                     "two_sided": np.full(c, inst["twosided"])})
                cols["kind"].append(np.full(c, TRIANGLE))
                cols["P"].append(P)
                cols["n"].append(ng)
                cols["vn"].append(VN)
                cols["uv"].append(uv[f] if uv is not None else np.full((c, 3, 2), np.nan))
                self._mesh.append(True)
            else:
                c = 1
                A = np.array([float(shape.surface_area()[0])])
                phi = sides * np.pi * A * L
                if shape.class_name() == "Rectangle":
                    P, ng = _rectangle(shape)
                    corners = np.vstack([P, P[1] + P[2] - P[0]])
                    lo, hi, w, cos_o = corners.min(axis=0), corners.max(axis=0), ng, 1.0
                    cols["kind"].append(np.full(1, PARALLELOGRAM))
                else:
                    bb = shape.bbox()
                    lo, hi = np.array(bb.min, dtype=np.float64), np.array(bb.max, dtype=np.float64)
                    w, cos_o = _shape_normal_cone(shape)
                    P, ng = np.zeros((3, 3)), np.zeros(3)
                    cols["kind"].append(np.full(1, MITSUBA))
                self._bounds.append({"p_min": lo, "p_max": hi, "phi": float(phi[0]), "w": w,
                                     "cos_theta_o": cos_o, "cos_theta_e": 0.0, "two_sided": inst["twosided"]})
                cols["P"].append(P[None])
                cols["n"].append(ng[None])
                cols["vn"].append(np.zeros((1, 3, 3)))
                cols["uv"].append(np.full((1, 3, 2), np.nan))
                self._mesh.append(False)
            self._power.append(phi)
            cols["area"].append(A)
            cols["radiance"].append(np.full(c, inst["radiance"]))
            cols["two"].append(np.full(c, inst["twosided"]))
            mitsuba = cols["kind"][-1][0] == MITSUBA
            if mitsuba:
                self.other_shapes.append(inst["shape"])
            cols["other"].append(np.full(c, len(self.other_shapes) - 1 if mitsuba else 0))
            self._count.append(c)
            self._first.append(o)
            o += c
        self.n_sub = o
        if not o:
            return
        cat = {k: np.concatenate(v) for k, v in cols.items()}
        f32 = np.float32
        self.radiance = mi.UInt32(cat["radiance"].astype(np.uint32))
        self.radiance_reach = tuple(int(x) for x in np.unique(cat["radiance"]))
        self.any_two = bool(cat["two"].any())
        self.two = mi.Bool(cat["two"])
        self.area = mi.Float(cat["area"].astype(f32))
        kind = cat["kind"]
        self.kinds = sorted(set(int(x) for x in np.unique(kind)))
        self.kind = mi.UInt32(kind.astype(np.uint32))
        self.geometry = scene.geometry
        self.other = mi.UInt32(cat["other"].astype(np.uint32))

        def points(a):                        # (n, 3) -> Point3f
            return mi.Point3f(*[mi.Float(np.ascontiguousarray(a[:, j], dtype=f32)) for j in range(3)])
        self.P = [points(cat["P"][:, v]) for v in range(3)]
        self.n = mi.Normal3f(points(cat["n"]))
        self.has_normals = bool(np.any(cat["vn"] != 0))
        if self.has_normals:
            self.vn = [mi.Normal3f(points(cat["vn"][:, v])) for v in range(3)]
        UV = cat["uv"]
        self.has_uv = bool(np.any(np.isfinite(UV)))
        if self.has_uv:
            self.uv_ok = mi.Bool(np.all(np.isfinite(UV), axis=(1, 2)))
            UV = np.nan_to_num(UV)
            self.uv = [mi.Point2f(*[mi.Float(np.ascontiguousarray(UV[:, v, j], dtype=f32)) for j in range(2)])
                       for v in range(3)]

    def power(self, i: int, scene):
        """Emitted power of instance ``i``: a float, or one value per triangle (array)."""
        p = self._power[i]
        return p if self._mesh[i] else float(p[0])

    def bounds(self, i: int, scene):
        """pbrt-v4 LightBounds of instance ``i`` (for meshes: a dict of per-triangle arrays)."""
        return self._bounds[i]

    # -- radiance and sampling -----------------------------------------------------------
    def _two_sided(self, idx, active):
        return dr.gather(mi.Bool, self.two, idx, active) if self.any_two else mi.Bool(False)

    def L(self, idx, si, wl, active):
        active = active & ((si.wi.z > 0) | self._two_sided(idx, active))
        slot = dr.gather(mi.UInt32, self.radiance, idx, active)
        return dr.select(active, self.textures.eval(slot, si.uv, wl.lambda_, active, reach=self.radiance_reach), 0.0)

    def _sample_planar(self, idx, u, active):
        """Uniform point on a triangle or parallelogram sub-light: (p, n, shading n, uv)."""
        p0, p1, p2 = (dr.gather(mi.Point3f, t, idx, active) for t in self.P)
        if TRIANGLE in self.kinds:
            t = dr.safe_sqrt(1.0 - u.x)
            b1, b2 = 1.0 - t, t * u.y
            if PARALLELOGRAM in self.kinds:
                par = dr.gather(mi.UInt32, self.kind, idx, active) == PARALLELOGRAM
                b1, b2 = dr.select(par, u.x, b1), dr.select(par, u.y, b2)
        else:
            b1, b2 = u.x, u.y
        p = dr.fma(p1 - p0, b1, dr.fma(p2 - p0, b2, p0))
        ng = dr.gather(mi.Normal3f, self.n, idx, active)
        ns = ng
        b0 = 1.0 - b1 - b2
        if self.has_normals:
            n0, n1, n2 = (dr.gather(mi.Normal3f, t_, idx, active) for t_ in self.vn)
            nsi = n0 * b0 + n1 * b1 + n2 * b2
            ns = dr.select(dr.squared_norm(nsi) > 0, dr.normalize(nsi), ng)
        uv = mi.Point2f(b1, b2)
        if self.has_uv:
            uv0, uv1, uv2 = (dr.gather(mi.Point2f, t_, idx, active) for t_ in self.uv)
            ok = dr.gather(mi.Bool, self.uv_ok, idx, active)
            uv = dr.select(ok, uv0 * b0 + uv1 * b1 + uv2 * b2, uv)
        return p, ng, ns, uv

    def _sample_point(self, idx, u, active, time=0.0):
        """Uniform point (by area) on sub-light ``idx``: (p, geometric n, shading n, uv)."""
        planar = (TRIANGLE in self.kinds) or (PARALLELOGRAM in self.kinds)
        if planar:
            p, ng, ns, uv = self._sample_planar(idx, u, active)
        if MITSUBA in self.kinds:
            # Other shapes through Mitsuba's sample_position.
            other = (dr.gather(mi.UInt32, self.kind, idx, active) == MITSUBA) if planar else mi.Bool(True)
            on = active & other
            k = dr.gather(mi.UInt32, self.other, idx, on)
            ps = self.geometry.sample_position(self.other_shapes, k, time, u, on)
            if planar:
                p, ng, ns, uv = (dr.select(other, a, b) for a, b in ((ps.p, p), (ps.n, ng), (ps.n, ns), (ps.uv, uv)))
            else:
                p, ng, ns, uv = ps.p, ps.n, ps.n, ps.uv
        return p, ng, ns, uv

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        p, ng, ns, uv = self._sample_point(idx, u, active, ref.time)
        area = dr.gather(mi.Float, self.area, idx, active)
        d = p - ref.p
        dist2 = dr.squared_norm(d)
        wi = d * dr.rsqrt(dist2)
        cos_g = dr.abs(dr.dot(ng, wi))
        front = (dr.dot(ns, wi) < 0) | self._two_sided(idx, active)
        active = active & front & (cos_g > 0) & (area > 0) & (dist2 > 0)
        pdf = dist2 / (cos_g * area)
        slot = dr.gather(mi.UInt32, self.radiance, idx, active)
        L = self.textures.eval(slot, uv, wl.lambda_, active, reach=self.radiance_reach)
        return LightSample(dr.select(active, L, 0.0), wi, dr.select(active, pdf, 0.0), p, mi.Bool(False))

    def pdf_Li(self, idx, ref_p, si, active):
        """Solid-angle density of reaching hit ``si`` from ``ref_p`` by sampling this light."""
        area = dr.gather(mi.Float, self.area, idx, active)
        d = si.p - ref_p
        dist2 = dr.squared_norm(d)
        cos_g = dr.abs(dr.dot(si.n, d)) * dr.rsqrt(dist2)
        ok = active & (cos_g > 0) & (area > 0)
        return dr.select(ok, dist2 / (cos_g * area), 0.0)

    # -- emission (light tracing) ----------------------------------------------------------
    emits_rays = True

    def sample_Le(self, idx, u_pos, u_dir, wl, active) -> LeSample:
        """A uniform point by area and a cosine-weighted direction about the shading normal
        (the side that emits, as in ``L``); ``n`` is the geometric normal turned to that side."""
        p, ng, ns, uv = self._sample_point(idx, u_pos, active)
        area = dr.gather(mi.Float, self.area, idx, active)
        two = self._two_sided(idx, active)
        back = two & (u_dir.x >= 0.5)            # two-sided: half the samples leave the back
        ux = dr.select(two, dr.minimum(dr.select(back, u_dir.x - 0.5, u_dir.x) * 2.0, 0.99999994), u_dir.x)
        local = square_to_cosine_hemisphere(mi.Point2f(ux, u_dir.y))
        d = mi.Frame3f(ns).to_world(local)
        d = dr.select(back, -d, d)
        n = dr.select(dr.dot(ng, ns) < 0, -ng, ng)
        n = dr.select(back, -n, n)
        ok = active & (area > 0) & (local.z > 0)
        slot = dr.gather(mi.UInt32, self.radiance, idx, ok)
        L = self.textures.eval(slot, uv, wl.lambda_, ok, reach=self.radiance_reach)
        return LeSample(o=p, d=d, L=dr.select(ok, L, 0.0), pdf_pos=dr.select(ok, dr.rcp(area), 0.0),
                        pdf_dir=dr.select(ok, cosine_hemisphere_pdf(local) * dr.select(two, 0.5, 1.0), 0.0),
                        n=mi.Normal3f(n))

    def pdf_Le(self, idx, p, n, d, active):
        """(area density of point ``p``, solid-angle density of direction ``d``) of
        ``sample_Le``; ``n``: the shading normal at ``p`` (e.g. ``si.sh_frame.n`` of a hit)."""
        area = dr.gather(mi.Float, self.area, idx, active)
        ok = active & (area > 0)
        two = self._two_sided(idx, active)
        cos = dr.select(two, 0.5 * dr.abs(dr.dot(n, d)), dr.maximum(dr.dot(n, d), 0.0))
        return (dr.select(ok, dr.rcp(area), 0.0), dr.select(ok, cos * dr.inv_pi, 0.0))
