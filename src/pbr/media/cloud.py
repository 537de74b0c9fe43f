"""pbrt-v4's procedural cloud density (``CloudMedium``): sums of Perlin noise, with the
lookup point perturbed by the noise's gradient ("wispiness"), falling off with height.
The density lies in [0, 1], so sigma_t is its majorant (pbr's majorant grid holds 1)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..textures.procedural import noise

_DELTA = 0.01          # pbrt-v4's DNoise: forward differences of this step


def _dnoise(perm, x, y, z):
    """pbrt-v4's ``DNoise``: the noise's gradient by forward differences."""
    n = noise(perm, x, y, z)
    inv = 1.0 / _DELTA
    return ((noise(perm, x + _DELTA, y, z) - n) * inv, (noise(perm, x, y + _DELTA, z) - n) * inv,
            (noise(perm, x, y, z + _DELTA) - n) * inv)


def cloud_density(perm, p: mi.Point3f, density, wispiness, frequency) -> mi.Float:
    """Density at medium-space point ``p`` for the parameters ``density``, ``wispiness``
    and ``frequency`` (pbrt-v4's ``CloudMedium::Density``)."""
    x, y, z = frequency * p.x, frequency * p.y, frequency * p.z
    v_omega, v_lambda = 0.05 * wispiness, 10.0
    for _ in range(2):                  # perturb the lookup point (no-op at wispiness 0)
        gx, gy, gz = _dnoise(perm, v_lambda * x, v_lambda * y, v_lambda * z)
        x, y, z = x + v_omega * gx, y + v_omega * gy, z + v_omega * gz
        v_omega, v_lambda = v_omega * 0.5, v_lambda * 1.99
    d = mi.Float(0.0)
    omega, lam = 0.5, 1.0
    for _ in range(5):
        d += omega * noise(perm, lam * x, lam * y, lam * z)
        omega, lam = omega * 0.5, lam * 1.99
    d = dr.clip((1.0 - p.y) * 4.5 * density * d, 0.0, 1.0)
    d += 2.0 * dr.maximum(0.0, 0.5 - p.y)
    return dr.clip(d, 0.0, 1.0)
