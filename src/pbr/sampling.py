"""Warps from the unit square to directions and shapes (one implementation each)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi


def square_to_uniform_disk_concentric(u: mi.Point2f) -> mi.Point2f:
    """Shirley-Chiu concentric map of [0,1]^2 onto the unit disk."""
    x, y = 2.0 * u.x - 1.0, 2.0 * u.y - 1.0
    first = dr.abs(x) > dr.abs(y)
    r = dr.select(first, x, y)
    phi = dr.select(first, (dr.pi / 4) * y / x, (dr.pi / 2) - (dr.pi / 4) * x / y)
    phi = dr.select((x == 0) & (y == 0), 0.0, phi)
    s, c = dr.sincos(phi)
    return mi.Point2f(r * c, r * s)


def square_to_cosine_hemisphere(u: mi.Point2f) -> mi.Vector3f:
    """Cosine-weighted direction about +z (Malley's method)."""
    p = square_to_uniform_disk_concentric(u)
    z = dr.safe_sqrt(1.0 - dr.squared_norm(p))
    return mi.Vector3f(p.x, p.y, z)


def cosine_hemisphere_pdf(w: mi.Vector3f) -> mi.Float:
    return dr.maximum(w.z, 0.0) * dr.inv_pi


def power_heuristic(pdf_a, pdf_b):
    """MIS weight of strategy a (beta = 2); 0 where both densities vanish."""
    a2, b2 = pdf_a * pdf_a, pdf_b * pdf_b
    w = a2 / (a2 + b2)
    return dr.select(dr.isfinite(w), w, dr.select(dr.isinf(pdf_a), 1.0, 0.0))


def mix32(x):
    """A 32-bit integer hash (xor-shift-multiply avalanche), per lane: seeds of
    per-lane random streams and scrambles (layered BSDFs, samplers)."""
    x = x ^ (x >> 16)
    x = x * 0x21F0AAAD
    x = x ^ (x >> 15)
    x = x * 0x735A2D97
    return x ^ (x >> 15)
