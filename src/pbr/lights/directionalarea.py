"""``directionalarea`` (Mitsuba 3): a shape that emits radiance ``radiance`` only along its
normal, so each point sends a parallel beam; the emitted power is ``radiance x area``
(Mitsuba's ``sample_ray`` weight), i.e. a receiver lit by the beam gets irradiance
``radiance |cos theta|``. The light is delta in direction: hitting it by chance has zero
probability, so ``L`` (emission seen on a hit) is 0, as Mitsuba's ``eval``.

Mitsuba's path tracer never connects to it (its ``sample_direction`` returns nothing),
so only its particle tracer renders it. pbr connects exactly on *planar* shapes
(rectangles, disks, flat meshes; detected at build time): from a reference point ``p``
in front of the plane, the only emitting point that reaches ``p`` is its orthogonal
projection, found by tracing the ray ``p - t n`` through the scene; it counts if the
first surface hit is the emitter itself (which also settles visibility). The sample is
a delta (``pdf = 1``, no MIS). On non-planar shapes there is no such unique point: those
contribute nothing to pbr's path tracer (as in Mitsuba's), with a warning.
"""

from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from ..textures import load_spectrum
from .base import LIGHT_TYPES, LightType, LightSample, LeSample


@LIGHT_TYPES.register("directionalarea")
class DirectionalAreaLight(LightType):
    """``directionalarea`` (Mitsuba's, on a shape): the surface emits along its normal only.

    ========  =======  =======  ===========================================
    name      type     default  meaning
    ========  =======  =======  ===========================================
    radiance  texture  1        emitted radiance
    to_world  -        -        not accepted: the shape's transform is used
    ========  =======  =======  ===========================================
    """

    name = "directionalarea"
    delta = True
    surface = True     # attached to a shape (as ``area``)
    traces_rays_in = ("sample_Li",)

    def add(self, loader, props, shape_index=None) -> int:
        if shape_index is None:
            raise props.error(None, "a 'directionalarea' emitter must be attached to a shape")
        if props.has("to_world"):
            raise props.error("to_world", "an area emitter inherits its transform from its shape")
        slot = load_spectrum(loader, props.raw("radiance", 1.0), props.key("radiance"), emitter=True)
        props.finish()
        self.instances.append({"radiance": slot, "shape": shape_index, "id": props.path})
        return len(self.instances) - 1

    @staticmethod
    def _plane(shape):
        """(normal, point, planar) from positions sampled over the shape."""
        k = 16
        g = (np.arange(k) + 0.5) / k
        uu, vv = np.meshgrid(g, g)
        ps = shape.sample_position(0.0, mi.Point2f(uu.ravel(), vv.ravel()))
        n = np.array(ps.n, dtype=np.float64).T
        p = np.array(ps.p, dtype=np.float64).T
        n0 = n[0] / np.linalg.norm(n[0])
        extent = max(float(np.ptp(p, axis=0).max()), 1e-6)
        planar = bool(np.all(np.abs(n - n0).max(axis=1) < 1e-4)
                      and np.all(np.abs((p - p[0]) @ n0) < 1e-5 * extent))
        return n0, p[0], planar

    def build(self, scene) -> None:
        normals, points, planar = [], [], []
        self._area = []
        for inst in self.instances:
            sh = scene.geometry.mi_shape(inst["shape"])
            n, p, ok = self._plane(sh)
            if not ok:
                warnings.warn(f"{inst['id']}: directionalarea on a non-planar shape is not sampled by "
                              "pbr's path tracer (it contributes nothing, as in Mitsuba's)", stacklevel=2)
            normals.append(n), points.append(p), planar.append(ok)
            self._area.append(float(sh.surface_area()[0]))
        self._normals = normals
        N, P = np.array(normals), np.array(points)
        self.normal = mi.Vector3f(N[:, 0], N[:, 1], N[:, 2])
        self.offset = mi.Float((N * P).sum(axis=1))          # plane: dot(n, x) = offset
        self.planar = mi.Bool(planar)
        self.radiance = mi.UInt32([i["radiance"] for i in self.instances])
        self.shape_index = mi.UInt32([i["shape"] for i in self.instances])
        self.geometry = scene.geometry
        self.any_planar = any(planar)

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        return self._area[i] * scene.textures.constant_value(inst["radiance"])

    def bounds(self, i: int, scene):
        """pbrt-v4 LightBounds: the shape's box, the emission direction (the normal), the
        power, and (nearly) zero-width cones of normals and emission directions."""
        bb = scene.geometry.mi_shape(self.instances[i]["shape"]).bbox()
        eps = float(np.cos(1e-3))   # a hair of slack against rounding in the BVH's cone tests
        return {"p_min": np.array(bb.min, dtype=np.float64), "p_max": np.array(bb.max, dtype=np.float64),
                "phi": self.power(i, scene), "w": self._normals[i], "cos_theta_o": eps, "cos_theta_e": eps,
                "two_sided": False}

    def L(self, idx, si, wl, active):
        return mi.Spectrum(0.0)

    def pdf_Li(self, idx, ref_p, si, active):
        return mi.Float(0.0)

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        if not self.any_planar:
            return LightSample(mi.Spectrum(0.0), mi.Vector3f(0, 0, 1), mi.Float(0.0), mi.Point3f(ref.p), mi.Bool(True))
        n = dr.gather(mi.Vector3f, self.normal, idx, active)
        h = dr.dot(n, ref.p) - dr.gather(mi.Float, self.offset, idx, active)
        active = active & dr.gather(mi.Bool, self.planar, idx, active) & (h > 0)
        wi = -n
        si, shape = self.geometry.intersect(ref.spawn_ray(wi), active)
        hit = active & si.is_valid() & (shape == dr.gather(mi.UInt32, self.shape_index, idx, active))
        slot = dr.gather(mi.UInt32, self.radiance, idx, hit)
        L = self.textures.eval(slot, si.uv, wl.lambda_, hit, reach=tuple(int(i["radiance"]) for i in self.instances))
        return LightSample(dr.select(hit, L, 0.0), wi, dr.select(hit, 1.0, 0.0), mi.Point3f(si.p), mi.Bool(True))

    # -- emission (light tracing) ----------------------------------------------------------
    emits_rays = True

    def sample_Le(self, idx, u_pos, u_dir, wl, active) -> LeSample:
        """A uniform point of the shape (by area) and the ray along its normal (Mitsuba's
        ``sample_ray``): ``pdf_pos = 1 / area``, a delta in direction."""
        ps = self.geometry.sample_position([i["shape"] for i in self.instances], idx, 0.0, u_pos, active)
        area = dr.gather(mi.Float, mi.Float(self._area), idx, active)
        ok = active & (area > 0)
        slot = dr.gather(mi.UInt32, self.radiance, idx, ok)
        L = self.textures.eval(slot, ps.uv, wl.lambda_, ok, reach=tuple(int(i["radiance"]) for i in self.instances))
        return LeSample(o=ps.p, d=mi.Vector3f(ps.n), L=dr.select(ok, L, 0.0),
                        pdf_pos=dr.select(ok, dr.rcp(area), 0.0), pdf_dir=mi.Float(1.0), n=mi.Normal3f(ps.n),
                        delta_dir=mi.Bool(True))

    def pdf_Le(self, idx, p, n, d, active):
        """(1 / area, 1: the delta in direction, as ``sample_Le`` reports it)."""
        area = dr.gather(mi.Float, mi.Float(self._area), idx, active)
        return dr.select(active & (area > 0), dr.rcp(area), 0.0), mi.Float(1.0)
