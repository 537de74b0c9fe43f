"""Lens systems of pbrt-v4's ``realistic`` camera: spherical element interfaces and an
aperture stop along the optical axis, traced in Dr.Jit.

A lens file (pbrt-v4's format) lists one interface per row: curvature radius, thickness
(the distance to the next interface toward the film), index of refraction of the medium
after it (0 or 1: air) and aperture diameter, in millimetres, front (scene side) first;
a curvature radius of 0 is the aperture stop. As in pbrt-v4, the film is at z = 0 and
the elements lie in front of it (camera space looks down +z); the tracing flips z into
pbrt-v4's lens space, where the system extends toward -z.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def read_lens_file(path: str) -> np.ndarray:
    """The (n, 4) rows of a pbrt-v4 lens file ('#' starts a comment)."""
    vals = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            vals += [float(x) for x in line.split("#", 1)[0].replace(",", " ").split()]
    if not vals or len(vals) % 4:
        raise ValueError(f"expected rows of 4 numbers (radius, thickness, eta, aperture), got {len(vals)} values")
    return np.asarray(vals, np.float64).reshape(-1, 4)


def _refract(wi, n, eta):
    """pbrt-v4's ``Refract``: (direction, ok) of ``wi`` (pointing away) through normal
    ``n`` with relative index ``eta`` (a Python float)."""
    cos_i = dr.dot(n, wi)
    flip = cos_i < 0.0
    e = dr.select(flip, 1.0 / eta, eta)
    cos_i = dr.abs(cos_i)
    n = dr.select(flip, -n, n)
    sin2_t = dr.maximum(0.0, 1.0 - cos_i * cos_i) / (e * e)
    ok = sin2_t < 1.0
    cos_t = dr.safe_sqrt(1.0 - sin2_t)
    return -wi / e + (cos_i / e - cos_t) * n, ok


def _sphere_hit(radius: float, z_center: float, o, d):
    """pbrt-v4's ``IntersectSphericalElement``: (t, normal facing -d, hit)."""
    oc = o - mi.Vector3f(0.0, 0.0, z_center)
    a = dr.squared_norm(d)
    b = 2.0 * dr.dot(d, oc)
    c = dr.squared_norm(oc) - radius * radius
    disc = b * b - 4.0 * a * c
    ok = disc >= 0.0
    root = dr.safe_sqrt(disc)
    q = dr.select(b < 0.0, -0.5 * (b - root), -0.5 * (b + root))
    t0, t1 = q / a, c / q
    t0, t1 = dr.minimum(t0, t1), dr.maximum(t0, t1)
    closer = (d.z > 0.0) != (radius < 0.0)
    t = dr.select(closer, t0, t1)
    ok &= t >= 0.0
    n = dr.normalize(oc + t * d)
    n = dr.select(dr.dot(n, -d) < 0.0, -n, n)
    return t, n, ok


class LensSystem:
    """Element interfaces (metres): ``radius``, ``thickness``, ``eta``, ``aperture``
    (radius), front first. The last thickness (rear element to film) is set by focusing."""

    def __init__(self, rows_mm: np.ndarray, aperture_diameter_mm: float):
        self.radius = (rows_mm[:, 0] / 1000.0).tolist()
        self.thickness = (rows_mm[:, 1] / 1000.0).tolist()
        self.eta = rows_mm[:, 2].tolist()
        ap = (rows_mm[:, 3] / 1000.0 / 2.0).tolist()
        for i, r in enumerate(self.radius):
            if r == 0.0:                    # the stop: the asked diameter, at most the file's
                ap[i] = min(ap[i], aperture_diameter_mm / 1000.0 / 2.0)
        self.aperture = ap

    @property
    def rear_z(self) -> float:
        return self.thickness[-1]

    @property
    def front_z(self) -> float:
        return sum(self.thickness)

    def _medium(self, i) -> float:
        e = self.eta[i] if 0 <= i < len(self.eta) else 0.0
        return e if e != 0.0 else 1.0

    def trace_from_film(self, o, d, active=True):
        """Camera-space ray from the film (z = 0) toward +z through the system: (origin,
        direction, ok) of the ray leaving the front element (pbrt-v4's
        ``TraceLensesFromFilm``)."""
        o = mi.Point3f(o.x, o.y, -o.z)
        d = mi.Vector3f(d.x, d.y, -d.z)
        ok = mi.Bool(active)
        z = 0.0
        for i in range(len(self.radius) - 1, -1, -1):
            z -= self.thickness[i]
            o, d, ok = self._element(i, z, o, d, ok, self._medium(i - 1) / self._medium(i))
        return mi.Point3f(o.x, o.y, -o.z), mi.Vector3f(d.x, d.y, -d.z), ok

    def trace_from_scene(self, o, d, active=True):
        """Camera-space ray from the scene side (toward -z) to the film side (pbrt-v4's
        ``TraceLensesFromScene``)."""
        o = mi.Point3f(o.x, o.y, -o.z)
        d = mi.Vector3f(d.x, d.y, -d.z)
        ok = mi.Bool(active)
        z = -self.front_z
        for i in range(len(self.radius)):
            o, d, ok = self._element(i, z, o, d, ok, self._medium(i) / self._medium(i - 1))
            z += self.thickness[i]
        return mi.Point3f(o.x, o.y, -o.z), mi.Vector3f(d.x, d.y, -d.z), ok

    def _element(self, i, z, o, d, ok, eta):
        """The ray (o, d) across element ``i``, its vertex at ``z``: the point where it
        meets the element, its direction after it (refracted with relative IOR ``eta``
        by a curved element; an aperture stop keeps it) and ``ok`` cleared where it
        misses the element or its aperture or is totally reflected."""
        if self.radius[i] == 0.0:
            t = (z - o.z) / d.z
            ok &= t >= 0.0
        else:
            t, n, hit = _sphere_hit(self.radius[i], z + self.radius[i], o, d)
            ok &= hit
        p = o + d * t
        ok &= p.x * p.x + p.y * p.y <= self.aperture[i] ** 2
        if self.radius[i] != 0.0:
            d, r_ok = _refract(dr.normalize(-d), n, eta)
            ok &= r_ok
        return mi.Point3f(p), d, ok

    # -- set-up (host side) -------------------------------------------------------------
    def _one(self, fn, o, d):
        ro, rd, ok = fn(mi.Point3f(*[mi.Float([c]) for c in o]), mi.Vector3f(*[mi.Float([c]) for c in d]))
        if not bool(ok[0]):
            return None
        return np.array(ro, np.float64).ravel(), np.array(rd, np.float64).ravel()

    def cardinal_points(self, film_diagonal: float):
        """((p', f'), (p, f)): principal planes and focal points of the scene-side and
        film-side rays parallel to the axis (pbrt-v4's thick-lens approximation)."""
        x = 0.001 * film_diagonal
        out = []
        for fn, o, d in ((self.trace_from_scene, (x, 0.0, self.front_z + 1.0), (0.0, 0.0, -1.0)),
                         (self.trace_from_film, (x, 0.0, self.rear_z - 1.0), (0.0, 0.0, 1.0))):
            r = self._one(fn, o, d)
            if r is None:
                raise ValueError("a ray parallel to the axis does not pass the lens system (is the aperture "
                                 "stop extremely small?)")
            ro, rd = r
            tf = -ro[0] / rd[0]
            fz = -(ro[2] + tf * rd[2])
            tp = (o[0] - ro[0]) / rd[0]
            pz = -(ro[2] + tp * rd[2])
            out.append((pz, fz))
        return out

    def focus(self, focus_distance: float, film_diagonal: float) -> None:
        """Set the rear element's distance to the film so that the plane at
        ``focus_distance`` is in focus (pbrt-v4's ``FocusThickLens``)."""
        (pz0, fz0), (pz1, _) = self.cardinal_points(film_diagonal)
        f = fz0 - pz0
        z = -focus_distance
        c = (pz1 - z - pz0) * (pz1 - z - 4.0 * f - pz0)
        if c <= 0.0:
            raise ValueError(f"the focus distance {focus_distance} m is too short for this lens system")
        delta = (pz1 - z + pz0 - np.sqrt(c)) / 2.0
        self.thickness[-1] += float(delta)
        self.focal_length = float(f)

    def exit_pupil_bounds(self, film_diagonal: float, n_segments: int = 64, n_samples: int = 1 << 14):
        """Per radial film segment, the bounds (x0, y0, x1, y1) of the points of the rear
        element's plane through which film points of the segment (on +x) reach the scene
        (pbrt-v4's ``BoundExitPupil``, with a stratified grid instead of the radical
        inverse); None where none does."""
        rr = self.aperture[-1]
        lo, hi = -1.5 * rr, 1.5 * rr
        k = int(np.sqrt(n_samples))
        g = (np.arange(k) + 0.5) / k
        gx, gy = np.meshgrid(lo + g * (hi - lo), lo + g * (hi - lo))
        bounds = []
        for s in range(n_segments):
            r0 = s / n_segments * film_diagonal / 2.0
            r1 = (s + 1) / n_segments * film_diagonal / 2.0
            fx = np.linspace(r0, r1, gx.size)
            np.random.default_rng(s).shuffle(fx)
            px, py = gx.ravel(), gy.ravel()
            o = mi.Point3f(mi.Float(fx), mi.Float(0.0), mi.Float(0.0))
            d = mi.Vector3f(mi.Float(px - fx), mi.Float(py), mi.Float(float(self.rear_z)))
            _, _, ok = self.trace_from_film(o, d)
            ok = np.array(ok, bool)
            if not ok.any():
                bounds.append(None)
                continue
            pad = 2.0 * np.hypot(hi - lo, hi - lo) / k
            bounds.append((px[ok].min() - pad, py[ok].min() - pad, px[ok].max() + pad, py[ok].max() + pad))
        return bounds
