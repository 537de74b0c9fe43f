"""The BSDF interface shared by every BSDF family.

Directions are in the local shading frame (normal = +z), both pointing away from the
surface; ``wi`` is toward the previous vertex (the camera side). As in Mitsuba,
``eval`` returns f(wi, wo) * |cos(theta_o)| (the cosine-weighted BSDF), and
``sample`` returns a :class:`BSDFSample` whose ``weight`` is eval / pdf.

Each family is a :class:`BSDFType`: it parses its instances from scene dicts and keeps
their parameters in one structure-of-arrays table, indexed by ``idx`` in kernels.
"""

from __future__ import annotations

import mitsuba as mi

from ..backend import Struct, VariantStruct
from ..plugins.registry import Registry
from ..spectrum import SampledWavelengths

# Type name -> BSDF family (each family registers itself in its module).
BSDF_TYPES = Registry("BSDF")

# Lobe flags (Python ints: a kernel only contains code for flags a scene has).
REFLECTION, TRANSMISSION, DIFFUSE, GLOSSY, SPECULAR = 1, 2, 4, 8, 16


class BSDFSample(Struct):
    """A sampled direction: ``wo`` (local), its solid-angle ``pdf``, the relative IOR
    ``eta`` crossed, whether the lobe was a Dirac delta, ``weight`` = f cos / pdf,
    ``terminate``: the direction depends on the wavelength (dispersion), so only the
    first wavelength may continue (pbrt-v4's TerminateSecondary), and ``null``: the lobe
    passes light straight on (Mitsuba's ``BSDFFlags::Null``, e.g. a thin dielectric's
    transmission), which volumetric path tracing does not count as a bounce."""

    _fields = {"wo": "Vector3f", "pdf": "Float", "eta": "Float", "delta": "Bool", "weight": "Spectrum",
               "terminate": "Bool", "null": "Bool"}
    _defaults = {"eta": 1.0}


class ShadingContext(metaclass=VariantStruct):
    """What a BSDF needs at a hit: the Mitsuba surface interaction (``si.wi`` local,
    ``si.uv``) and the sampled wavelengths. A Dr.Jit struct, so that ``dr.switch`` can
    pass it to the families (which read textures through their own reference, set by
    ``BSDFSet.build``)."""

    _fields = {"si": "SurfaceInteraction3f", "wl": SampledWavelengths}
    # Whether the context carries a ``regularize`` mask (:class:`RegularizedContext`): a
    # class attribute, so that it survives Dr.Jit rebuilding the struct in loops and calls.
    regularizing = False

    def __init__(self, si=None, wl=None):
        self.si = si if si is not None else mi.SurfaceInteraction3f()
        self.wl = wl if wl is not None else SampledWavelengths()

    def at(self, si):
        """The same context (class and other fields) at the surface interaction ``si``."""
        return ShadingContext(si, self.wl)


class RegularizedContext(ShadingContext):
    """A shading context with pbrt-v4's BSDF regularisation: where ``regularize`` is set
    (a path integrator's ``regularize`` after the path's first non-specular bounce),
    microfacet roughness alpha below 0.3 becomes clamp(2 alpha, 0.1, 0.3)
    (:func:`~.microfacet.regularized_alpha`) and smooth conductors and dielectrics become
    rough ones of alpha 0.1, so that light sampling reaches caustic paths (biased, less
    noisy)."""

    _fields = {**ShadingContext._fields, "regularize": "Bool"}
    regularizing = True

    def __init__(self, si=None, wl=None, regularize=None):
        super().__init__(si, wl)
        self.regularize = regularize if regularize is not None else mi.Bool(False)

    def at(self, si):
        return RegularizedContext(si, self.wl, self.regularize)


def shading_context(si, wl, regularize=None) -> ShadingContext:
    """The context of a path vertex: a :class:`RegularizedContext` when ``regularize``
    (a mask) is given, else a plain one (no regularisation code is traced)."""
    return ShadingContext(si, wl) if regularize is None else RegularizedContext(si, wl, regularize)


class BSDFType:
    """A BSDF family: parse instances, build the parameter table, evaluate/sample."""

    name = ""
    flags = 0
    # Whether ``sample``'s weight is a random estimate that ``eval`` does not reproduce (a
    # layered BSDF's walk): the path replay then differentiates the sample's own weight.
    stochastic = False
    # Whether a lobe passes light straight on (Mitsuba's Null flag): then
    # ``null_transmission(ctx, idx, active)`` gives its weight, which shadow rays of the
    # volumetric integrators are multiplied by when they cross the surface.
    null_lobe = False
    # Whether a sample can cross into another medium (``BSDFSample.eta`` other than 1):
    # path tracers keep the relative IOR for Russian roulette only where some family does.
    refracts = False
    # Whether pbrt-v4's regularisation (:class:`RegularizedContext`) turns the family's
    # delta lobes into glossy ones (smooth conductors and dielectrics): light sampling at
    # its vertices then pays off.
    regularizes_to_glossy = False

    def __init__(self):
        self.instances: list = []

    def add(self, loader, props) -> int:
        """Parse one instance from ``props`` (a :class:`Props`) and return its index."""
        raise NotImplementedError

    textures = None  # the scene's TextureSet, set by BSDFSet.build

    def build(self) -> None:
        """(Re)build the Dr.Jit parameter table from the instances."""

    def eval_pdf(self, ctx, idx, wo, active):
        """(f * |cos theta_o|, pdf of sampling wo) for local direction ``wo``."""
        raise NotImplementedError

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        raise NotImplementedError

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        """``eval_pdf(wo)`` and ``sample(u1, u2)`` at once; families override it to share
        texture lookups between the two (one vertex needs both)."""
        f, pdf = self.eval_pdf(ctx, idx, wo, active)
        return f, pdf, self.sample(ctx, idx, u1, u2, active)
