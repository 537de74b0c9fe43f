"""BSDF families and :class:`BSDFSet`, the per-scene dispatch over them.

A scene's BSDFs get global ids; ``BSDFSet`` maps an id to (family, index in family) and
calls the family's vectorised code. With a single family the call is direct; with
several it is a ``dr.switch`` over only the families the scene uses.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .base import BSDFSample, BSDFType, ShadingContext  # noqa: F401
from .diffuse import Diffuse
from .conductor import Conductor, RoughConductor

BSDF_TYPES: dict[str, type] = {
    "diffuse": Diffuse,
    "conductor": Conductor,
    "roughconductor": RoughConductor,
}


class BSDFSet:
    def __init__(self):
        self.families: dict[str, BSDFType] = {}
        self.entries: list[tuple[str, int]] = []   # global id -> (family name, local index)

    def add(self, loader, props) -> int:
        t = props.type
        if t not in BSDF_TYPES:
            raise props.error(None, f"unsupported BSDF type {t!r} (supported: {', '.join(sorted(BSDF_TYPES))})")
        fam = self.families.setdefault(t, BSDF_TYPES[t]())
        local = fam.add(loader, props)
        self.entries.append((t, local))
        return len(self.entries) - 1

    def build(self, textures) -> None:
        self.order = list(self.families)
        for f in self.families.values():
            f.textures = textures
            f.build()
        self.family_of = mi.UInt32([self.order.index(t) for t, _ in self.entries])
        self.local_of = mi.UInt32([i for _, i in self.entries])

    def has_flag(self, flag: int) -> bool:
        return any(f.flags & flag for f in self.families.values())

    def _dispatch(self, method, bsdf_id, ctx, active, *args):
        local = dr.gather(mi.UInt32, self.local_of, bsdf_id, active)
        fams = [self.families[t] for t in self.order]
        if len(fams) == 1:
            return getattr(fams[0], method)(ctx, local, *args, active)
        fam = dr.gather(mi.UInt32, self.family_of, bsdf_id, active)
        return dr.switch(fam, [_typed(getattr(f, method)) for f in fams], ctx, local, *args, active)

    def eval_pdf(self, bsdf_id, ctx, wo, active):
        return self._dispatch("eval_pdf", bsdf_id, ctx, active, wo)

    def sample(self, bsdf_id, ctx, u1, u2, active) -> BSDFSample:
        return self._dispatch("sample", bsdf_id, ctx, active, u1, u2)

    def eval_pdf_sample(self, bsdf_id, ctx, wo, u1, u2, active):
        return self._dispatch("eval_pdf_sample", bsdf_id, ctx, active, wo, u1, u2)


def _typed(fn):
    """Wrap a family method so that every family returns identical types (``dr.switch``
    requires it): spectra as ``mi.Spectrum``, densities as ``mi.Float``."""
    def cast(v):
        if isinstance(v, BSDFSample):
            return BSDFSample(mi.Vector3f(v.wo), mi.Float(v.pdf), mi.Float(v.eta), mi.Bool(v.delta),
                              mi.Spectrum(v.weight))
        if isinstance(v, tuple):
            return tuple(cast(x) for x in v)
        if dr.size_v(v) == 4:
            return mi.Spectrum(v)
        return mi.Float(v)

    def wrapped(*args):
        return cast(fn(*args))
    return wrapped
