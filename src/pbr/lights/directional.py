"""``directional`` (Mitsuba; pbrt-v4's ``distant``): parallel light along one direction,
a Dirac delta in direction. Units and emission: docs/lights.md.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .base import (LIGHT_TYPES, gather3, LeSample, LightSample, LightType, load_constant_emission, luminance,
                   photometric, vec_table)


def scene_sphere(scene):
    """(centre, radius) of the scene's bounding sphere (as LightSet computes it)."""
    bbox = scene.bbox()
    if not bbox.valid():
        return np.zeros(3), 1.0
    c = np.array(bbox.center(), dtype=np.float64)
    r = float(np.linalg.norm(np.array(bbox.max, dtype=np.float64) - c))
    return c, max(r, 1e-4)


@LIGHT_TYPES.register("directional")
class DirectionalLight(LightType):
    """``directional`` (Mitsuba's): light arriving from one direction, from infinitely far.

    ===========  =========  ========  ===================================================
    name         type       default   meaning
    ===========  =========  ========  ===================================================
    irradiance   spectrum   1         irradiance on a plane facing the light (W/m^2)
    direction    vector     -         the direction the light travels (or to_world's +z)
    to_world     transform  identity  instead of direction
    scale        float      1         factor on the spectrum
    illuminance  float      -         pbrt-v4's target illuminance: rescales the spectrum
    L, from, to  -          -         ``distant`` only (see DistantLight)
    ===========  =========  ========  ===================================================
    """

    name = "directional"
    delta = True
    pbrt_names = False

    def add(self, loader, props, shape_index=None) -> int:
        key = "irradiance"
        if self.pbrt_names and props.has("L"):
            if props.has("irradiance"):
                raise props.error("L", "give either 'L' or 'irradiance', not both")
            key = "L"
        slot = load_constant_emission(loader, props, key)
        given = [k for k in ("direction", "to_world") + (("from", "to") if self.pbrt_names else ()) if props.has(k)]
        if "direction" in given and len(given) > 1:
            raise props.error("direction", f"give only one of 'direction', 'to_world'"
                              f"{', from/to' if self.pbrt_names else ''}")
        if "to_world" in given and ("from" in given or "to" in given):
            raise props.error("to_world", "give either 'to_world' or 'from'/'to', not both")
        if props.has("direction"):
            d = props.vector3("direction")
        elif self.pbrt_names and ("from" in given or "to" in given):
            d = props.vector3("to", [0.0, 0.0, 1.0]) - props.vector3("from", [0.0, 0.0, 0.0])
        else:
            d = props.transform("to_world")[:3, :3] @ np.array([0.0, 0.0, 1.0])
        n = float(np.linalg.norm(d))
        if not n > 1e-12:
            raise props.error(given[0] if given else "direction", "the direction has zero length")
        sc = props.float("scale", 1.0)
        e_v = props.float("illuminance", -1.0)
        if e_v > 0:
            ph = photometric(loader.textures, slot)
            if not ph > 0:
                raise props.error("illuminance", "cannot reach a target illuminance with a black spectrum")
            sc *= e_v / ph
        props.finish()
        self.instances.append({"slot": slot, "d": d / n, "factor": sc})
        return len(self.instances) - 1

    def build(self, scene) -> None:
        I = self.instances
        self.dir = vec_table([i["d"] for i in I])
        self.slot = mi.UInt32([i["slot"] for i in I])
        self.factor = mi.Float([i["factor"] for i in I])
        c, r = scene_sphere(scene)
        self.center = mi.Point3f(*c.tolist())
        self.radius = float(r)

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        _, r = scene_sphere(scene)
        return math.pi * r * r * inst["factor"] * luminance(scene.textures, inst["slot"])

    def bounds(self, i: int, scene):
        return None

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        d = gather3(mi.Vector3f, self.dir, idx, active)
        r = dr.maximum(self.radius, dr.norm(ref.p - self.center))
        p = ref.p - d * (2.0 * r)
        slot = dr.gather(mi.UInt32, self.slot, idx, active)
        E = self.textures.eval(slot, mi.Point2f(0.5), wl.lambda_, active,
                               reach=tuple(int(i["slot"]) for i in self.instances)) * dr.gather(mi.Float, self.factor, idx, active)
        return LightSample(dr.select(active, E, 0.0), -d, dr.select(active, 1.0, 0.0), p, mi.Bool(True))


    # -- emission (light tracing) ----------------------------------------------------------
    emits_rays = True

    def sample_Le(self, idx, u_pos, u_dir, wl, active) -> LeSample:
        """A ray along the light's direction from a uniform point of the disk of the
        scene's bounding sphere that faces the light (pbrt-v4): ``pdf_pos = 1 / (pi r^2)``."""
        d = gather3(mi.Vector3f, self.dir, idx, active)
        disk = mi.warp.square_to_uniform_disk_concentric(u_pos)
        fr = mi.Frame3f(d)
        o = self.center + (fr.s * disk.x + fr.t * disk.y - d) * self.radius
        slot = dr.gather(mi.UInt32, self.slot, idx, active)
        E = self.textures.eval(slot, mi.Point2f(0.5), wl.lambda_, active,
                               reach=tuple(int(i["slot"]) for i in self.instances)) * dr.gather(mi.Float, self.factor, idx, active)
        return LeSample(o=o, d=d, L=dr.select(active, E, 0.0), pdf_pos=mi.Float(1.0 / (math.pi * self.radius ** 2)),
                        pdf_dir=mi.Float(1.0), n=mi.Normal3f(d), delta_dir=mi.Bool(True))

    def pdf_Le(self, idx, p, n, d, active):
        """(1 / (pi r^2), 1: the delta in direction, as ``sample_Le`` reports it)."""
        return mi.Float(1.0 / (math.pi * self.radius ** 2)), mi.Float(1.0)


@LIGHT_TYPES.register("distant")
class DistantLight(DirectionalLight):
    """``distant`` (pbrt-v4's): ``directional`` that also takes ``L`` (instead of
    ``irradiance``) and ``from``/``to`` (instead of ``direction``: default from (0, 0, 0)
    to (0, 0, 1)).
    """
    name = "distant"
    pbrt_names = True
