"""``area``: a diffuse emitter attached to a shape, one-sided (it emits on the side its
normal points to, as Mitsuba's ``area``). Points are sampled uniformly by area on the
shape (through Mitsuba's shape sampling), so the solid-angle density is
``dist^2 / (|cos theta_l| A)``."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..textures import load_spectrum
from .base import LightType, LightSample


class AreaLight(LightType):
    name = "area"

    def add(self, loader, props, shape_index=None) -> int:
        slot = load_spectrum(loader, props.raw("radiance", 1.0), props.key("radiance"), emitter=True)
        props.finish()
        self.instances.append({"radiance": slot, "shape": shape_index})
        return len(self.instances) - 1

    def build(self, scene) -> None:
        shapes = scene.mi_scene.shapes()
        self.shape_index = mi.UInt32([i["shape"] for i in self.instances])
        self.radiance = mi.UInt32([i["radiance"] for i in self.instances])
        self.area = mi.Float([shapes[i["shape"]].surface_area()[0] for i in self.instances])
        self.shape_ptrs = scene.mi_scene.shapes_dr()

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        area = float(scene.mi_scene.shapes()[inst["shape"]].surface_area()[0])
        return np.pi * area * scene.textures.constant_value(inst["radiance"])

    def L(self, idx, si, wl, active):
        active = active & (si.wi.z > 0)
        slot = dr.gather(mi.UInt32, self.radiance, idx, active)
        return dr.select(active, self.textures.eval(slot, si.uv, wl.lambda_, active), 0.0)

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        shape = dr.gather(mi.ShapePtr, self.shape_ptrs, dr.gather(mi.UInt32, self.shape_index, idx, active), active)
        ps = shape.sample_position(ref.time, u, active)
        d = ps.p - ref.p
        dist2 = dr.squared_norm(d)
        wi = d * dr.rsqrt(dist2)
        cos_l = -dr.dot(ps.n, wi)
        active = active & (cos_l > 0) & (ps.pdf > 0)
        pdf = ps.pdf * dist2 / cos_l
        slot = dr.gather(mi.UInt32, self.radiance, idx, active)
        L = self.textures.eval(slot, ps.uv, wl.lambda_, active)
        return LightSample(dr.select(active, L, 0.0), wi, dr.select(active, pdf, 0.0), ps.p, mi.Bool(False))

    def pdf_Li(self, idx, ref_p, si, active):
        """Solid-angle density of reaching hit ``si`` from ``ref_p`` by sampling this light."""
        area = dr.gather(mi.Float, self.area, idx, active)
        cos_l = dr.abs(si.wi.z)
        dist2 = dr.squared_norm(si.p - ref_p)
        return dr.select(active & (cos_l > 0), dist2 / (cos_l * area), 0.0)
