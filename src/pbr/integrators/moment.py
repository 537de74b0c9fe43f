"""``moment``: the first and second moments of nested integrators' samples (Mitsuba's
``moment``), from which per-pixel variances follow. Channels and conventions:
docs/integrators.md.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from .aov import AOVIntegrator
from .base import INTEGRATORS, PRIMAL, SamplingIntegrator, NestingIntegrator, nested_integrators
from .lightpath import LightTracingIntegrator
from .ptracer import ParticleTracerIntegrator
from .radiosity import RadiosityIntegrator
from .sppm import SPPMIntegrator


def _refuse(t, integrator):
    """Why ``integrator`` (type ``t``) cannot be nested in ``moment``, or None."""
    if isinstance(integrator, (AOVIntegrator, MomentIntegrator)):
        return f"a {t!r} integrator cannot be nested in 'moment' (its AOVs are not supported there)"
    if isinstance(integrator, (LightTracingIntegrator, ParticleTracerIntegrator, SPPMIntegrator,
                               RadiosityIntegrator)) or type(integrator).sample is SamplingIntegrator.sample:
        return (f"the {t!r} integrator has no per-sample estimate to take moments of (supported: integrators "
                "that trace camera samples, e.g. path, volpath, direct, depth)")
    return None


@INTEGRATORS.register("moment")
class MomentIntegrator(NestingIntegrator):
    """``moment`` (Mitsuba's): per camera sample, each nested integrator's radiance as XYZ
    and its square, averaged by the film: channels R, G, B (the first nested integrator's
    image), then ``key.X/Y/Z`` of each nested integrator in order, then ``m2_key.X/Y/Z``
    (Mitsuba 3.9's order; :attr:`aov_names`). :meth:`pixel_variance` turns them into the
    variance of each pixel's mean. Nested integrators must give each camera sample its
    whole estimate (``path``, ``volpath``, ``direct``, ``depth``, ...). No derivatives.

    =========  ======  =======  ==========================================================
    name       type    default  meaning
    =========  ======  =======  ==========================================================
    (any key)  plugin  -        a nested integrator (at least one) whose moments are taken
    =========  ======  =======  ==========================================================
    """

    name = "moment"
    supports_films = False        # develops its own channels (RGB films only)
    light_sampler_type = "uniform"   # the moments sample no light; nested integrators use their own

    def __init__(self, props):
        super().__init__(props)
        self.nested = nested_integrators(props, _refuse)
        props.finish()
        if not self.nested:
            raise props.error(None, "expected at least one nested integrator")
        first = [f"{key}.{c}" for key, _ in self.nested for c in "XYZ"]
        self.aov_names = first + [f"m2_{n}" for n in first]

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        """(H, W, 3 + len(aov_names)) tensor (class docstring)."""
        self.prepare(scene, sensor)

        def radiance(rng, ray, wl, inside):
            L0, xyz = None, []
            for _, integ in self.nested:
                L = integ.sample(scene, rng, mi.Ray3f(ray), wl, PRIMAL, None, None, inside)[0]
                L0 = L if L0 is None else L0
                xyz += list(spec.to_xyz(L, wl))
            return L0, xyz + [dr.square(c) for c in xyz]

        return self._film(scene, sensor, seed, spp, radiance, progress)

    def pixel_variance(self, image, spp: int) -> np.ndarray:
        """Variance of each pixel's XYZ mean, per nested integrator: (H, W, n, 3), from an
        image this integrator rendered with ``spp`` samples per pixel (exact in
        expectation for a box filter; with wider filters, an approximation)."""
        img = np.asarray(image, dtype=np.float64)
        n = len(self.nested)
        m1 = img[..., 3:3 + 3 * n].reshape(*img.shape[:2], n, 3)
        m2 = img[..., 3 + 3 * n:3 + 6 * n].reshape(*img.shape[:2], n, 3)
        return np.maximum(m2 - m1 * m1, 0.0) / max(spp - 1, 1)
