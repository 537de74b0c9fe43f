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
from .plastic import Plastic

BSDF_TYPES: dict[str, type] = {
    "diffuse": Diffuse,
    "conductor": Conductor,
    "roughconductor": RoughConductor,
    "plastic": Plastic,
}


NO_BACK = 0xFFFFFFFF


class BSDFSet:
    """All BSDFs of a scene. Entry ``i`` is (family, index in family, back entry).

    ``twosided`` (Mitsuba's) is not a family: its entry is the front BSDF's, with a back
    entry (the second nested BSDF, or the front one again). Where the incident direction
    lies below the surface, the dispatcher mirrors both directions through the surface
    and uses the back entry."""

    def __init__(self):
        self.families: dict[str, BSDFType] = {}
        self.entries: list[tuple[str, int, int]] = []

    def add(self, loader, props) -> int:
        t = props.type
        if t == "twosided":
            return self._add_twosided(loader, props)
        if t not in BSDF_TYPES:
            raise props.error(None, f"unsupported BSDF type {t!r} "
                                    f"(supported: {', '.join(sorted(list(BSDF_TYPES) + ['twosided']))})")
        fam = self.families.setdefault(t, BSDF_TYPES[t]())
        local = fam.add(loader, props)
        self.entries.append((t, local, NO_BACK))
        return len(self.entries) - 1

    def _add_twosided(self, loader, props) -> int:
        nested = [k for k, v in props.children()]
        if not 1 <= len(nested) <= 2:
            raise props.error(None, f"twosided takes one or two nested BSDFs, got {len(nested)}")
        ids = [loader.bsdf(props.raw(k), props.key(k)) for k in nested]
        props.finish()
        for i, k in zip(ids, nested):
            if self.entries[i][2] != NO_BACK:
                raise props.error(k, "a twosided BSDF cannot contain another twosided BSDF")
        front, back = ids[0], ids[-1]
        fam, local, _ = self.entries[front]
        self.entries.append((fam, local, back))
        return len(self.entries) - 1

    def build(self, textures) -> None:
        self.order = list(self.families)
        for f in self.families.values():
            f.textures = textures
            f.build()
        self.family_of = mi.UInt32([self.order.index(t) for t, _, _ in self.entries])
        self.local_of = mi.UInt32([i for _, i, _ in self.entries])
        self.back_of = mi.UInt32([b for _, _, b in self.entries])
        self.twosided = any(b != NO_BACK for _, _, b in self.entries)

    def has_flag(self, flag: int) -> bool:
        return any(f.flags & flag for f in self.families.values())

    def _dispatch(self, method, bsdf_id, ctx, active, *args):
        local = dr.gather(mi.UInt32, self.local_of, bsdf_id, active)
        fams = [self.families[t] for t in self.order]
        if len(fams) == 1:
            return getattr(fams[0], method)(ctx, local, *args, active)
        fam = dr.gather(mi.UInt32, self.family_of, bsdf_id, active)
        return dr.switch(fam, [_typed(getattr(f, method)) for f in fams], ctx, local, *args, active)

    def _side(self, bsdf_id, ctx, active):
        """(entry to use, context, flip mask) after applying two-sidedness."""
        if not self.twosided:
            return bsdf_id, ctx, None
        back = dr.gather(mi.UInt32, self.back_of, bsdf_id, active)
        flip = (back != NO_BACK) & (ctx.si.wi.z < 0)
        si = mi.SurfaceInteraction3f(ctx.si)
        si.wi = _flip(si.wi, flip)
        return dr.select(flip, back, bsdf_id), ShadingContext(si, ctx.wl), flip

    def eval_pdf(self, bsdf_id, ctx, wo, active):
        bsdf_id, ctx, flip = self._side(bsdf_id, ctx, active)
        if flip is not None:
            wo = _flip(wo, flip)
        return self._dispatch("eval_pdf", bsdf_id, ctx, active, wo)

    def sample(self, bsdf_id, ctx, u1, u2, active) -> BSDFSample:
        bsdf_id, ctx, flip = self._side(bsdf_id, ctx, active)
        bs = self._dispatch("sample", bsdf_id, ctx, active, u1, u2)
        if flip is not None:
            bs.wo = _flip(bs.wo, flip)
        return bs

    def eval_pdf_sample(self, bsdf_id, ctx, wo, u1, u2, active):
        bsdf_id, ctx, flip = self._side(bsdf_id, ctx, active)
        if flip is not None:
            wo = _flip(wo, flip)
        f, pdf, bs = self._dispatch("eval_pdf_sample", bsdf_id, ctx, active, wo, u1, u2)
        if flip is not None:
            bs.wo = _flip(bs.wo, flip)
        return f, pdf, bs


def _flip(v, mask):
    """Mirror a local direction through the surface where ``mask``."""
    return mi.Vector3f(v.x, v.y, dr.select(mask, -v.z, v.z))


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
