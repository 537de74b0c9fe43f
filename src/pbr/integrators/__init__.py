"""Integrators, selected by the scene's ``integrator`` type."""

from .base import SamplingIntegrator  # noqa: F401
from .path import PathIntegrator, PRBIntegrator
from .prbvolpath import PRBVolPathIntegrator
from .ptracer import ParticleTracerIntegrator
from .volpath import SimpleVolPathIntegrator, VolPathIntegrator
from .ao import AOIntegrator
from .aov import AOVIntegrator
from .direct import DirectIntegrator
from .randomwalk import RandomWalkIntegrator
from .simplepath import SimplePathIntegrator
from .whitted import WhittedIntegrator
from .sppm import SPPMIntegrator
from .radiosity import RadiosityIntegrator
from .bdpt import BDPTIntegrator

INTEGRATORS = {"path": PathIntegrator, "volpath": VolPathIntegrator, "volpathmis": VolPathIntegrator,
               "simplevolpath": SimpleVolPathIntegrator}
INTEGRATORS.update(prb=PRBIntegrator, prbvolpath=PRBVolPathIntegrator)
INTEGRATORS.update(ptracer=ParticleTracerIntegrator, lightpath=ParticleTracerIntegrator)
INTEGRATORS.update(whitted=WhittedIntegrator, direct=DirectIntegrator, randomwalk=RandomWalkIntegrator,
                   simplepath=SimplePathIntegrator, ambientocclusion=AOIntegrator, aov=AOVIntegrator)
INTEGRATORS.update(sppm=SPPMIntegrator)
INTEGRATORS.update(radiosity=RadiosityIntegrator)
INTEGRATORS.update(bdpt=BDPTIntegrator)
