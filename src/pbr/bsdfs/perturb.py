"""Shading-frame perturbation: ``normalmap`` and ``bumpmap`` (Mitsuba's semantics).

Both wrap one BSDF and evaluate it in a perturbed frame, expressed in the unperturbed
local shading frame: directions are rotated into it, a direction on the other side of the
unperturbed and perturbed surfaces gets nothing (no light leaks), and Estevez et al.'s
shadowing term (Ray Tracing Gems, 2019) softens the terminator.

Bump mapping takes any texture as its height field h: a raw ``bitmap`` is differentiated
exactly (the gradient of its bilinear interpolation: Mitsuba's ``eval_1_grad``), any
other texture (procedural, ``imagemap``, combinators) by forward differences at shifted
points as pbrt-v4's ``BumpMap`` does (:func:`height_gradient`). One frame construction
(:func:`bumpmap_frame`) serves both, and pbrt-v4's material ``displacement``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..plugins.props import SceneError
from ..textures import Bitmap, load_spectrum
from ..textures.procedural import footprint, uv_differentials

# Perturbation kinds: a normal map, a bump map of a raw bitmap (exact gradient), a bump
# map of any other texture (forward differences).
NORMAL, BUMP, BUMP_DIFFERENCED = 1, 2, 3
# pbrt-v4's finite-difference step in u and v where the pixel footprint gives none.
DEFAULT_STEP = 0.0005


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


def height_gradient(textures, slot, si, lam, active, reach=None):
    """(dh/du, dh/dv) of height texture ``slot`` at ``si`` by forward differences
    (pbrt-v4's ``BumpMap``): h at the point shifted by du along dp/du with its uv shifted
    by (du, 0), likewise for v, minus h at the point, over the step. The steps are half
    the sum of |du/dx| and |du/dy| (|dv/dx|, |dv/dy|) of the render's pixel footprint,
    DEFAULT_STEP where that is 0 (no footprint, or a degenerate parametrisation). h is
    the texture's value at the first sampled wavelength (a float texture's value)."""
    dpdx, dpdy = footprint(textures, si, active)
    dudx, dudy, dvdx, dvdy = uv_differentials(si, dpdx, dpdy)
    du = 0.5 * (dr.abs(dudx) + dr.abs(dudy))
    dv = 0.5 * (dr.abs(dvdx) + dr.abs(dvdy))
    du = dr.select(du > 0, du, DEFAULT_STEP)
    dv = dr.select(dv > 0, dv, DEFAULT_STEP)

    def h(s):
        return textures.eval(slot, s, lam, active, illuminant=False, reach=reach)[0]

    def shifted(step, dp, duv):
        s = mi.SurfaceInteraction3f(si)
        s.p = si.p + dp * step
        s.uv = si.uv + duv * step
        return s

    h0 = h(si)
    return ((h(shifted(du, si.dp_du, mi.Vector2f(1.0, 0.0))) - h0) / du,
            (h(shifted(dv, si.dp_dv, mi.Vector2f(0.0, 1.0))) - h0) / dv)


def shadow_terminator(n_local, wo):
    """Estevez et al.'s shadowing term for a perturbed normal (in the unperturbed frame)."""
    tan2_n = dr.maximum(1.0 - n_local.z * n_local.z, 0.0) / (n_local.z * n_local.z)
    tan2_o = dr.maximum(1.0 - wo.z * wo.z, 0.0) / dr.maximum(wo.z * wo.z, 1e-30)
    alpha2 = dr.minimum(0.125 * tan2_n, 1.0)
    return 2.0 / (1.0 + dr.sqrt(1.0 + alpha2 * tan2_o))


def parse(loader, props, bsdf_like):
    """(kind, texture slot, scale, flip_invalid, shadowing, nested BSDF key) of a
    normalmap/bumpmap dict. A bump map's height texture may be any texture: a raw bitmap
    is differentiated exactly (BUMP), any other by forward differences (BUMP_DIFFERENCED)."""
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
    slot = load_spectrum(loader, props.raw(tex_key), props.key(tex_key), emitter=False, unbounded=True,
                         scalar=kind == BUMP)
    tex = loader.textures.items[slot]
    if kind == BUMP and not isinstance(tex, Bitmap):
        kind = BUMP_DIFFERENCED
        loader.textures.mark_differenced(slot)
    elif not isinstance(tex, Bitmap):
        raise props.error(tex_key, f"{props.type} needs a bitmap texture, got {type(tex).__name__}")
    else:
        loader.textures.mark_raw(slot)
    return kind, slot, scale, flip, shadow, bsdfs[0]


__all__ = ["NORMAL", "BUMP", "BUMP_DIFFERENCED", "normalmap_frame", "bumpmap_frame", "height_gradient",
           "shadow_terminator", "parse", "SceneError"]
