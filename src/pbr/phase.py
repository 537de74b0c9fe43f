"""Phase functions (shared by participating media and the layered BSDFs' inner medium).

Convention (pbrt-v4's and Mitsuba's): both directions point away from the scattering
point; ``wo`` toward where the path came from, ``wi`` the new direction. Forward
scattering (the path goes straight on, ``wi = -wo``) is therefore at
``dot(wo, wi) = -1``, where the Henyey-Greenstein lobe peaks for ``g > 0``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .plugins.props import HG_ASYMMETRY
from .plugins.registry import Registry

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


def rayleigh(cos_theta):
    """Rayleigh phase function 3 (1 + cos^2) / (16 pi) (symmetric, so the direction
    convention does not matter)."""
    return (3.0 / (16.0 * dr.pi)) * (1.0 + cos_theta * cos_theta)


def rayleigh_sample(wo, u: mi.Point2f):
    """Sample ``wi`` from the Rayleigh phase function: (wi, pdf). The CDF of
    mu = cos(theta) is (mu^3 + 3 mu + 4) / 8, inverted in closed form (Cardano):
    mu = A - 1/A with A^3 = z + sqrt(z^2 + 1), z = 4u - 2."""
    z = 4.0 * u.x - 2.0
    a = dr.cbrt(z + dr.sqrt(z * z + 1.0))
    mu = dr.clip(a - dr.rcp(a), -1.0, 1.0)
    sin_t = dr.safe_sqrt(1.0 - mu * mu)
    sp, cp = dr.sincos(2.0 * dr.pi * u.y)
    wi = mi.Frame3f(-wo).to_world(mi.Vector3f(sin_t * cp, sin_t * sp, mu))
    return wi, rayleigh(mu)


# Phase function kinds of media (isotropic is HG with g = 0).
HG, RAYLEIGH = 0, 1

# Type name -> parser of a phase function plugin's Props into (kind, g).
PHASE_TYPES = Registry("phase")


@PHASE_TYPES.register("isotropic")
def _isotropic(props):
    """``isotropic``: no parameters (HG with g = 0)."""
    return HG, 0.0


@PHASE_TYPES.register("hg")
def _henyey_greenstein(props):
    """``hg``: the Henyey-Greenstein phase function.

    ====  =====  =======  ============================================
    name  type   default  meaning
    ====  =====  =======  ============================================
    g     float  0.8      mean cosine, in [-1, 1] (clamped to +-G_MAX)
    ====  =====  =======  ============================================
    """
    return HG, props.float("g", 0.8, valid=HG_ASYMMETRY)


@PHASE_TYPES.register("rayleigh")
def _rayleigh(props):
    """``rayleigh``: no parameters."""
    return RAYLEIGH, 0.0


def phase_eval(kind, g, wo, wi, kinds):
    """Value (= density) of the phase function ``kind`` (per lane) for the directions
    (wo, wi); ``kinds`` is the Python set of kinds present, so a scene without Rayleigh
    media has no Rayleigh code."""
    c = dr.dot(wo, wi)
    v = hg(c, g) if HG in kinds else mi.Float(0.0)
    if RAYLEIGH in kinds:
        v = dr.select(kind == RAYLEIGH, rayleigh(c), v) if HG in kinds else rayleigh(c)
    return v


def phase_sample(kind, g, wo, u: mi.Point2f, kinds):
    """Sample a new direction: (wi, pdf); the phase weight p / pdf is exactly 1."""
    if kinds == {RAYLEIGH}:
        return rayleigh_sample(wo, u)
    wi, pdf = hg_sample(wo, g, u)
    if RAYLEIGH in kinds:
        wr, pr = rayleigh_sample(wo, u)
        ray = kind == RAYLEIGH
        wi, pdf = dr.select(ray, wr, wi), dr.select(ray, pr, pdf)
    return wi, pdf
