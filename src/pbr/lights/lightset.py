"""``LightSet``: every light of a scene, and the dispatch over their families.

Each light has a global index; ``LightSet`` maps it to (family, index in family) and
dispatches with ``dr.switch`` over the families a scene uses (a direct call for one).
Area lights are found through ``Scene.shape_light`` (shape -> light + 1); infinite lights
are evaluated on rays that leave the scene.
"""

from __future__ import annotations

import numpy as np
import drjit as dr
import mitsuba as mi

from .. import dispatch
from ..plugins.props import did_you_mean
from ..plugins.tables import own_table_memory
from .. import spectrum as spec
from ..spectrum import SampledWavelengths
from .area import AreaLight
from .base import LIGHT_TYPES, LightSample, LightType, LeSample
from .lightsamplers import make_light_sampler, LightTable


class LightSet:
    """Every emitter of a scene: ``entries[g]`` is emitter ``g``'s (type, index in its
    family), ``paths[g]`` its key path. After :meth:`build`, lights are the emitters
    expanded (one per triangle of an emissive mesh) and are what samplers pick."""

    def __init__(self):
        self.families: dict[str, LightType] = {}
        self.entries: list[tuple[str, int]] = []
        self.paths: list[str] = []

    def __len__(self):
        return len(self.entries)

    @property
    def area(self) -> AreaLight:
        return self.families.setdefault("area", LIGHT_TYPES["area"]())

    def add(self, loader, props, shape_index=None) -> int:
        """Parse one emitter; returns its global light index."""
        t = props.type
        if t not in LIGHT_TYPES:
            raise props.error(None, f"unsupported emitter type {t!r}{did_you_mean(t, LIGHT_TYPES)} "
                                        f"(supported: {LIGHT_TYPES.supported()})")
        surface = t == "area" or getattr(LIGHT_TYPES[t], "surface", False)  # attached to a shape
        if surface != (shape_index is not None):
            raise props.error(None, f"a {t!r} emitter must be attached to a shape" if surface
                              else f"a {t!r} emitter cannot be attached to a shape")
        fam = self.families.setdefault(t, LIGHT_TYPES[t]())
        local = fam.add(loader, props, shape_index) if surface else fam.add(loader, props)
        self.entries.append((t, local))
        self.paths.append(props.path)
        return len(self.entries) - 1

    def build(self, scene) -> None:
        self.order = list(self.families)
        self.textures = scene.textures
        for f in self.families.values():
            f.textures = scene.textures
            f.build(scene)
        # Emitters -> lights: an area emitter on a triangle mesh is one light per triangle.
        # Light indices (sampler, dispatch, shape_light) number the expanded lights.
        table = LightTable(self.entries, self.families, scene)
        self.first_light = table.first
        self.family_of = mi.UInt32(np.repeat([self.order.index(t) for t, _ in self.entries], table.counts))
        self.local_of = mi.UInt32(table.local)
        self._map_shapes(scene, table)
        self.infinite_ids = [g for g, (t, _) in enumerate(self.entries) if self.families[t].infinite]
        self.any_delta = any(f.delta for f in self.families.values())
        # Shape-attached families other than 'area' (directionalarea): L/pdf_Li mask them out.
        self._other_surface = any(getattr(f, "surface", False) for t, f in self.families.items() if t != "area")
        bbox = scene.bbox()
        c = np.array(bbox.center()) if bbox.valid() else np.zeros(3)
        self.scene_center = c
        self.scene_radius = float(np.linalg.norm(np.array(bbox.max) - c)) if bbox.valid() else 1.0
        self.table = table
        self._samplers = {}
        # The texture slots of the emitted spectra (TextureSet.fix_per_sample)
        self.spectrum_slots = sorted({int(inst[k]) for f in self.families.values() for inst in f.instances
                                      for k in ("radiance", "slot") if isinstance(inst.get(k), (int, np.integer))})

    def sampler(self, kind: str):
        """The light sampler ``kind`` ('uniform', 'power' or 'bvh'; see
        :mod:`.lightsamplers`) over this build's lights, built once per build. Integrators
        fetch theirs in their per-render ``prepare`` step and pass it to :meth:`sample_Li`,
        :meth:`pdf_Li`, :meth:`Le_escaped` (next-event estimation) or :meth:`sample_Le`,
        :meth:`pmf_Le` (light paths: 'power', pbrt-v4's choice for emission)."""
        if kind not in self._samplers:
            sampler = make_light_sampler(kind, self.table.powers, self.table.bounds)
            own_table_memory(sampler)
            self._samplers[kind] = sampler
        return self._samplers[kind]

    def _map_shapes(self, scene, table) -> None:
        """``scene.shape_light``: shape -> its emitter's first light + 1 (0: none), and
        which shapes are one light per triangle (a hit's light adds its prim_index)."""
        if not hasattr(self, "shape_emitter"):       # the loader's table: emitter index + 1
            self.shape_emitter = np.array(scene.shape_light, dtype=np.int64)
        se = self.shape_emitter
        first = np.append(table.first, 0)
        scene.shape_light = mi.UInt32(np.where(se > 0, first[se - 1] + 1, 0).astype(np.uint32))
        per_tri = np.array([t == "area" and self.families[t].is_mesh(i) for t, i in self.entries] + [False])
        self.any_mesh_light = bool(per_tri[se[se > 0] - 1].any()) if np.any(se > 0) else False
        self.shape_per_prim = mi.UInt32(np.where(se > 0, per_tri[se - 1], False).astype(np.uint32))

    def light_of_hit(self, scene, shape, si, active):
        """Light index + 1 of a surface hit on pbr shape ``shape`` (0 where the shape does
        not emit); on an emissive triangle mesh the hit triangle's light."""
        light = dr.gather(mi.UInt32, scene.shape_light, shape, active)
        if self.any_mesh_light:
            light += dr.gather(mi.UInt32, self.shape_per_prim, shape, active) * si.prim_index
        return light

    def _dispatch(self, method, light, active, *args):
        local = dr.gather(mi.UInt32, self.local_of, light, active)
        fams = [self.families[t] for t in self.order]
        if len(fams) == 1:
            return getattr(fams[0], method)(local, *args, active)
        fam = dr.gather(mi.UInt32, self.family_of, light, active)
        tracing = [k for k, f in enumerate(fams) if method in f.traces_rays_in]
        return self._switch(fam, [_typed(getattr(f, method)) for f in fams], local, args, active, tracing)

    def _switch(self, fam, fns, local, args, active, outside=()):
        """``dispatch.switch`` over the families. What was fixed once per camera sample
        for the wavelengths among ``args`` (``spectrum.fixed_for``: D65, the emitter
        spectra) goes along as an argument: a symbolic call receives its arguments as new
        variables and cannot read the caller's other arrays."""
        at = next((i for i, a in enumerate(args) if isinstance(a, SampledWavelengths)), None)
        fixed = spec.fixed_for(args[at].lambda_) if at is not None else None
        if not fixed:
            return dispatch.switch(fam, fns, local, *args, active, outside=outside)
        fixed = {k: fixed[k] for k in sorted(fixed, key=str)}

        def forwarding(fn):
            def call(local, *rest):
                *a, values, on = rest
                with spec.fixed_as(a[at].lambda_, values):
                    return fn(local, *a, on)
            return call

        return dispatch.switch(fam, [forwarding(fn) for fn in fns], local, *args, fixed, active, outside=outside)

    # -- used by integrators -----------------------------------------------------------
    def L(self, light, si, wl, active):
        """Emitted radiance of area light ``light`` at surface hit ``si`` (toward si.wi)."""
        if "area" not in self.families:  # no area lights (e.g. only delta lights)
            return mi.Spectrum(0.0)
        active = self._area_only(light, active)
        return self.area.L(dr.gather(mi.UInt32, self.local_of, light, active), si, wl, active)

    def sample_Li(self, sampler, ref, u1, u2, wl, active) -> LightSample:
        """Pick a light with ``sampler`` (its probability included in the returned pdf)
        and sample it."""
        if not self.entries:
            # No lights: an empty sample (pdf 0), so no shadow ray is traced.
            return LightSample()
        light, pmf = sampler.sample(u1, ref.p, ref.n, active)
        ls = self._dispatch("sample_Li", light, active, ref, u2, wl)
        ls.pdf = ls.pdf * pmf
        return ls

    def sample_Li_light(self, light, ref, u, wl, active) -> LightSample:
        """Sample light ``light`` itself (no light-sampler pick; ``pdf`` is the light's
        own density): for integrators that visit every light, e.g. ``whitted``."""
        return self._dispatch("sample_Li", light, active, ref, u, wl)

    @property
    def n_lights(self) -> int:
        """Number of lights after expansion (one per emissive triangle)."""
        return dr.width(self.local_of) if self.entries else 0

    def pdf_Li(self, sampler, light, ref_p, ref_n, si, active):
        """Density of NEE with ``sampler`` reaching area-light hit ``si`` from (ref_p, ref_n)."""
        if "area" not in self.families:
            return mi.Float(0.0)
        active = self._area_only(light, active)
        local = dr.gather(mi.UInt32, self.local_of, light, active)
        return sampler.pmf(light, ref_p, ref_n, active) * self.area.pdf_Li(local, ref_p, si, active)

    def _area_only(self, light, active):
        if not self._other_surface:
            return active
        return active & (dr.gather(mi.UInt32, self.family_of, light, active) == self.order.index("area"))

    @property
    def has_infinite(self) -> bool:
        return bool(self.infinite_ids)

    def Le_escaped(self, d, wl, ref_p, ref_n, active, sampler=None):
        """[(radiance, density of NEE with ``sampler`` choosing that direction)] for each
        infinite light (density None without a sampler)."""
        out = []
        for g in self.infinite_ids:
            t, i = self.entries[g]
            fam = self.families[t]
            idx = mi.UInt32(i)
            kw = {"ref_p": ref_p} if getattr(fam, "needs_ref", False) else {}  # portal lights: ray origin
            Le = fam.Le(idx, d, wl, active, **kw)
            pdf = None if sampler is None else fam.pdf_Le_dir(idx, d, active, **kw) * sampler.pmf(
                mi.UInt32(int(self.first_light[g])), ref_p, ref_n, active)
            out.append((Le, pdf))
        return out

    # -- emission: rays leaving the lights (light tracing, BDPT, photon mapping) ---------
    # -- emission: rays leaving the lights (light tracing, BDPT, photon mapping) ---------
    def sample_Le(self, sampler, u_light, u_pos, u_dir, wl, active) -> LeSample:
        """Pick a light with ``sampler`` (independent of any shading point: pbrt-v4 uses
        the power sampler) and sample a ray leaving it (see
        :class:`pbr.lights.base.LeSample`). Lanes with nothing to emit have ``pdf_dir = 0``
        and ``weight = 0``."""
        if not self.entries:
            return LeSample()
        light, pmf = sampler.sample(u_light, None, None, active)
        light = mi.UInt32(light)
        local = dr.gather(mi.UInt32, self.local_of, light, active)
        fams = [self.families[t] for t in self.order]
        if len(fams) == 1:
            s = fams[0].sample_Le(local, u_pos, u_dir, wl, active)
        else:
            fam = dr.gather(mi.UInt32, self.family_of, light, active)
            s = self._switch(fam, [_typed_Le(f.sample_Le) for f in fams], local, (u_pos, u_dir, wl), active)
        s = _cast_Le(s)
        ok = active & (s.pdf_pos > 0) & (s.pdf_dir > 0) & (pmf > 0)
        cos = dr.select(s.delta_pos, 1.0, dr.abs(dr.dot(s.n, s.d)))
        s.pmf = dr.select(active, mi.Float(pmf), 0.0)
        s.weight = dr.select(ok, s.L * (cos / (s.pmf * s.pdf_pos * s.pdf_dir)), 0.0)
        s.pdf_dir = dr.select(ok, s.pdf_dir, 0.0)
        s.light = light
        return s

    def pmf_Le(self, sampler, light, active=True):
        """Probability that ``sample_Le`` with ``sampler`` picks light ``light``."""
        return sampler.pmf(light, None, None, active)

    def pdf_Le(self, light, p, n, d, active):
        """(pdf_pos, pdf_dir) with which light ``light`` emits the ray from ``p`` along
        ``d`` (``n``: the shading normal at ``p`` for area lights; the pick probability
        ``pmf_Le`` is not included). Delta components are reported as 1, as ``sample_Le``
        does; for infinite lights ``d`` is the direction the light sends (opposite to the
        escaped ray) and ``p`` is unused."""
        return self._dispatch("pdf_Le", light, active, p, n, d)


def _cast_Le(v):
    return LeSample(o=mi.Point3f(v.o), d=mi.Vector3f(v.d), L=mi.Spectrum(v.L), pdf_pos=mi.Float(v.pdf_pos),
                    pdf_dir=mi.Float(v.pdf_dir), n=mi.Normal3f(v.n), delta_pos=mi.Bool(v.delta_pos),
                    delta_dir=mi.Bool(v.delta_dir), infinite=mi.Bool(v.infinite), pmf=mi.Float(v.pmf),
                    weight=mi.Spectrum(v.weight), light=mi.UInt32(v.light))


def _typed_Le(fn):
    def wrapped(*args):
        return _cast_Le(fn(*args))
    return wrapped


def _typed(fn):
    """Identical output types for every family (``dr.switch`` requires it)."""
    def cast(v):
        if isinstance(v, LightSample):
            return LightSample(mi.Spectrum(v.L), mi.Vector3f(v.wi), mi.Float(v.pdf), mi.Point3f(v.p),
                               mi.Bool(v.delta))
        if isinstance(v, tuple):
            return tuple(cast(x) for x in v)
        return mi.Spectrum(v) if dr.size_v(v) == 4 else mi.Float(v)

    def wrapped(*args):
        return cast(fn(*args))
    return wrapped
