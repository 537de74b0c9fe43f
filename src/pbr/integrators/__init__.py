"""Integrators, one module each, registered in :data:`INTEGRATORS` where they are
defined; the scene's ``integrator`` type selects one. The camera-sample machinery they
share (passes, film, PRB adjoint passes) is :mod:`.base`."""

from .base import INTEGRATORS, SamplingIntegrator  # noqa: F401
from . import (ao, aov, bdpt, depth, direct, mlt, moment, path, prbvolpath, projective, ptracer, radiosity,  # noqa: F401
               randomwalk, simplepath, sppm, volpath, whitted)
