"""Animated transforms (pbrt-v4's ``AnimatedTransform``): an affine transform that moves
between ``m0`` at time ``t0`` and ``m1`` at time ``t1`` (held outside [t0, t1]).

Each end is split into a translation, a rotation (a unit quaternion) and a stretch (the
polar decomposition of its linear part); at a time between them the translation and
the stretch are interpolated linearly and the rotation by quaternion slerp, as pbrt-v4
does. Moving cameras (``cameras.py``) and moving shapes and instances (``geometry.py``)
use it: ``at(time)`` evaluates it per lane in a kernel, ``matrix(t)`` on the host."""

from __future__ import annotations

import math

import drjit as dr
import numpy as np


def polar(m: np.ndarray):
    """(translation, unit quaternion (w, x, y, z), stretch S) of an affine 4x4 ``m`` with
    linear part R S (R a rotation, S symmetric positive: the polar decomposition)."""
    a = m[:3, :3]
    u, sig, vt = np.linalg.svd(a)
    r = u @ vt
    if np.linalg.det(r) < 0:     # a reflection (e.g. pbrt-v4's Scale -1 1 1): keep it in S
        u[:, -1] = -u[:, -1]
        r = u @ vt
    stretch = r.T @ a
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2
    y = math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2
    z = math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2
    x = math.copysign(x, r[2, 1] - r[1, 2])
    y = math.copysign(y, r[0, 2] - r[2, 0])
    z = math.copysign(z, r[1, 0] - r[0, 1])
    return m[:3, 3].copy(), np.array([w, x, y, z]), stretch


def quat_matrix(q):
    """Rows of the rotation matrix of unit quaternion ``q`` = (w, x, y, z)."""
    w, x, y, z = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def inverse3(a):
    """Rows of the inverse of the 3x3 matrix with rows ``a`` (Python floats or Dr.Jit
    Floats), by its adjugate."""
    c = [[a[(j + 1) % 3][(i + 1) % 3] * a[(j + 2) % 3][(i + 2) % 3]
          - a[(j + 1) % 3][(i + 2) % 3] * a[(j + 2) % 3][(i + 1) % 3] for j in range(3)] for i in range(3)]
    inv_det = 1.0 / (a[0][0] * c[0][0] + a[0][1] * c[1][0] + a[0][2] * c[2][0])
    return [[c[i][j] * inv_det for j in range(3)] for i in range(3)]


class AnimatedTransform:
    """A transform moving from ``m0`` (4x4, at ``t0``) to ``m1`` (at ``t1`` > ``t0``)."""

    def __init__(self, m0: np.ndarray, m1: np.ndarray, t0: float, t1: float):
        self.m0, self.m1 = np.asarray(m0, np.float64), np.asarray(m1, np.float64)
        self.t0, self.t1 = float(t0), float(t1)
        self.tr0, q0, self.s0 = polar(self.m0)
        self.tr1, q1, self.s1 = polar(self.m1)
        if np.dot(q0, q1) < 0:
            q1 = -q1
        self.q0, self.q1 = q0, q1
        self.theta = math.acos(min(1.0, float(np.dot(q0, q1))))
        # Equal keys: the same motion (what moving shapes are grouped by).
        self.key = (self.m0.tobytes(), self.m1.tobytes(), self.t0, self.t1)

    def at(self, time):
        """(rows of the linear part, origin) at ``time`` (a Dr.Jit Float or a Python
        float): lists of the same type."""
        t = dr.clip((time - self.t0) / max(self.t1 - self.t0, 1e-30), 0.0, 1.0)
        if self.theta < 1e-4:
            q = [dr.lerp(float(a), float(b), t) for a, b in zip(self.q0, self.q1)]
            inv = dr.rsqrt(sum(c * c for c in q))
            q = [c * inv for c in q]
        else:
            s = 1.0 / math.sin(self.theta)
            wa, wb = dr.sin((1.0 - t) * self.theta) * s, dr.sin(t * self.theta) * s
            q = [wa * float(a) + wb * float(b) for a, b in zip(self.q0, self.q1)]
        r = quat_matrix(q)
        st = [[dr.lerp(float(self.s0[i, j]), float(self.s1[i, j]), t) for j in range(3)] for i in range(3)]
        lin = [[sum(r[i][k] * st[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
        o = [dr.lerp(float(a), float(b), t) for a, b in zip(self.tr0, self.tr1)]
        return lin, o

    def inverse_at(self, time):
        """(rows of the linear part, origin) of the inverse transform at ``time``."""
        lin, o = self.at(time)
        inv = inverse3(lin)
        return inv, [-(inv[i][0] * o[0] + inv[i][1] * o[1] + inv[i][2] * o[2]) for i in range(3)]

    def matrix(self, t: float) -> np.ndarray:
        """The 4x4 transform at time ``t`` (host side)."""
        lin, o = self.at(float(t))
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = np.array(lin, np.float64), o
        return m

    def motion_bounds(self, lo, hi, steps: int = 256):
        """(lo, hi) of a box that holds the box [lo, hi] (object space) at every time:
        its corners at ``steps`` + 1 times, padded by the largest step of a corner
        between two of them (the path between two times stays that close)."""
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        pts = np.stack([corners @ self.matrix(t).T for t in np.linspace(self.t0, self.t1, steps + 1)])[..., :3]
        pad = float(np.linalg.norm(np.diff(pts, axis=0), axis=-1).max(initial=0.0))
        return pts.reshape(-1, 3).min(axis=0) - pad, pts.reshape(-1, 3).max(axis=0) + pad
