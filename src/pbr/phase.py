"""Phase functions (shared by participating media and the layered BSDFs' inner medium).

Convention (pbrt-v4's and Mitsuba's): both directions point away from the scattering
point; ``wo`` toward where the path came from, ``wi`` the new direction. Forward
scattering (the path goes straight on, ``wi = -wo``) is therefore at
``dot(wo, wi) = -1``, where the Henyey-Greenstein lobe peaks for ``g > 0``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

# |g| close to 1 makes the lobe a numerical spike: clamp as pbrt-v4 does.
G_MAX = 0.99


def hg(cos_theta, g):
    """Henyey-Greenstein density (per steradian) at ``cos_theta = dot(wo, wi)``."""
    g = dr.clip(g, -G_MAX, G_MAX)
    d = dr.maximum(1.0 + g * g + 2.0 * g * cos_theta, 1e-12)
    return (1.0 - g * g) / (4.0 * dr.pi * d * dr.sqrt(d))


def hg_pdf(wo, wi, g):
    """Density of :func:`hg_sample` (equal to the phase function value)."""
    return hg(dr.dot(wo, wi), g)


def hg_sample(wo, g, u: mi.Point2f):
    """Sample a new direction ``wi`` for a path arriving along ``-wo``: (wi, pdf). The
    weight p / pdf is exactly 1."""
    g = dr.clip(g, -G_MAX, G_MAX)
    # mu: cosine between the forward direction (-wo) and wi; inverse of the HG CDF in mu
    # (uniform in mu where g is too small for the closed form to be accurate).
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x)
    mu_hg = (1.0 + g * g - s * s) / (2.0 * g)
    mu = dr.select(dr.abs(g) < 1e-3, 1.0 - 2.0 * u.x, mu_hg)
    mu = dr.clip(mu, -1.0, 1.0)
    sin_t = dr.safe_sqrt(1.0 - mu * mu)
    sp, cp = dr.sincos(2.0 * dr.pi * u.y)
    frame = mi.Frame3f(-wo)
    wi = frame.to_world(mi.Vector3f(sin_t * cp, sin_t * sp, mu))
    return wi, hg(-mu, g)
