"""``spot``: Mitsuba's spot light, shining along local +z of ``to_world`` with Mitsuba's
falloff (linear in the angle between ``beam_width`` and ``cutoff_angle``). Emission
and power: docs/lights.md.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..textures import load_spectrum
from .base import (LIGHT_TYPES, apply_rows, DeltaPositionLight, gather3, LeSample, light_frame, LightSample,
                   load_constant_emission, luminance, mat_rows, max_value, point_bounds, power_factor)


def spot_solid_angle(cutoff_rad: float, beam_rad: float) -> float:
    """Integral of the falloff over the sphere: the power of a unit-intensity spot."""
    if cutoff_rad - beam_rad < 1e-7:
        return 2.0 * math.pi * (1.0 - math.cos(cutoff_rad))
    return 2.0 * math.pi * (1.0 - (math.sin(cutoff_rad) - math.sin(beam_rad)) / (cutoff_rad - beam_rad))


@LIGHT_TYPES.register("spot")
class SpotLight(DeltaPositionLight):
    """``spot`` (Mitsuba's): a point light emitting into a cone with a smooth falloff,
    optionally modulated by a texture over the cone.

    ============  =========  ===========  ========================================================
    name          type       default      meaning
    ============  =========  ===========  ========================================================
    intensity     spectrum   1            radiant intensity at the centre of the beam (W/sr)
    cutoff_angle  float      20           half-angle of the cone (degrees)
    beam_width    float      0.75 cutoff  half-angle of the full-intensity core (degrees)
    texture       texture    -            a spatially varying texture projected over the cone
    to_world      transform  identity     light-to-world frame (the light looks down +z)
    scale         float      1            pbrt-v4's factor on the emitted spectrum
    power         float      -            pbrt-v4's total emitted power (W): rescales the spectrum
                                          (photometric: its luminance without the RGB multiplier)
    ============  =========  ===========  ========================================================
    """

    name = "spot"

    def add(self, loader, props, shape_index=None) -> int:
        slot = load_constant_emission(loader, props, "intensity")
        tex = None
        if props.has("texture"):
            tex = load_spectrum(loader, props.raw("texture"), props.key("texture"), emitter=False)
            if not loader.textures.spatially_varying(tex):
                raise props.error("texture", "must vary spatially (e.g. a bitmap); use 'intensity' for a constant")
        cutoff = props.float("cutoff_angle", 20.0, min=1e-4, max=180.0)
        beam = props.float("beam_width", cutoff * 0.75, min=0.0)
        if beam > cutoff:
            raise props.error("beam_width", f"must not exceed cutoff_angle ({cutoff}), got {beam}")
        m = light_frame(props)
        c_rad, b_rad = math.radians(cutoff), math.radians(beam)
        factor = power_factor(props, loader.textures, slot, spot_solid_angle(c_rad, b_rad))
        props.finish()
        self.instances.append({"slot": slot, "tex": tex, "to_world": m, "factor": factor,
                               "cutoff": c_rad, "beam": b_rad})
        return len(self.instances) - 1

    def build(self, scene) -> None:
        self._base_tables()
        I = self.instances
        self.inv_rows = mat_rows([np.linalg.inv(i["to_world"][:3, :3]) for i in I])
        self.cos_cutoff = mi.Float([math.cos(i["cutoff"]) for i in I])
        self.cos_beam = mi.Float([math.cos(i["beam"]) for i in I])
        self.cutoff_rad = mi.Float([i["cutoff"] for i in I])
        self.inv_transition = mi.Float([1.0 / (i["cutoff"] - i["beam"]) if i["cutoff"] > i["beam"] else 0.0
                                        for i in I])
        self.uv_factor = mi.Float([math.tan(i["cutoff"]) for i in I])
        self.any_texture = any(i["tex"] is not None for i in I)
        if self.any_texture:
            self.tex = mi.UInt32([i["tex"] if i["tex"] is not None else 0 for i in I])
            self.has_tex = mi.Bool([i["tex"] is not None for i in I])

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        phi = spot_solid_angle(inst["cutoff"], inst["beam"]) * inst["factor"] * luminance(scene.textures, inst["slot"])
        if inst["tex"] is not None:
            phi *= scene.textures.constant_value(inst["tex"])
        return phi

    def bounds(self, i: int, scene):
        inst = self.instances[i]
        phi = 4.0 * math.pi * inst["factor"] * max_value(scene.textures, inst["slot"])
        w = inst["to_world"][:3, :3] @ np.array([0.0, 0.0, 1.0])
        cos_e = math.cos(inst["cutoff"] - inst["beam"])
        if cos_e == 1.0 and inst["cutoff"] != inst["beam"]:
            cos_e = 0.999  # pbrt-v4's slop for round-off
        return point_bounds(self._position(i), w, phi, math.cos(inst["beam"]), cos_e)

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        p, wi, inv_dist2, ok = self._toward(idx, ref, active)
        local = apply_rows(self.inv_rows, idx, -wi, ok)
        cos_t = local.z * dr.rsqrt(dr.squared_norm(local))
        cos_c = dr.gather(mi.Float, self.cos_cutoff, idx, ok)
        cos_b = dr.gather(mi.Float, self.cos_beam, idx, ok)
        ramp = (dr.gather(mi.Float, self.cutoff_rad, idx, ok) - dr.safe_acos(cos_t)) * \
            dr.gather(mi.Float, self.inv_transition, idx, ok)
        falloff = dr.select(cos_t >= cos_b, 1.0, dr.clip(ramp, 0.0, 1.0))
        ok &= (cos_t > cos_c) & (falloff > 0)
        L = self._intensity(idx, wl, ok) * (falloff * inv_dist2)
        if self.any_texture:
            with_tex = ok & dr.gather(mi.Bool, self.has_tex, idx, ok)
            k = 0.5 * dr.rcp(local.z * dr.gather(mi.Float, self.uv_factor, idx, with_tex))
            uv = mi.Point2f(0.5 + local.x * k, 0.5 + local.y * k)
            t = self.textures.eval(dr.gather(mi.UInt32, self.tex, idx, with_tex), uv, wl.lambda_, with_tex,
                                   illuminant=False)
            L = dr.select(with_tex, L * t, L)
        return LightSample(dr.select(ok, L, 0.0), wi, dr.select(ok, 1.0, 0.0), p, mi.Bool(True))

    # -- emission (light tracing) ----------------------------------------------------------
    def _cone_ok(self) -> bool:
        """Cone sampling needs rigid frames (a sheared frame distorts the cone's density)."""
        return all(np.allclose(i["to_world"][:3, :3].T @ i["to_world"][:3, :3],
                               np.eye(3) * np.cbrt(np.linalg.det(i["to_world"][:3, :3])) ** 2, atol=1e-5)
                   for i in self.instances)

    def sample_Le(self, idx, u_pos, u_dir, wl, active):
        """A direction uniform inside the cutoff cone (pbrt-v4's ``SampleLe``), with the
        intensity that ``sample_Li`` delivers at distance 1."""
        if not self._cone_ok():
            return super().sample_Le(idx, u_pos, u_dir, wl, active)
        cos_c = dr.gather(mi.Float, self.cos_cutoff, idx, active)
        local = mi.warp.square_to_uniform_cone(u_dir, cos_c)
        fwd = [gather3(mi.Vector3f, row, idx, active) for row in self.fwd_rows()]
        d = dr.normalize(mi.Vector3f(dr.dot(fwd[0], local), dr.dot(fwd[1], local), dr.dot(fwd[2], local)))
        p = gather3(mi.Point3f, self.pos, idx, active)
        I, _ = self._intensity_along(idx, p, d, u_pos, wl, active)
        return LeSample(o=p, d=d, L=I, pdf_pos=mi.Float(1.0),
                        pdf_dir=dr.select(active, mi.warp.square_to_uniform_cone_pdf(local, cos_c), 0.0),
                        delta_pos=mi.Bool(True))

    def pdf_Le(self, idx, p, n, d, active):
        if not self._cone_ok():
            return super().pdf_Le(idx, p, n, d, active)
        local = apply_rows(self.inv_rows, idx, d, active)
        cos_t = local.z * dr.rsqrt(dr.squared_norm(local))
        cos_c = dr.gather(mi.Float, self.cos_cutoff, idx, active)
        inside = active & (cos_t >= cos_c)
        return mi.Float(1.0), dr.select(inside, dr.rcp(dr.two_pi * (1.0 - cos_c)), 0.0)

    def fwd_rows(self):
        """Rows of each instance's light-to-world 3x3 matrix."""
        return mat_rows([i["to_world"][:3, :3] for i in self.instances])
