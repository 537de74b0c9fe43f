"""Integrators, selected by the scene's ``integrator`` type."""

from .base import SamplingIntegrator  # noqa: F401
from .path import PathIntegrator

INTEGRATORS = {"path": PathIntegrator}
