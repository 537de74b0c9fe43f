"""Fresnel equations (one implementation, shared by every BSDF).

``eta`` is the relative index of refraction interior/exterior; ``cos_theta_i`` is taken
w.r.t. the surface normal, negative when the incident direction is inside.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..plugins.props import IOR


def fresnel_dielectric(cos_theta_i, eta):
    """Unpolarised reflectance of a dielectric interface.

    Returns (R, cos_theta_t, eta_it, eta_ti): the reflectance, the signed cosine of the
    refracted direction (opposite side), and the relative IORs across the interface in
    the direction of travel (eta_it = eta_t / eta_i) and back. R = 1 under total
    internal reflection; R = 0 for index-matched interfaces."""
    outside = cos_theta_i >= 0
    rcp_eta = dr.rcp(eta)
    eta_it = dr.select(outside, eta, rcp_eta)
    eta_ti = dr.select(outside, rcp_eta, eta)
    cos_t_sqr = dr.fma(-dr.fma(-cos_theta_i, cos_theta_i, 1.0), eta_ti * eta_ti, 1.0)
    cos_i = dr.abs(cos_theta_i)
    cos_t = dr.safe_sqrt(cos_t_sqr)
    a_s = dr.fma(-eta_it, cos_t, cos_i) / dr.fma(eta_it, cos_t, cos_i)
    a_p = dr.fma(-eta_it, cos_i, cos_t) / dr.fma(eta_it, cos_i, cos_t)
    r = 0.5 * (a_s * a_s + a_p * a_p)
    matched = eta == 1
    r = dr.select(matched, 0.0, dr.select(cos_i == 0, 1.0, r))
    cos_theta_t = dr.select(outside, -cos_t, cos_t)
    return r, cos_theta_t, eta_it, eta_ti


def fresnel_conductor(cos_theta_i, eta, k):
    """Unpolarised reflectance of a conductor with complex IOR n = eta + i k (per wavelength).

    Exact formula with complex arithmetic, written without dividing by n so that it
    holds down to n = 0 (eta = k = 0 is a valid input: a perfect mirror, the limit of
    total internal reflection): with w = n c_t = sqrt(n^2 - sin^2) (principal root),
    r_s = (c - w)/(c + w) and r_p = (n^2 c - w)/(n^2 c + w)."""
    c = dr.clip(dr.abs(cos_theta_i), 0.0, 1.0)
    s2 = 1.0 - c * c
    n2_re, n2_im = eta * eta - k * k, 2.0 * eta * k
    w_re, w_im = _csqrt(n2_re - s2, n2_im)
    rs = _cabs2_ratio(c - w_re, -w_im, c + w_re, w_im)
    n2c_re, n2c_im = n2_re * c, n2_im * c
    rp = _cabs2_ratio(n2c_re - w_re, n2c_im - w_im, n2c_re + w_re, n2c_im + w_im)
    return 0.5 * (rs + rp)


def _csqrt(re, im):
    """Principal square root (a, b) of a complex number (re, im). The larger of a, b is
    sqrt((|z| + |re|) / 2) and the smaller |im| / (2 * larger): no cancellation of
    |z| - |re| when |im| << |re| (a conductor with small k under total internal reflection)."""
    big = dr.safe_sqrt(0.5 * (dr.sqrt(dr.fma(re, re, im * im)) + dr.abs(re)))
    # |im| written as a select so that at im = 0 it keeps im's derivative (dr.abs's is 0
    # there): the one-sided derivative at k = 0 or eta = 0 of a conductor, whose im =
    # 2 eta k >= 0; d R / d k at k = 0 was about half the finite difference
    abs_im = dr.select(im < 0, -im, im)
    small = dr.select(big > 0, 0.5 * abs_im / big, 0.0)
    pos = re >= 0
    a, b = dr.select(pos, big, small), dr.select(pos, small, big)
    return a, dr.select(im < 0, -b, b)


def _cabs2_ratio(ar, ai, br, bi):
    """|a|^2 / |b|^2, and 1 where b = 0 (there a = 0 too in fresnel_conductor, whose
    ratios tend to 1: w = 0 only where n^2 = sin^2, i.e. at grazing or on n = 0)."""
    den = br * br + bi * bi
    return dr.select(den > 0, (ar * ar + ai * ai) / den, 1.0)


def reflect(wi):
    """Mirror direction about +z (local frame)."""
    return mi.Vector3f(-wi.x, -wi.y, wi.z)


def reflect_about(wi, m):
    return 2.0 * dr.dot(wi, m) * m - wi


def refract(wi, cos_theta_t, eta_ti):
    """Refracted direction about +z (local frame) given fresnel_dielectric's outputs."""
    return mi.Vector3f(-eta_ti * wi.x, -eta_ti * wi.y, cos_theta_t)


def refract_about(wi, m, cos_theta_t, eta_ti):
    """Refracted direction about microfacet normal ``m``."""
    return m * (dr.dot(wi, m) * eta_ti + cos_theta_t) - wi * eta_ti


# Named indices of refraction (Mitsuba's names; values at ~589 nm).
IOR_TABLE = {
    "vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277,
    "carbon dioxide": 1.00045, "water": 1.3330, "acetone": 1.36, "ethanol": 1.361,
    "carbon tetrachloride": 1.461, "glycerol": 1.4729, "benzene": 1.501,
    "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
    "pyrex": 1.470, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046,
    "sodium chloride": 1.544, "amber": 1.55, "pet": 1.5750, "diamond": 2.419,
}


def fresnel_diffuse_reflectance(eta: float) -> float:
    """Hemispherical average of the dielectric Fresnel reflectance for light arriving
    from the side of relative IOR ``eta`` (fits by Egan & Hilgeman 1973 for eta < 1 and
    d'Eon & Irving 2011 otherwise, the same fits Mitsuba uses)."""
    inv = 1.0 / eta
    if eta < 1.0:
        return 0.0636 * inv + eta * (eta * -1.4399 + 0.7099) + 0.6681
    c = (0.919317, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881)
    return sum(ci * inv ** i for i, ci in enumerate(c))


def lookup_ior(props, name: str, default):
    """A float IOR from a number or a name in :data:`IOR_TABLE` (error names the key)."""
    v = props.raw(name, default)
    if isinstance(v, str):
        key = v.strip().lower()
        if key not in IOR_TABLE:
            raise props.error(name, f"unknown IOR name {v!r}; known: {', '.join(IOR_TABLE)}")
        return IOR_TABLE[key]
    return props.float(name, default, valid=IOR)
