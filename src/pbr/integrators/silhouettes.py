"""Silhouette curves of Mitsuba's analytic shapes (``sphere``, ``disk``, ``cylinder``) for
the projective integrators' boundary terms.

A triangle mesh's silhouettes lie on its edges, a fixed set; an analytic shape's depend
on the viewpoint. Each shape contributes curves parametrised by t in [0, 1), worked out
in the shape's local frame (Mitsuba's: unit sphere at the origin, unit disk in z = 0,
cylinder of radius 1 from z = 0 to z = 1) from the viewpoint brought into that frame,
then mapped by ``to_world`` (an affine map keeps lines tangent to a surface tangent;
a sphere's frame is Mitsuba's: its radius |to_world (1, 0, 0)| about the translation):

* sphere: the circle where rays from the viewpoint graze the sphere (none from inside);
* disk: its rim (a boundary: a discontinuity from every viewpoint off its plane);
* cylinder (open, as Mitsuba's): its two rims, and the two lines along its side where
  rays from the viewpoint graze it (none from inside the infinite cylinder).

The boundary's normal velocity is that of a material point: the curve's local point
mapped by the *attached* ``to_world``. At a point of a smooth silhouette the surface
normal is perpendicular both to the ray and to the curve, so the point's motion along
the surface, whichever way the curve was parametrised, adds nothing to it; on a rim the
motion along the ray and along the rim adds nothing either.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

SPHERE, RIM, SIDE = 0, 1, 2
# A viewpoint closer than this (squared local distance to the centre or the axis) is
# taken to be on the surface: no silhouette from there.
ON_SURFACE = 1.0 + 1e-3


def curve_kinds(shape):
    """The (kind, parameter) curves of ``shape``: the rim's z or the side's sign; None
    for shapes without analytic silhouettes here (meshes, curves, SDF grids...)."""
    t = shape.shape_type()
    if t == int(mi.ShapeType.Sphere):
        return [(SPHERE, 0.0)]
    if t == int(mi.ShapeType.Disk):
        return [(RIM, 0.0)]
    if t == int(mi.ShapeType.Cylinder):
        return [(RIM, 0.0), (RIM, 1.0), (SIDE, -1.0), (SIDE, 1.0)]
    return None


def _rows(flat, base):
    """The 3x4 affine matrix (rows of 4) stored at ``base`` of ``flat``."""
    return [[dr.gather(mi.Float, flat, base + 4 * r + c) for c in range(4)] for r in range(3)]


def _apply(m, p, w):
    """``m`` (3x4) times (p, w): w = 1 for points, 0 for vectors."""
    return mi.Vector3f(*[m[r][0] * p.x + m[r][1] * p.y + m[r][2] * p.z + (m[r][3] * w if w else 0.0)
                         for r in range(3)])


class CurveSet:
    """The silhouette curves of a scene's analytic shapes: curve ``k`` belongs to shape
    ``slot[k]`` and has a kind (:data:`SPHERE`, :data:`RIM`, :data:`SIDE`) and a
    parameter (a rim's local z, a side's sign)."""

    def __init__(self, shapes):
        self.shapes, kind, slot, param = [], [], [], []
        for shape in shapes:
            curves = curve_kinds(shape)
            if not curves:
                continue
            for k, prm in curves:
                kind.append(k); slot.append(len(self.shapes)); param.append(prm)
            self.shapes.append(shape)
        self.count = len(kind)
        if self.count:
            self.kind_np, self.slot_np = np.array(kind), np.array(slot)
            self.kind = mi.UInt32(np.array(kind, np.uint32))
            self.slot = mi.UInt32(np.array(slot, np.uint32))
            self.param = mi.Float(np.array(param, np.float32))

    def frames(self):
        """(to_world of every shape, attached; its inverse, detached): 12 floats (3x4,
        row-major) per shape."""
        n = len(self.shapes)
        m_acc, inv_acc = dr.zeros(mi.Float, 12 * n), dr.zeros(mi.Float, 12 * n)
        for s, shape in enumerate(self.shapes):
            T = mi.traverse(shape)["to_world"]
            m = T.matrix
            if shape.shape_type() == int(mi.ShapeType.Sphere):
                # Mitsuba renders a sphere of radius |to_world (1, 0, 0)| about the
                # translation, whatever else to_world holds (it warns about
                # non-uniform scales); rotations move no silhouette
                r = dr.norm(mi.Vector3f(m[0][0], m[1][0], m[2][0]))
                z = mi.Float(0.0)
                m = [[r, z, z, m[0][3]], [z, r, z, m[1][3]], [z, z, r, m[2][3]]]
                ir = dr.detach(dr.rcp(r))
                inv = [[ir, z, z, -dr.detach(m[0][3]) * ir], [z, ir, z, -dr.detach(m[1][3]) * ir],
                       [z, z, ir, -dr.detach(m[2][3]) * ir]]
            else:
                inv = dr.detach(T.inverse().matrix)
            for r in range(3):
                for c in range(4):
                    i = mi.UInt32(12 * s + 4 * r + c)
                    dr.scatter(m_acc, m[r][c], i)
                    dr.scatter(inv_acc, inv[r][c], i)
        return m_acc, inv_acc

    def point(self, frames, k, t, view, active):
        """Curve ``k`` at parameter ``t`` seen from ``view`` (world): (y, dy/dt in
        world space, whether the curve exists from there, the local point)."""
        M, Minv = frames
        kind = dr.gather(mi.UInt32, self.kind, k, active)
        base = dr.gather(mi.UInt32, self.slot, k, active) * 12
        prm = dr.gather(mi.Float, self.param, k, active)
        o = _apply(_rows(Minv, base), view, 1.0)
        phi = dr.two_pi * t
        s, c = dr.sincos(phi)
        # sphere: the circle of tangency from o (centre o / |o|^2, radius sqrt(1 - 1/|o|^2))
        d2 = dr.squared_norm(o)
        axis = o * dr.rsqrt(d2)
        u, v = mi.coordinate_system(axis)
        rho = dr.safe_sqrt(1.0 - dr.rcp(d2))
        y_sph = o / d2 + rho * (c * u + s * v)
        e_sph = dr.two_pi * rho * (c * v - s * u)
        # rim at height prm
        y_rim = mi.Vector3f(c, s, prm)
        e_rim = mi.Vector3f(-dr.two_pi * s, dr.two_pi * c, 0.0)
        # side line where rays from o graze the cylinder: its direction (cos, sin) solves
        # o_xy . (cos, sin) = 1; side prm = -1 or +1 of the plane through o and the axis
        r2 = dr.fma(o.x, o.x, o.y * o.y)
        rr = dr.sqrt(r2)
        nx, ny = o.x / rr, o.y / rr
        q = dr.safe_sqrt(1.0 - dr.rcp(r2))
        y_side = mi.Vector3f(nx / rr - prm * ny * q, ny / rr + prm * nx * q, t)
        e_side = mi.Vector3f(0.0, 0.0, 1.0)
        y_l = dr.select(kind == SPHERE, y_sph, dr.select(kind == RIM, y_rim, y_side))
        e_l = dr.select(kind == SPHERE, e_sph, dr.select(kind == RIM, e_rim, e_side))
        # (not from the surface itself: a hit point on it sees its tangent plane, where
        # the cosine is 0 and no light jumps; nor a rim from its own plane, a disk's hit
        # points)
        ok = active & dr.select(kind == SPHERE, d2 > ON_SURFACE,
                                dr.select(kind == RIM, dr.abs(o.z - prm) > ON_SURFACE - 1.0, r2 > ON_SURFACE))
        m = _rows(M, base)
        return mi.Point3f(_apply(m, y_l, 1.0)), _apply(m, e_l, 0.0), ok, y_l

    def attached(self, frames, k, y_l, active):
        """The material point at local ``y_l`` of curve ``k``'s shape, moved by the
        attached ``to_world`` of ``frames``."""
        base = dr.gather(mi.UInt32, self.slot, k, active) * 12
        return mi.Point3f(_apply(_rows(frames[0], base), y_l, 1.0))

    def lengths(self, frames) -> np.ndarray:
        """A length scale of every curve in world units (its size for a fixed curve,
        the shape's for a silhouette): relative probabilities of choosing them."""
        M = np.array(dr.detach(frames[0]), np.float64).reshape(-1, 3, 4)
        cols = np.linalg.norm(M[:, :, :3], axis=1)      # |to_world e_i| per local axis
        out = []
        for kind, slot, prm in zip(self.kind_np, self.slot_np, np.array(self.param)):
            if kind == SPHERE:
                out.append(2 * math.pi * cols[slot].mean())
            elif kind == RIM:
                out.append(2 * math.pi * cols[slot, :2].mean())
            else:
                out.append(cols[slot, 2])
        return np.asarray(out)
