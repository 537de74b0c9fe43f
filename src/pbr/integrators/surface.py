"""What a camera ray sees first, as per-sample channels: the ``aov`` integrator's
outputs and the ``gbuffer`` film's surface channels."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .. import spectrum as spec
from ..bsdfs.base import ShadingContext


def surface_channels(scene, rng, ray, wl, kinds, active, frame=None) -> list:
    """Per-sample channels (list of ``mi.Float``) of the surface ``ray`` sees, for each
    AOV type in ``kinds`` (depth, position, uv, geo_normal, sh_normal, dp_du, dp_dv,
    prim_index, shape_index, albedo; 0 where the ray escapes). ``frame``: a function
    mapping (point or vector, is_point) to another frame (the gbuffer's camera space)."""
    si, shape = scene.geometry.intersect(ray, active)
    hit = active & si.is_valid()
    bsdfs = scene.bsdfs
    bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
    ctx = ShadingContext(si, wl)
    out = []
    for kind in kinds:
        if kind == "depth":
            v = [si.t]
        elif kind == "position":
            v = list(si.p if frame is None else frame(si.p, True))
        elif kind == "uv":
            v = list(si.uv)
        elif kind == "geo_normal":
            v = list(si.n if frame is None else frame(si.n, False))
        elif kind == "sh_normal":
            n = bsdfs.shading_normal(bsdf_id, ctx, hit)
            v = list(n if frame is None else frame(n, False))
        elif kind == "dp_du":
            v = list(si.dp_du)
        elif kind == "dp_dv":
            v = list(si.dp_dv)
        elif kind == "prim_index":
            v = [mi.Float(si.prim_index)]
        elif kind == "shape_index":
            v = [mi.Float(shape + 1)]
        else:   # albedo
            u1 = rng.next_float32()
            u2 = rng.next_2d()
            bs = bsdfs.sample(bsdf_id, ctx, u1, u2, hit)
            rho = dr.select(bs.pdf > 0, bs.weight, 0.0)
            v = list(spec.xyz_to_srgb(spec.to_xyz(rho, wl)))
        out += [dr.select(hit, mi.Float(c), 0.0) for c in v]
    return out
