"""``null``: an index-matched interface that lets light pass straight through (a Dirac
delta in the forward direction with unit weight). It marks medium boundaries and cut-out
(``mask``) regions."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .base import BSDF_TYPES, BSDFType, BSDFSample, TRANSMISSION, SPECULAR


def pass_through(wi, pdf, active) -> BSDFSample:
    """A forward-scattering delta sample of unit weight: a null lobe (Mitsuba's
    ``BSDFFlags::Null``, which its ``path`` does not count as a surface seen)."""
    return BSDFSample(-wi, dr.select(active, pdf, 0.0), mi.Float(1.0), mi.Bool(True),
                      dr.select(active, mi.Spectrum(1.0), 0.0), null=active)


@BSDF_TYPES.register("null")
class Null(BSDFType):
    """``null``: light passes unchanged (medium boundaries, cut-outs). No parameters."""

    name = "null"
    flags = TRANSMISSION | SPECULAR

    def add(self, loader, props) -> int:
        props.finish()
        self.instances.append(None)
        return len(self.instances) - 1

    def eval_pdf(self, ctx, idx, wo, active):
        return mi.Spectrum(0.0), mi.Float(0.0)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        return pass_through(ctx.si.wi, mi.Float(1.0), active)
