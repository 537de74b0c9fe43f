"""Microfacet distributions (Trowbridge-Reitz/GGX and Beckmann), isotropic or anisotropic,
with visible-normal sampling: the one implementation every rough BSDF uses.

All vectors are in the local shading frame (normal +z). ``alpha_u``/``alpha_v`` are the
roughness along x/y. Smith's masking uses the same approximations as Mitsuba 3
(exact for GGX, the rational fit for Beckmann), so rough BSDFs agree with it.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..sampling import square_to_uniform_disk_concentric
from ..spectrum import clamp_keep_grad

GGX, BECKMANN = "ggx", "beckmann"
# pbrt-v4's regularised roughness of smooth interfaces (alpha 0 -> clamp(0, 0.1, 0.3)),
# and the distribution they are given (pbrt-v4 has Trowbridge-Reitz only).
REGULARIZED_ALPHA = 0.1
REGULARIZED_VARIANT = (GGX, True)


def regularized_alpha(alpha, mask):
    """pbrt-v4's ``TrowbridgeReitzDistribution::Regularize`` where ``mask``: a roughness
    below 0.3 becomes clamp(2 alpha, 0.1, 0.3)."""
    return dr.select(mask & (alpha < 0.3), dr.clip(2.0 * alpha, REGULARIZED_ALPHA, 0.3), alpha)


class Microfacet:
    def __init__(self, kind: str, alpha_u, alpha_v, sample_visible: bool = True):
        self.kind = kind
        # Very small roughness underflows (alpha^4 in D): clamp as pbrt-v4 and Mitsuba do.
        # Below the clamp the derivative is the one at 1e-4 (d/d alpha was 0 there, while
        # the image does change as alpha rises through it).
        self.au = clamp_keep_grad(alpha_u, 1e-4)
        self.av = clamp_keep_grad(alpha_v, 1e-4)
        self.sample_visible = sample_visible

    def D(self, m):
        """Normal distribution (projected area density w.r.t. solid angle of m)."""
        au, av = self.au, self.av
        cos2 = m.z * m.z
        if self.kind == BECKMANN:
            e = -((m.x / au) ** 2 + (m.y / av) ** 2) / cos2
            r = dr.exp(e) / (dr.pi * au * av * cos2 * cos2)
        else:
            t = (m.x / au) ** 2 + (m.y / av) ** 2 + cos2
            r = dr.rcp(dr.pi * au * av * t * t)
        r = dr.select(m.z > 0, r, 0.0)
        return dr.select(r * m.z > 1e-20, r, 0.0)

    def G1(self, v, m):
        """Smith's masking function for direction v and microfacet normal m."""
        xy2 = (self.au * v.x) ** 2 + (self.av * v.y) ** 2
        tan2 = xy2 / (v.z * v.z)
        if self.kind == BECKMANN:
            a = dr.rsqrt(tan2)
            r = dr.select(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            r = 2.0 / (1.0 + dr.sqrt(1.0 + tan2))
        r = dr.select(xy2 == 0, 1.0, r)
        return dr.select(dr.dot(v, m) * v.z <= 0, 0.0, r)

    def G(self, wi, wo, m):
        return self.G1(wi, m) * self.G1(wo, m)

    def pdf(self, wi, m):
        """Density of ``sample(wi)`` returning m (solid angle of m)."""
        if self.sample_visible:
            r = self.D(m) * self.G1(wi, m) * dr.abs(dr.dot(wi, m)) / dr.abs(wi.z)
        else:
            r = self.D(m) * m.z
        return dr.select(dr.isfinite(r), r, 0.0)

    def _beckmann_visible(self, wi, u: mi.Point2f):
        """A visible normal of the Beckmann distribution (Heitz and d'Eon 2014): stretch
        ``wi`` to unit roughness, sample the slope distribution seen from it (the x slope
        by Newton's method on its CDF in the erf domain, as Mitsuba does, starting from
        the exact solution at grazing incidence), rotate and unstretch."""
        s = dr.select(wi.z < 0, -1.0, 1.0)
        v = dr.normalize(mi.Vector3f(self.au * wi.x * s, self.av * wi.y * s, wi.z * s))
        # sin from the x, y components, not sqrt(1 - cos^2): for tiny roughness v is within
        # an ulp or two of +z, and 1 - v.z^2 is quantised to multiples of 1.2e-7 (the
        # slope distribution then did not match the pdf: E[d log pdf / d alpha] was
        # -8906 at alpha 1e-4 instead of 0, and roughness gradients were biased)
        sin_t = dr.sqrt(dr.fma(v.x, v.x, v.y * v.y))
        inv_sin = dr.select(sin_t > 0, dr.rcp(sin_t), 0.0)
        cos_phi = dr.select(sin_t > 0, v.x * inv_sin, 1.0)
        sin_phi = dr.select(sin_t > 0, v.y * inv_sin, 0.0)
        tan_t = sin_t / v.z
        cot_t = dr.rcp(tan_t)
        top = dr.erf(cot_t)
        ux = dr.clip(u.x, 1e-6, 1.0 - 1e-6)
        uy = dr.clip(u.y, 1e-6, 1.0 - 1e-6)
        x = top - (top + 1.0) * dr.erf(dr.sqrt(-dr.log(ux)))
        target = ux * (1.0 + top + tan_t * dr.exp(-cot_t * cot_t) / dr.sqrt(dr.pi))
        for _ in range(3):
            slope = dr.erfinv(x)
            value = 1.0 + x + tan_t * dr.exp(-slope * slope) / dr.sqrt(dr.pi) - target
            x = x - value / (1.0 - slope * tan_t)
        sx, sy = dr.erfinv(x), dr.erfinv(2.0 * uy - 1.0)
        mx = (cos_phi * sx - sin_phi * sy) * self.au
        my = (sin_phi * sx + cos_phi * sy) * self.av
        return dr.normalize(mi.Vector3f(-mx, -my, 1.0))

    def sample(self, wi, u: mi.Point2f):
        """Sample a microfacet normal: visible normals when ``sample_visible`` (Heitz 2018
        for GGX; Heitz and d'Eon 2014 for Beckmann), otherwise D(m) cos(theta_m)."""
        if self.sample_visible and self.kind == BECKMANN:
            m = self._beckmann_visible(wi, u)
        elif self.sample_visible:
            # Stretch wi to the unit-roughness configuration (upper hemisphere).
            s = dr.select(wi.z < 0, -1.0, 1.0)
            v = dr.normalize(mi.Vector3f(self.au * wi.x * s, self.av * wi.y * s, wi.z * s))
            # Sample the projected hemisphere seen from v.
            p = square_to_uniform_disk_concentric(u)
            t1, t2 = p.x, p.y
            h = 0.5 * (1.0 + v.z)
            t2 = (1.0 - h) * dr.safe_sqrt(1.0 - t1 * t1) + h * t2
            lensq = v.x * v.x + v.y * v.y
            inv = dr.rsqrt(dr.maximum(lensq, 1e-30))
            T1 = dr.select(lensq > 0, mi.Vector3f(-v.y * inv, v.x * inv, 0.0), mi.Vector3f(1.0, 0.0, 0.0))
            T2 = dr.cross(v, T1)
            nh = t1 * T1 + t2 * T2 + dr.safe_sqrt(1.0 - t1 * t1 - t2 * t2) * v
            m = dr.normalize(mi.Vector3f(self.au * nh.x, self.av * nh.y, dr.maximum(nh.z, 1e-6)))
        else:
            # Sample D(m) cos(theta_m): tan^2(theta) from the marginal, phi (anisotropic) from the conditional.
            phi_u = 2.0 * dr.pi * u.y
            sp, cp = dr.sincos(phi_u)
            # Anisotropic azimuth: phi = atan(av/au tan(phi_u)), keeping the quadrant.
            phi = dr.atan2(self.av * sp, self.au * cp)
            sphi, cphi = dr.sincos(phi)
            a2 = dr.rcp((cphi / self.au) ** 2 + (sphi / self.av) ** 2)
            if self.kind == BECKMANN:
                tan2 = -a2 * dr.log(dr.maximum(1.0 - u.x, 1e-30))
            else:
                tan2 = a2 * u.x / dr.maximum(1.0 - u.x, 1e-30)
            cos_t = dr.rsqrt(1.0 + tan2)
            sin_t = dr.sqrt(tan2) * cos_t  # not sqrt(1 - cos^2): that rounds to 0 for tiny alpha
            m = mi.Vector3f(sin_t * cphi, sin_t * sphi, cos_t)
        return m, self.pdf(wi, m)


class VariantTable:
    """The (distribution, sample_visible) choices of a rough BSDF family's instances.

    Only the variants a scene uses are traced; when there are several, each is computed
    and the result selected per lane (``per_variant``)."""

    def __init__(self, variants_per_instance):
        self.variants = sorted(set(variants_per_instance))
        self.index = mi.UInt32([self.variants.index(v) for v in variants_per_instance])

    def lane(self, idx, active):
        """Variant index per lane, or None when the family has one variant."""
        return dr.gather(mi.UInt32, self.index, idx, active) if len(self.variants) > 1 else None

    def per_variant(self, var, fn):
        """``fn(variant)`` (a tuple of arrays) for the single variant, or selected per lane."""
        if var is None:
            return fn(self.variants[0])
        out = None
        for k, v in enumerate(self.variants):
            r = fn(v)
            out = r if out is None else type(r)(dr.select(var == k, a, b) for a, b in zip(r, out))
        return out
