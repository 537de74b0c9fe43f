"""The volumetric walk shared by the volumetric integrators (``volpath``, ``prbvolpath``,
``simplevolpath``; pbrt-v4's chapter 14).

A path through participating media alternates *free flights* through the medium it is
in (:func:`free_flight`: the majorant walk of :mod:`pbr.media.majorant`, one tentative
collision per step) with surface events; media change where a ray crosses a shape with
``interior``/``exterior`` media (:func:`enter`), and ``null`` surfaces are crossed
unchanged. Next-event estimation traces a shadow ray to the light sample through media
and null surfaces (:func:`transmittance`). What an estimator does at a collision (delta
or ratio tracking, spectral MIS, derivatives) is its own: it passes a callback and the
state it updates. The helpers below build a vertex's light sample reference, shadow ray,
phase-function terms and next ray, identically for every volumetric estimator.

Conventions: medium indices are +1 (0: vacuum); directions are world-space unit vectors.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..bsdfs.base import ShadingContext
from ..media import majorant

# Shadow rays stop this fraction short of the light sample (its own surface is no occluder).
SHADOW_EPSILON = 1e-4


class Collision:
    """One step of a free flight, as :func:`free_flight` hands it to the estimator:
    medium ``m`` (index), position ``p`` and distance ``t`` along the ray (``t_prev``
    before the step), whether a tentative collision happened (``coll``; else the
    segment ended), the majorant transmittance ``T_maj`` over the step and the majorant
    ``sigma_maj``, the lanes still walking (``going``) and the wavelengths ``wl``."""

    def __init__(self, m, p, t, t_prev, coll, T_maj, sigma_maj, going, wl):
        self.m, self.p, self.t, self.t_prev = m, p, t, t_prev
        self.coll, self.T_maj, self.sigma_maj, self.going, self.wl = coll, T_maj, sigma_maj, going, wl


@dr.syntax
def free_flight(media, rng, ray, medium, t_max, wl, active, state, collide, args=(), factor: float = 1.0):
    """Walk medium ``medium`` (index + 1) along ``ray`` up to ``t_max`` on ``active``
    lanes: at each step ``collide(state, Collision, rng, *args)`` returns the new
    ``state`` (a tuple of Dr.Jit values) and the lanes that stop (absorbed, scattered,
    ...). Grid majorants are multiplied by ``factor``. Returns the final state.

    ``args`` must not hold ``rng``, ``wl`` or a value of ``state`` again: the symbolic
    loop would capture the same variable twice (a random number generator captured twice
    repeats or skips numbers)."""
    m = medium - 1
    it = majorant.start(media, m, ray, t_max, active)
    going = mi.Bool(active)
    while dr.hint(going, label="free_flight"):
        t_prev = mi.Float(it.t)
        coll, T_maj, sigma_maj, done = majorant.step(media, it, m, wl, rng.next_float32(), going, factor=factor)
        c = Collision(m, ray.o + ray.d * it.t, it.t, t_prev, coll, T_maj, sigma_maj, going, wl)
        state, stop = collide(state, c, rng, *args)
        going &= ~done & ~stop
    return state


def transmittance(scene, ray, p_light, medium, active, state, segment, args=(), wl=None, crossing=None,
                  crossing_args=()):
    """Follow a shadow ray from ``ray.o`` toward ``p_light`` through media and ``null``
    surfaces. ``state[0]`` is the transmittance; in each medium segment (ray origin to
    the next surface, or to the light) ``segment(state, ray, medium, t_end, in_medium,
    *args)`` returns the new state (``medium``: index + 1). The ray stops at an opaque surface (transmittance 0)
    or where the transmittance is 0. Returns the final state.

    With the wavelengths ``wl``, surfaces whose BSDF has a null lobe (``thindielectric``'s
    transmission, as Mitsuba's volumetric integrators treat it) are crossed too, the
    transmittance multiplied by the lobe's weight ``w``; ``crossing(state, w, lanes,
    *crossing_args)``, if given, applies it instead (``w`` then carries derivatives)."""
    has_media = len(scene.media) > 0
    bsdfs = scene.bsdfs
    if not (has_media or bsdfs.has_null or (wl is not None and bsdfs.has_null_lobes)):
        # Nothing to cross: one occlusion test (no loop, no surface interaction).
        ray = mi.Ray3f(ray)
        ray.maxt = dr.norm(p_light - ray.o) * (1.0 - SHADOW_EPSILON)
        blocked = scene.geometry.occluded(ray, active)
        return (dr.select(blocked, 0.0, state[0]),) + tuple(state[1:])
    return _march(scene, ray, p_light, medium, active, state, segment, args, wl, crossing, crossing_args)


@dr.syntax
def _march(scene, ray, p_light, medium, active, state, segment, args, wl, crossing, crossing_args):
    """:func:`transmittance`'s walk from surface to surface."""
    has_media = len(scene.media) > 0
    going = mi.Bool(active)
    med = mi.UInt32(medium)
    ray = mi.Ray3f(ray)
    while dr.hint(going, label="shadow_ray", exclude=[p_light]):
        remaining = dr.norm(p_light - ray.o)
        si, shape = scene.geometry.intersect(ray, going)
        hit = going & si.is_valid() & (si.t < remaining * (1.0 - SHADOW_EPSILON))
        t_end = dr.select(hit, si.t, remaining)
        if has_media:
            state = segment(state, ray, med, t_end, going & (med > 0), *args)
        passable, med, ray, w, lobe = cross_null(scene, shape, si, ray, p_light, med, hit, wl, crossing is not None)
        if w is not None and crossing is not None:
            state = crossing(state, w, lobe, *crossing_args)
        elif w is not None:
            state = (state[0] * w,) + tuple(state[1:])
        T = dr.select(hit & ~passable, 0.0, state[0])
        state = (T,) + tuple(state[1:])
        going &= passable & (dr.max(T) > 0)
    return state


# ------------------------------------------------------------------ crossing surfaces

def enter(scene, shape, si, d, medium, active):
    """The medium (index + 1) after crossing surface ``si`` of ``shape`` along ``d``:
    the shape's exterior medium when leaving along its normal, its interior otherwise;
    ``medium`` where the shape has no media."""
    trans = active & dr.gather(mi.Bool, scene.shape_transition, shape, active)
    inside = dr.gather(mi.UInt32, scene.shape_interior, shape, trans)
    outside = dr.gather(mi.UInt32, scene.shape_exterior, shape, trans)
    return dr.select(trans, dr.select(dr.dot(d, si.n) > 0, outside, inside), medium)


def aim(ray, p_light):
    """``ray`` re-aimed from its origin at ``p_light``. A spawned ray's origin is offset
    along the surface normal; keeping the direction taken from the unshifted point makes a
    shadow ray meet the light's own surface short of ``p_light`` (which then counts as an
    occluder: up to half the direct light was lost with the light 0.1 above a floor), or
    drift past it after crossing null surfaces."""
    ray.d = dr.normalize(p_light - ray.o)
    return ray


def cross_null(scene, shape, si, ray, p_light, medium, hit, wl=None, grad=False):
    """A shadow ray toward ``p_light`` meets surface ``si``: (lanes that pass it, being
    ``null`` surfaces (or, given the wavelengths ``wl``, surfaces with a null lobe), the
    medium beyond, the ray continuing behind it, the weight of the crossing (None: 1; with
    ``grad``, attached to the parameters), the lanes crossing a null lobe)."""
    bsdfs = scene.bsdfs
    bid = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
    passable = hit & bsdfs.is_null(bid, hit)
    w, lobe = None, mi.Bool(False)
    if wl is not None and bsdfs.has_null_lobes:
        lobe = hit & bsdfs.has_null_lobe(bid, hit)
        si_l = mi.SurfaceInteraction3f(si)
        si_l.wi = si.to_local(-ray.d)
        with dr.resume_grad(when=grad):
            w = dr.select(lobe, bsdfs.null_transmission(bid, ShadingContext(si_l, wl), lobe), 1.0)
        passable |= lobe
    medium = enter(scene, shape, si, ray.d, medium, passable)
    nxt = aim(si.spawn_ray(dr.normalize(p_light - si.p)), p_light)
    return passable, medium, dr.select(passable, nxt, ray), w, lobe


def hero_ratio(T_maj):
    """T_maj / T_maj[0]: the weight of a segment passed without a collision, sampled with
    the hero wavelength's probability T_maj[0] (0 where that is 0)."""
    t0 = T_maj[0]
    return dr.select(t0 > 0, T_maj * dr.rcp(t0), 0.0)


# --------------------------------------------------------------------------- vertices

def classify(scene, shape, surf, scattered, skip, depth, max_depth):
    """What the path does after a free flight: (BSDF entry of the surface reached,
    ``skip``: lanes crossing a null surface (or a hidden emitter), ``real``: lanes at a
    scattering surface, ``at_vertex``: lanes at a real scattering event (surface or
    medium: one more vertex), ``sc``/``rs``: the medium/surface vertices that may still
    scatter (depth + 1 < max_depth))."""
    bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, surf)
    skip |= surf & scene.bsdfs.is_null(bsdf_id, surf)
    real = surf & ~skip
    at_vertex = real | scattered
    go_on = at_vertex & (depth + 1 < max_depth)
    return bsdf_id, skip, real, at_vertex, go_on, go_on & scattered, go_on & real


def nee_reference(si, sc, p_sc):
    """The point light sampling starts from: the medium scattering point on ``sc`` lanes
    (no normal), the surface hit elsewhere."""
    ref = dr.zeros(mi.SurfaceInteraction3f)
    ref.p = dr.select(sc, p_sc, si.p)
    ref.n = dr.select(sc, mi.Normal3f(0.0), si.n)
    ref.time = si.time
    return ref


def phase_nee(media, medium, ray, wi, sc, f, pdf):
    """(f, pdf) toward light direction ``wi``: the phase function's (its value is its
    density) on medium-vertex lanes ``sc``, the BSDF's ``f``/``pdf`` elsewhere."""
    f_ph = media.phase_eval(medium - 1, -ray.d, wi, sc)
    return dr.select(sc, mi.Spectrum(f_ph), f), dr.select(sc, f_ph, pdf)


def shadow_ray(scene, shape, si, ls, sc, p_sc, medium, active):
    """(shadow ray toward the light sample ``ls``, aimed at its point, and the medium it
    starts in) from the vertex (``p_sc`` on medium lanes ``sc``, the surface elsewhere)."""
    sray = si.spawn_ray(ls.wi)
    sray.o[sc] = p_sc
    sray = aim(sray, ls.p)
    if len(scene.media) > 0:
        medium = enter(scene, shape, si, ls.wi, medium, active)
    return sray, medium


def cross_null_lobe(bs, lobe, beta, go_on, rs, at_vertex, skip):
    """Lanes whose BSDF sample took a null lobe (``thindielectric``'s transmission, as in
    Mitsuba's volumetric integrators) go on as through a null surface: no vertex, no
    bounce, the MIS state of the last vertex kept, the throughput weighted by the lobe.
    Updates ``beta``, ``go_on``, ``rs``, ``at_vertex`` and ``skip`` in place (masked
    assignments to the callers' loop state) and returns the mask of the lanes that crossed."""
    crossed = lobe & bs.null & (bs.pdf > 0)
    beta[crossed] = beta * bs.weight
    go_on[crossed] = False
    rs[crossed] = False
    at_vertex[crossed] = False
    skip[crossed] = True
    return crossed


def sample_direction(media, medium, ray, si, bs, sc, rng):
    """The path's next direction: (world direction, pdf, weight, delta) from the BSDF
    sample ``bs`` at surfaces, or a phase-function sample (weight 1) on medium lanes
    ``sc`` (which draws two random numbers when the scene has media)."""
    wi = si.to_world(bs.wo)
    pdf = mi.Float(bs.pdf)
    weight = mi.Spectrum(bs.weight)
    delta = mi.Bool(bs.delta)
    if len(media) > 0:
        wph, pph = media.phase_sample(medium - 1, -ray.d, rng.next_2d(), sc)
        wi = dr.select(sc, wph, wi)
        pdf = dr.select(sc, pph, pdf)
        weight = dr.select(sc, mi.Spectrum(1.0), weight)
        delta = delta & ~sc
    return wi, pdf, weight, delta


def next_ray(scene, shape, si, ray, medium, wi, p_sc, sc, cont, rs, skip):
    """(next ray, medium it travels in): along ``wi`` from the vertex on ``cont`` lanes
    (surface lanes ``rs`` may enter another medium), straight on through skipped (null or
    hidden) surfaces, unchanged elsewhere."""
    new_ray = si.spawn_ray(wi)
    new_ray.o[sc] = p_sc
    if len(scene.media) > 0:
        medium = enter(scene, shape, si, wi, medium, cont & rs)
        medium = enter(scene, shape, si, ray.d, medium, skip)
    return dr.select(cont, new_ray, dr.select(skip, si.spawn_ray(ray.d), ray)), medium
