"""The subsurface step of ``volpath`` (pbrt-v4's VolPathIntegrator with a BSSRDF): light
refracted into a ``subsurface`` material leaves it at another point of the same
material, found by a probe segment sampled from the BSSRDF's radial profile
(:mod:`pbr.bsdfs.bssrdf`). Every intersection of the segment with a surface of the
same material is a candidate; one is chosen uniformly (reservoir sampling with one
uniform number). The path then continues from the exit point with the exit lobe S_w.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..bsdfs import bssrdf
from ..bsdfs.base import BSDFSample, ShadingContext
from ..sampling import cosine_hemisphere_pdf, square_to_cosine_hemisphere

# Surfaces a probe segment may cross (a bound on the walk; pbrt-v4 has none).
MAX_PROBE_HITS = 256


@dr.syntax
def probe_walk(scene, bsdf_id, p0, p1, u, time, active):
    """Intersect the segment p0 -> p1 with the scene: (number of hits on surfaces of BSDF
    entry ``bsdf_id``, and one of them chosen uniformly with the uniform ``u``: its
    point, geometric normal, shading normal and shape)."""
    d = p1 - p0
    ray = mi.Ray3f(p0, dr.normalize(d))
    ray.maxt = dr.norm(d)
    ray.time = time
    n = mi.UInt32(0)
    steps = mi.UInt32(0)
    p = mi.Point3f(0.0)
    ng = mi.Normal3f(0.0)
    ns = mi.Normal3f(0.0)
    shape_x = mi.UInt32(0)
    u = mi.Float(u)
    going = mi.Bool(active)
    while going:
        si, shape = scene.geometry.intersect(ray, going)
        hit = going & si.is_valid()
        same = hit & (dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit) == bsdf_id)
        n = dr.select(same, n + 1, n)
        # Keep the k-th candidate with probability 1 / k, reusing u for the next choice.
        p_keep = dr.rcp(mi.Float(dr.maximum(n, 1)))
        keep = same & (u < p_keep)
        u = dr.select(same, dr.select(keep, u / p_keep, (u - p_keep) / dr.maximum(1.0 - p_keep, 1e-12)), u)
        u = dr.minimum(u, 0.99999994)
        p = dr.select(keep, si.p, p)
        ng = dr.select(keep, si.n, ng)
        ns = dr.select(keep, si.sh_frame.n, ns)
        shape_x = dr.select(keep, shape, shape_x)
        ray = dr.select(hit, si.spawn_ray_to(p1), ray)
        steps += 1
        going = hit & (steps < MAX_PROBE_HITS)
    return n, p, ng, ns, shape_x


def probe(scene, rng, si, bsdf_id, wl, active):
    """Light entering surfaces at ``si`` on ``active`` lanes: (the lanes at a subsurface
    entry (``bsdf_id``), those of them with an exit point, the exit interaction (``wi`` along its shading normal), its shape,
    the path weight S_p / density (hero wavelength's density, times the number of
    candidates), each wavelength's density over the hero's, the material's eta)."""
    lanes, fam, idx = scene.bsdfs.subsurface(bsdf_id, active)
    tab = fam.tables
    sigma_t, rho = fam.coefficients(ShadingContext(si, wl), idx, lanes)
    u1 = rng.next_float32()
    u2 = rng.next_2d()
    n_o = si.sh_frame.n
    prof = bssrdf.Profile(tab, idx, sigma_t, rho, lanes)
    p0, p1, ok = bssrdf.sample_probe(prof, si.p, n_o, u1, u2, lanes)
    n, p, ng, ns, shape_x = probe_walk(scene, bsdf_id, p0, p1, rng.next_float32(), si.time, ok)
    found = ok & (n > 0)
    sp = prof.sr(dr.norm(p - si.p), found)
    pdf = bssrdf.pdf_sp(prof, si.p, n_o, p, ng, found)
    found &= (pdf[0] > 0) & (dr.max(sp) > 0)
    inv = dr.select(found, dr.rcp(pdf[0]), 0.0)
    weight = sp * (mi.Float(n) * inv)
    ratio = pdf * inv
    si_x = dr.zeros(mi.SurfaceInteraction3f)
    si_x.p = p
    si_x.n = ng
    si_x.sh_frame = mi.Frame3f(ns)
    si_x.t = mi.Float(0.0)
    si_x.time = si.time
    si_x.wi = mi.Vector3f(0.0, 0.0, 1.0)
    si_x.wavelengths = si.wavelengths
    return lanes, found, si_x, shape_x, weight, ratio, dr.gather(mi.Float, tab.eta, idx, lanes)


def exit_lobe(eta, active):
    """The exit lobe S_w (pbrt-v4's NormalizedFresnelBxDF: cosine-sampled) as a ``lobe``
    of ``VolPathIntegrator._next_event``: (f |cos| toward the light, its pdf, a sample)."""
    def lobe(wo_em, ls, u1, u2):
        f = mi.Spectrum(bssrdf.sw_eval(eta, wo_em))
        pdf = dr.select(wo_em.z > 0, cosine_hemisphere_pdf(wo_em), 0.0)
        wo = square_to_cosine_hemisphere(u2)
        pdf_s = cosine_hemisphere_pdf(wo)
        ok = active & (pdf_s > 0)
        w = bssrdf.sw_eval(eta, wo) * dr.select(ok, dr.rcp(pdf_s), 0.0)
        bs = BSDFSample(wo, dr.select(ok, pdf_s, 0.0), mi.Float(1.0), mi.Bool(False), mi.Spectrum(w),
                        mi.Bool(False), mi.Bool(False))
        return f, pdf, bs
    return lobe
