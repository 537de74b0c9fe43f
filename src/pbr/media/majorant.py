"""Majorant traversal along a ray: piecewise-constant ``sigma_maj`` segments and
exponential free-flight sampling against them (pbrt-v4's ``SampleT_maj`` with its
``DDAMajorantIterator``), one step per call so that integrators can run it inside their
own Dr.Jit loops.

A homogeneous medium is one segment ``[0, t_max)`` with ``sigma_maj = sigma_t``. A grid
medium is clipped to its unit cube (it is empty outside) and walked cell by cell through
the 16^3 majorant grid with a 3D DDA. Sampling uses the first wavelength's majorant
(the hero wavelength); the transmittance ``T_maj`` is returned for all wavelengths, so
integrators can weight the others (spectral MIS).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..backend import Struct
from .grid import MAJORANT_RES


class MajorantIterator(Struct):
    """Position ``t`` along the ray, end ``t_end`` of the medium segment, and the DDA
    state (current ``cell``, next boundary crossing ``t_next`` and spacing ``dt`` per
    axis, ``step`` direction) of grid media."""

    _fields = {"t": "Float", "t_end": "Float", "cell": "Vector3i", "t_next": "Vector3f",
               "dt": "Vector3f", "step": "Vector3i"}
    _defaults = {"t_next": dr.inf, "dt": dr.inf}


def start(media, m, ray: mi.Ray3f, t_max, active) -> MajorantIterator:
    """Iterator over medium ``m`` along ``ray`` (unit-length direction) up to ``t_max``."""
    it = MajorantIterator(mi.Float(0.0), mi.Float(t_max))
    if not media.has_grid:
        return it
    grid = active & dr.gather(mi.Bool, media.is_grid, m, active)
    o = media.to_local(m, ray.o, grid)
    d = media.to_local(m, ray.d, grid, vector=True)
    # Slab test against the unit cube.
    t0, t1 = mi.Float(0.0), mi.Float(t_max)
    for k in range(3):
        inv = dr.rcp(d[k])
        ta, tb = -o[k] * inv, (1.0 - o[k]) * inv
        lo, hi = dr.minimum(ta, tb), dr.maximum(ta, tb)
        flat = d[k] == 0
        inside = (o[k] >= 0) & (o[k] <= 1)
        lo = dr.select(flat, dr.select(inside, -dr.inf, dr.inf), lo)
        hi = dr.select(flat, dr.select(inside, dr.inf, -dr.inf), hi)
        t0, t1 = dr.maximum(t0, lo), dr.minimum(t1, hi)
    empty = t0 >= t1
    # A segment that misses the cube has nothing to walk: it starts and ends at one
    # finite point with no cell boundary ahead (t_next stays inf), so step() reports it
    # done with T_maj = 1. (A DDA set up at a point outside the cube found boundaries
    # behind it: negative distances, T_maj > 1; at t_max = inf, NaN.)
    t_skip = dr.select(dr.isfinite(mi.Float(t_max)), t_max, 0.0)
    it.t[grid] = dr.select(empty, t_skip, t0)
    it.t_end[grid] = dr.select(empty, t_skip, t1)
    grid &= ~empty
    # DDA set-up at the entry point.
    r = MAJORANT_RES
    pos = o + d * it.t
    cell = dr.clip(mi.Vector3i(dr.floor(pos * r)), 0, r - 1)
    t_next, dt, step = mi.Vector3f(dr.inf), mi.Vector3f(dr.inf), mi.Vector3i(0)
    for k in range(3):
        pos_k = dr.select(d[k] > 0, mi.Float(cell[k] + 1) / r, mi.Float(cell[k]) / r)
        t_next[k] = dr.select(d[k] != 0, it.t + (pos_k - pos[k]) / d[k], dr.inf)
        dt[k] = dr.select(d[k] != 0, dr.abs(dr.rcp(r * d[k])), dr.inf)
        step[k] = dr.select(d[k] > 0, 1, dr.select(d[k] < 0, -1, 0))
    it.cell[grid] = cell
    it.t_next[grid] = t_next
    it.dt[grid] = dt
    it.step[grid] = step
    return it


def step(media, it: MajorantIterator, m, wl, u, active, factor: float = 1.0):
    """One step: sample a tentative collision in the current segment with the first
    wavelength's majorant. Returns (collided, T_maj over the distance advanced, sigma_maj,
    done); ``it.t`` is the collision point or the segment's end, and ``done`` means the
    walk reached ``t_end`` without a collision. ``factor`` inflates grid majorants (more
    null collisions; the differentiable integrator needs sigma_maj > sigma_t)."""
    sigma_maj = mi.Spectrum(media.majorant(m, it.cell, wl, active))
    seg_end = mi.Float(it.t_end)
    grid = mi.Bool(False)
    if media.has_grid:
        grid = active & dr.gather(mi.Bool, media.is_grid, m, active)
        if factor != 1.0:
            sigma_maj = dr.select(grid, sigma_maj * factor, sigma_maj)
        seg_end[grid] = dr.minimum(seg_end, dr.minimum(it.t_next.x, dr.minimum(it.t_next.y, it.t_next.z)))
    s0 = sigma_maj[0]
    t_c = it.t - dr.log(1.0 - u) * dr.rcp(s0)
    collided = active & (s0 > 0) & (t_c < seg_end)
    t_stop = dr.select(collided, t_c, seg_end)
    dist = t_stop - it.t
    T_maj = dr.select(sigma_maj > 0, dr.exp(-sigma_maj * dist), 1.0)
    it.t[active] = t_stop
    if media.has_grid:
        adv = grid & ~collided & (t_stop < it.t_end)
        ax = dr.select(it.t_next.x <= dr.minimum(it.t_next.y, it.t_next.z), 0,
                       dr.select(it.t_next.y <= it.t_next.z, 1, 2))
        for k in range(3):
            mk = adv & (ax == k)
            it.cell[k] = dr.select(mk, it.cell[k] + it.step[k], it.cell[k])
            it.t_next[k] = dr.select(mk, it.t_next[k] + it.dt[k], it.t_next[k])
        out = (it.cell < 0) | (it.cell >= MAJORANT_RES)
        left = adv & (out.x | out.y | out.z)
        it.t[left] = it.t_end
    done = active & ~collided & (it.t >= it.t_end)
    return collided, mi.Spectrum(dr.select(active, T_maj, 1.0)), sigma_maj, done
