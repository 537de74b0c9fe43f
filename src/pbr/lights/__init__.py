"""Light families and :class:`LightSet`, the per-scene collection of lights.

Each light has a global index; ``LightSet`` maps it to (family, index in family) and
dispatches with ``dr.switch`` over the families a scene uses (a direct call for one).
Area lights are found through ``Scene.shape_light`` (shape -> light + 1); infinite lights
are evaluated on rays that leave the scene.
"""

from __future__ import annotations

import numpy as np
import drjit as dr
import mitsuba as mi

from .area import AreaLight
from .point import PointLight
from .spot import SpotLight
from .projector import ProjectorLight, ProjectionLight
from .goniometric import GoniometricLight
from .directional import DirectionalLight, DistantLight
from .infinite import ConstantLight, EnvMapLight, PortalEnvMapLight
from .directionalarea import DirectionalAreaLight
from .base import LightSample, LightType  # noqa: F401
from .lightsamplers import make_light_sampler, LightTable, LIGHT_SAMPLERS  # noqa: F401

LIGHT_TYPES: dict[str, type] = {"area": AreaLight}
LIGHT_TYPES.update(constant=ConstantLight, envmap=EnvMapLight, portalenvmap=PortalEnvMapLight,
                   directionalarea=DirectionalAreaLight)
LIGHT_TYPES.update(point=PointLight, spot=SpotLight, projector=ProjectorLight, projection=ProjectionLight,
                   goniometric=GoniometricLight, directional=DirectionalLight, distant=DistantLight)


class LightSet:
    def __init__(self):
        self.families: dict[str, LightType] = {}
        self.entries: list[tuple[str, int]] = []

    def __len__(self):
        return len(self.entries)

    @property
    def area(self) -> AreaLight:
        return self.families.setdefault("area", AreaLight())

    def add(self, loader, props, shape_index=None) -> int:
        """Parse one emitter; returns its global light index."""
        t = props.type
        if t not in LIGHT_TYPES:
            raise props.error(None, f"unsupported emitter type {t!r} (supported: {', '.join(sorted(LIGHT_TYPES))})")
        surface = t == "area" or getattr(LIGHT_TYPES[t], "surface", False)  # attached to a shape
        if surface != (shape_index is not None):
            raise props.error(None, f"a {t!r} emitter must be attached to a shape" if surface
                              else f"a {t!r} emitter cannot be attached to a shape")
        fam = self.families.setdefault(t, LIGHT_TYPES[t]())
        local = fam.add(loader, props, shape_index) if surface else fam.add(loader, props)
        self.entries.append((t, local))
        return len(self.entries) - 1

    def build(self, scene, sampler_kind: str) -> None:
        self.order = list(self.families)
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
        bbox = scene.mi_scene.bbox()
        c = np.array(bbox.center()) if bbox.valid() else np.zeros(3)
        self.scene_center = c
        self.scene_radius = float(np.linalg.norm(np.array(bbox.max) - c)) if bbox.valid() else 1.0
        self.sampler = make_light_sampler(sampler_kind, table.powers, table.bounds)

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
        return dr.switch(fam, [_typed(getattr(f, method)) for f in fams], local, *args, active)

    # -- used by integrators -----------------------------------------------------------
    def L(self, light, si, wl, active):
        """Emitted radiance of area light ``light`` at surface hit ``si`` (toward si.wi)."""
        if "area" not in self.families:  # no area lights (e.g. only delta lights)
            return mi.Spectrum(0.0)
        active = self._area_only(light, active)
        return self.area.L(dr.gather(mi.UInt32, self.local_of, light, active), si, wl, active)

    def sample_Li(self, ref, u1, u2, wl, active) -> LightSample:
        """Pick a light (sampler probability included in the returned pdf) and sample it."""
        if not self.entries:
            # No lights: an empty sample (pdf 0), so no shadow ray is traced.
            return LightSample()
        light, pmf = self.sampler.sample(u1, ref.p, ref.n, active)
        ls = self._dispatch("sample_Li", light, active, ref, u2, wl)
        ls.pdf = ls.pdf * pmf
        return ls

    def pdf_Li(self, light, ref_p, ref_n, si, active):
        """Density of NEE reaching area-light hit ``si`` from (ref_p, ref_n)."""
        if "area" not in self.families:
            return mi.Float(0.0)
        active = self._area_only(light, active)
        local = dr.gather(mi.UInt32, self.local_of, light, active)
        return self.sampler.pmf(light, ref_p, ref_n, active) * self.area.pdf_Li(local, ref_p, si, active)

    def _area_only(self, light, active):
        if not self._other_surface:
            return active
        return active & (dr.gather(mi.UInt32, self.family_of, light, active) == self.order.index("area"))

    @property
    def has_infinite(self) -> bool:
        return bool(self.infinite_ids)

    def Le_escaped(self, d, wl, ref_p, ref_n, active):
        """[(radiance, NEE density of that direction)] for each infinite light."""
        out = []
        for g in self.infinite_ids:
            t, i = self.entries[g]
            fam = self.families[t]
            idx = mi.UInt32(i)
            kw = {"ref_p": ref_p} if getattr(fam, "needs_ref", False) else {}  # portal lights: ray origin
            Le = fam.Le(idx, d, wl, active, **kw)
            pdf = fam.pdf_Le_dir(idx, d, active, **kw) * self.sampler.pmf(
                mi.UInt32(int(self.first_light[g])), ref_p, ref_n, active)
            out.append((Le, pdf))
        return out


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
