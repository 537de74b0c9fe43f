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
from .base import LightSample, LightType  # noqa: F401
from .lightsamplers import make_light_sampler, LIGHT_SAMPLERS  # noqa: F401
from ..scene.props import SceneError

LIGHT_TYPES: dict[str, type] = {"area": AreaLight}


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
        if (t == "area") != (shape_index is not None):
            raise props.error(None, "an 'area' emitter must be attached to a shape" if t == "area"
                              else f"a {t!r} emitter cannot be attached to a shape")
        fam = self.families.setdefault(t, LIGHT_TYPES[t]())
        local = fam.add(loader, props, shape_index) if t == "area" else fam.add(loader, props)
        self.entries.append((t, local))
        return len(self.entries) - 1

    def build(self, scene, sampler_kind: str) -> None:
        self.order = list(self.families)
        for f in self.families.values():
            f.textures = scene.textures
            f.build(scene)
        self.family_of = mi.UInt32([self.order.index(t) for t, _ in self.entries])
        self.local_of = mi.UInt32([i for _, i in self.entries])
        self.infinite_ids = [g for g, (t, _) in enumerate(self.entries) if self.families[t].infinite]
        self.any_delta = any(f.delta for f in self.families.values())
        bbox = scene.mi_scene.bbox()
        c = np.array(bbox.center()) if bbox.valid() else np.zeros(3)
        self.scene_center = c
        self.scene_radius = float(np.linalg.norm(np.array(bbox.max) - c)) if bbox.valid() else 1.0
        powers = np.array([self.families[t].power(i, scene) for t, i in self.entries], dtype=np.float64)
        bounds = [self.families[t].bounds(i, scene) for t, i in self.entries]
        if len(self.entries) and not np.all(np.isfinite(powers)):
            raise SceneError("scene: a light has a non-finite power")
        self.sampler = make_light_sampler(sampler_kind, powers, bounds)

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
        return self.area.L(dr.gather(mi.UInt32, self.local_of, light, active), si, wl, active)

    def sample_Li(self, ref, u1, u2, wl, active) -> LightSample:
        """Pick a light (sampler probability included in the returned pdf) and sample it."""
        light, pmf = self.sampler.sample(u1, ref.p, ref.n, active)
        ls = self._dispatch("sample_Li", light, active, ref, u2, wl)
        ls.pdf = ls.pdf * pmf
        return ls

    def pdf_Li(self, light, ref_p, ref_n, si, active):
        """Density of NEE reaching area-light hit ``si`` from (ref_p, ref_n)."""
        local = dr.gather(mi.UInt32, self.local_of, light, active)
        return self.sampler.pmf(light, ref_p, ref_n, active) * self.area.pdf_Li(local, ref_p, si, active)

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
            Le = fam.Le(idx, d, wl, active)
            pdf = fam.pdf_Le_dir(idx, d, active) * self.sampler.pmf(mi.UInt32(g), ref_p, ref_n, active)
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
