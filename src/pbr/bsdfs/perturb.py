"""Shading-frame perturbation: ``normalmap`` and ``bumpmap`` (Mitsuba's semantics).

Both wrap one BSDF and evaluate it in a perturbed frame, expressed in the unperturbed
local shading frame: directions are rotated into it, a direction on the other side of the
unperturbed and perturbed surfaces gets nothing (no light leaks), and Estevez et al.'s
shadowing term (Ray Tracing Gems, 2019) softens the terminator.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..plugins.props import SceneError
from ..textures import Bitmap, load_spectrum

NORMAL, BUMP = 1, 2


def _frame_from_normal(n, s_hint):
    """Orthonormal frame with normal n and first tangent along s_hint (Gram-Schmidt)."""
    s = dr.normalize(s_hint - n * dr.dot(n, s_hint))
    return mi.Frame3f(s, dr.cross(n, s), n)


def _flip_invalid(n, wi):
    """Keep the perturbed normal on the side of the incident direction."""
    flip = wi.z * dr.dot(wi, n) <= 0
    return mi.Vector3f(dr.select(flip, -n.x, n.x), dr.select(flip, -n.y, n.y), n.z)


def normalmap_frame(rgb, wi, flip_invalid: bool):
    """Local frame from a tangent-space normal map value in [0, 1]^3."""
    n = mi.Vector3f(rgb) * 2.0 - 1.0
    if flip_invalid:
        n = _flip_invalid(n, wi)
    n = dr.normalize(n)
    return _frame_from_normal(n, mi.Vector3f(1.0, 0.0, 0.0))


def bumpmap_frame(si, grad_u, grad_v, flip_invalid: bool):
    """Local frame of a surface displaced along its shading normal by a height field
    with gradient (grad_u, grad_v) w.r.t. the surface coordinates."""
    n_sh = si.sh_frame.n
    dp_du = si.dp_du + n_sh * (grad_u - dr.dot(n_sh, si.dp_du))
    dp_dv = si.dp_dv + n_sh * (grad_v - dr.dot(n_sh, si.dp_dv))
    n = dr.normalize(dr.cross(dp_du, dp_dv))
    n = dr.select(dr.dot(si.n, n) < 0, -n, n)
    n = si.to_local(n)
    if flip_invalid:
        n = _flip_invalid(n, si.wi)
    return _frame_from_normal(n, si.to_local(si.dp_du))


def shadow_terminator(n_local, wo):
    """Estevez et al.'s shadowing term for a perturbed normal (in the unperturbed frame)."""
    tan2_n = dr.maximum(1.0 - n_local.z * n_local.z, 0.0) / (n_local.z * n_local.z)
    tan2_o = dr.maximum(1.0 - wo.z * wo.z, 0.0) / dr.maximum(wo.z * wo.z, 1e-30)
    alpha2 = dr.minimum(0.125 * tan2_n, 1.0)
    return 2.0 / (1.0 + dr.sqrt(1.0 + alpha2 * tan2_o))


def parse(loader, props, bsdf_like):
    """(kind, texture slot, scale, flip_invalid, shadowing, nested BSDF key) of a
    normalmap/bumpmap dict."""
    kind = NORMAL if props.type == "normalmap" else BUMP
    flip = props.bool("flip_invalid_normals", True)
    shadow = props.bool("use_shadowing_function", True)
    bsdfs = [k for k, v in props.children() if v["type"] in bsdf_like or
             (v["type"] == "ref" and loader.resolve_ref(v.get("id"), props.key(k)).get("type") in bsdf_like)]
    if len(bsdfs) != 1:
        raise props.error(None, f"{props.type} takes exactly one nested BSDF, got {len(bsdfs)}")
    if kind == NORMAL:
        tex_key, scale = "normalmap", 1.0
        if not props.has(tex_key):
            raise props.error(tex_key, "missing the normal map texture (a raw bitmap)")
    else:
        scale = props.float("scale", 1.0)
        texs = [k for k, v in props.children() if k not in bsdfs]
        if len(texs) != 1:
            raise props.error(None, f"bumpmap takes exactly one nested (height) texture, got {len(texs)}")
        tex_key = texs[0]
    slot = load_spectrum(loader, props.raw(tex_key), props.key(tex_key), emitter=False, unbounded=True)
    tex = loader.textures.items[slot]
    if not isinstance(tex, Bitmap):
        raise props.error(tex_key, f"{props.type} needs a bitmap texture, got {type(tex).__name__}")
    loader.textures.mark_raw(slot)
    return kind, slot, scale, flip, shadow, bsdfs[0]


__all__ = ["NORMAL", "BUMP", "normalmap_frame", "bumpmap_frame", "shadow_terminator", "parse", "SceneError"]
