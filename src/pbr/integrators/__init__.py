"""Integrators, selected by the scene's ``integrator`` type."""

from .base import SamplingIntegrator  # noqa: F401
from .path import PathIntegrator
from .volpath import SimpleVolPathIntegrator, VolPathIntegrator

INTEGRATORS = {"path": PathIntegrator, "volpath": VolPathIntegrator, "volpathmis": VolPathIntegrator,
               "simplevolpath": SimpleVolPathIntegrator}
