"""Image-projecting delta lights: Mitsuba's ``projector`` and pbrt-v4's ``projection``, a
pinhole at the origin of ``to_world`` projecting along local +z with the perspective
camera's pixel mapping. Radiometry of each: docs/lights.md.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..cameras import _x_fov
from ..plugins.props import RADIANCE, Props
from ..textures import load_spectrum, Bitmap
from .base import (LIGHT_TYPES, apply_rows, DeltaPositionLight, gather3, light_frame, LightSample, luminance,
                   mat_rows, max_value, point_bounds, vec_table)


def _image_luminance(textures, slot):
    """(luminance, max channel), two (H, W) arrays, of a bitmap slot; None for other textures."""
    t = textures.items[slot]
    if not isinstance(t, Bitmap):
        return None
    a = np.asarray(t.params["data"], dtype=np.float64)
    a = a.reshape(t.height, t.width, -1)
    if a.shape[2] >= 3:
        return np.maximum(spec.luminance_rgb(np.moveaxis(a[..., :3], -1, 0)), 0.0), np.max(a[..., :3], axis=2)
    return np.maximum(a[..., 0], 0.0), np.maximum(a[..., 0], 0.0)


def _is_texture_plugin(loader, v) -> bool:
    while isinstance(v, dict) and v.get("type") == "ref":
        v = loader.ids.get(v.get("id"), ({},))[0]
    return isinstance(v, dict) and v.get("type") in ("bitmap", "checkerboard")


@LIGHT_TYPES.register("projector")
class ProjectorLight(DeltaPositionLight):
    """``projector`` (Mitsuba's): a pinhole projecting an image.

    ============  =========  ========  ========================================================
    name          type       default   meaning
    ============  =========  ========  ========================================================
    irradiance    texture    1         the projected image (a bitmap texture), or a spectrum
    fov           float      -         field of view (degrees; default: a 50 mm focal length)
    fov_axis      string     'x'       axis of fov, as the perspective camera's
    focal_length  string     '50mm'    instead of fov
    filename      -          -         ``projection`` only
    to_world      transform  identity  light-to-world frame (the light looks down +z)
    scale         float      1         pbrt-v4's factor on the emitted spectrum
    power         float      -         pbrt-v4's total emitted power (W): rescales the spectrum
                                       (photometric: its luminance without the RGB multiplier)
    ============  =========  ========  ========================================================
    """

    name = "projector"
    pbrt = False   # pbrt-v4's radiometry and parameters (``projection``)

    def add(self, loader, props, shape_index=None) -> int:
        if self.pbrt:
            fname = props.string("filename")
            img = {"type": "bitmap", "filename": fname, "filter_type": "nearest", "wrap_mode": "clamp"}
            slot = load_spectrum(loader, img, props.key("image"), emitter=True)
        else:
            v = props.raw("irradiance", 1.0)
            slot = load_spectrum(loader, v, props.key("irradiance"), emitter=not _is_texture_plugin(loader, v),
                                 valid=RADIANCE)
        t = loader.textures.items[slot]
        w, h = (t.width, t.height) if isinstance(t, Bitmap) else (1, 1)
        aspect = w / h
        if self.pbrt:
            fov = props.float("fov", 90.0, min=1e-4, max=179.99)
            tan_x = math.tan(math.radians(fov) / 2) * max(aspect, 1.0)
        else:
            if not props.has("fov") and not props.has("focal_length"):
                x_fov = _x_fov(Props({"type": "projector", "focal_length": "50mm"}, props.path), aspect)
            else:
                x_fov = _x_fov(props, aspect)
            tan_x = math.tan(math.radians(x_fov) / 2)
        tan_y = tan_x / aspect
        m = light_frame(props)
        inst = {"slot": slot, "to_world": m, "tan": (tan_x, tan_y), "res": (w, h)}
        self.instances.append(inst)
        sc = props.float("scale", 1.0)
        p = props.float("power", -1.0)
        props.finish()
        if p > 0:
            k = self._power_unit(inst, loader.textures)
            if not k > 0:
                raise props.error("power", "cannot reach a target power with a black image")
            sc *= p / k
        inst["factor"] = sc
        return len(self.instances) - 1

    def _power_unit(self, inst, textures) -> float:
        """Emitted power (luminance) per unit ``scale``."""
        tan_x, tan_y = inst["tan"]
        area = 4.0 * tan_x * tan_y
        img = _image_luminance(textures, inst["slot"])
        if img is None:
            e = luminance(textures, inst["slot"])
            if self.pbrt:  # mean of cos^3 over the image plane (analytic: the solid angle / A)
                return e * 4.0 * math.atan(tan_x * tan_y / math.sqrt(1 + tan_x ** 2 + tan_y ** 2))
            return math.pi * area * e
        e = img[0]
        if self.pbrt:
            h, w = e.shape
            x = (1 - 2 * (np.arange(w) + 0.5) / w) * tan_x
            y = (1 - 2 * (np.arange(h) + 0.5) / h) * tan_y
            cos3 = (1.0 + x[None, :] ** 2 + y[:, None] ** 2) ** -1.5
            return area * float(np.mean(e * cos3))
        return math.pi * area * float(np.mean(e))

    def build(self, scene) -> None:
        self._base_tables()
        I = self.instances
        inv = [np.linalg.inv(i["to_world"]) for i in I]
        self.inv_rows = mat_rows([a[:3, :3] for a in inv])
        self.inv_t = vec_table([a[:3, 3] for a in inv])
        self.n_world = vec_table([i["to_world"][:3, :3] @ np.array([0.0, 0.0, 1.0]) for i in I])
        self.tan_x = mi.Float([i["tan"][0] for i in I])
        self.tan_y = mi.Float([i["tan"][1] for i in I])

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        return inst["factor"] * self._power_unit(inst, scene.textures)

    def bounds(self, i: int, scene):
        inst = self.instances[i]
        tan_x, tan_y = inst["tan"]
        img = _image_luminance(scene.textures, inst["slot"])
        e = max_value(scene.textures, inst["slot"]) if img is None else float(np.mean(img[1]))
        phi = 4.0 * math.pi * inst["factor"] * e * (1.0 if self.pbrt else math.pi)
        w = inst["to_world"][:3, :3] @ np.array([0.0, 0.0, 1.0])
        return point_bounds(self._position(i), w, phi, 1.0, 1.0 / math.sqrt(1.0 + tan_x ** 2 + tan_y ** 2))

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        p, wi, inv_dist2, ok = self._toward(idx, ref, active)
        t = gather3(mi.Vector3f, self.inv_t, idx, ok)
        local = apply_rows(self.inv_rows, idx, mi.Vector3f(ref.p), ok) + t
        inv_z = dr.rcp(local.z)
        uv = mi.Point2f(0.5 - 0.5 * local.x * inv_z / dr.gather(mi.Float, self.tan_x, idx, ok),
                        0.5 - 0.5 * local.y * inv_z / dr.gather(mi.Float, self.tan_y, idx, ok))
        if self.pbrt:
            ok &= local.z >= 1e-3 * dr.norm(local)
        else:
            ok &= local.z > 0
        ok &= (uv.x >= 0) & (uv.x <= 1) & (uv.y >= 0) & (uv.y <= 1)
        slot = dr.gather(mi.UInt32, self.slot, idx, ok)
        E = self.textures.eval(slot, uv, wl.lambda_, ok, reach=tuple(int(i["slot"]) for i in self.instances)) * dr.gather(mi.Float, self.factor, idx, ok)
        if self.pbrt:
            L = E * inv_dist2
        else:
            cos_n = -dr.dot(gather3(mi.Vector3f, self.n_world, idx, ok), wi)
            ok &= cos_n > 0
            L = E * (math.pi * dr.rcp(dr.square(local.z) * cos_n))
        return LightSample(dr.select(ok, L, 0.0), wi, dr.select(ok, 1.0, 0.0), p, mi.Bool(True))


@LIGHT_TYPES.register("projection")
class ProjectionLight(ProjectorLight):
    """``projection`` (pbrt-v4's): a pinhole projecting an image file, with pbrt-v4's
    radiometry.

    ========  =========  ========  ========================================================
    name      type       default   meaning
    ========  =========  ========  ========================================================
    filename  string     -         the image (required)
    fov       float      90        field of view of the image's shorter side (degrees)
    to_world  transform  identity  light-to-world frame (the light looks down +z)
    scale     float      1         pbrt-v4's factor on the emitted spectrum
    power     float      -         pbrt-v4's total emitted power (W): rescales the spectrum
                                   (photometric: its luminance without the RGB multiplier)
    ========  =========  ========  ========================================================
    """
    name = "projection"
    pbrt = True
