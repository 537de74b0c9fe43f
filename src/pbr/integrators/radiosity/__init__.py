"""``radiosity``: the finite-element solution of diffuse global illumination: patches
(:mod:`.patches`) of constant radiance on spectral bins (:mod:`.bins`), form factors
(:mod:`.formfactors`), four solvers (:mod:`.solvers`); the solution is viewed from any
camera. How a hit is shaded from it: docs/integrators.md.
"""

from __future__ import annotations

import time
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np

from ...bsdfs.base import ShadingContext
from ...plugins.props import SceneError
from ..base import INTEGRATORS, SamplingIntegrator, PRIMAL
from . import solvers
from .bins import WavelengthBins
from .energy import energy_balance
from .export import export_mesh, vertex_colors, vertex_values
from .formfactors import form_factor_column, form_factor_matrix, shoot
from .patches import Patches, check_materials, max_area_for

SOLVERS = ("gauss_seidel", "jacobi", "progressive", "stochastic_jacobi")
MAX_DENSE_PATCHES = 16384   # the dense matrix of the Jacobi and Gauss-Seidel solvers: 1 GiB


class RadiositySolution:
    """A solved scene: ``patches``, ``bins``, and per patch and bin (N, K) arrays ``Le``
    (emitted radiance), ``rho`` (reflectance), ``H`` (gathered incident radiance) and
    ``L = Le + rho H`` (exitant radiance); ``F`` the dense form factors (dense solvers
    only) and ``stats`` (:class:`.solvers.SolveStats`)."""

    def __init__(self, patches, bins, Le, rho, L, H, stats, F=None, geometry=None, setup_seconds=0.0):
        self.patches, self.bins = patches, bins
        self.Le, self.rho, self.L, self.H = Le, rho, L, H
        self.stats, self.F, self.geometry = stats, F, geometry
        self.setup_seconds = setup_seconds
        self._tables = {}

    @property
    def radiosity(self) -> np.ndarray:
        """B = pi L per patch and bin."""
        return np.pi * self.L

    def rgb(self) -> np.ndarray:
        """(N, 3) linear sRGB of each patch's exitant radiance."""
        return self.bins.to_srgb(self.L)

    def vertex_values(self, values=None) -> np.ndarray:
        return vertex_values(self.patches, self.L if values is None else values)

    def vertex_colors(self, space: str = "linear") -> np.ndarray:
        return vertex_colors(self, space)

    def export(self, path: str, space: str = "srgb", exposure: float = 0.0):
        """Write the subdivided meshes with vertex colours (PLY, GLB, ... by extension)."""
        return export_mesh(self, path, space, exposure)

    def energy_balance(self, rays_per_patch: int = 256, seed: int = 1, batches: int = 8):
        return energy_balance(self, self.geometry, rays_per_patch, seed, batches)

    def table(self, smooth: bool) -> mi.Float:
        """``H`` per patch (flat) or per vertex (smooth), flattened for :meth:`bins.lookup`."""
        if smooth not in self._tables:
            H = self.vertex_values(self.H) if smooth else self.H
            self._tables[smooth] = mi.Float(np.ascontiguousarray(H, np.float32).ravel())
        return self._tables[smooth]


def _form_factor_bar(progress, n):
    """A tqdm bar (fraction of receivers) for the dense matrix of large scenes."""
    if progress is not None or n < 2048:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=1.0, desc="radiosity form factors", leave=False, bar_format="{l_bar}{bar}| {elapsed}")


@INTEGRATORS.register("radiosity")
class RadiosityIntegrator(SamplingIntegrator):
    """``radiosity``: the finite-element solution of diffuse global illumination, solved
    once per scene and viewed from any camera. Triangle meshes, one-sided ``diffuse``
    BSDFs and ``area`` emitters only.

    ===================  ======  ============  ============================================================
    name                 type    default       meaning
    ===================  ======  ============  ============================================================
    solver               string  gauss_seidel  'jacobi', 'gauss_seidel', 'progressive' or
                                               'stochastic_jacobi'
    max_area             float   auto          largest patch area (0: the mesh triangles as given); not
                                               given: the smallest that keeps within patch_budget
    patch_budget         int     512           most patches when max_area is not given (measured on
                                               the Cornell box: docs/integrators.md)
    wavelength_bins      int     32            spectral bins of the solution (>= 4)
    max_iterations       int     10000         iteration limit of the solvers
    tolerance            float   1e-4          relative change of the total power (jacobi, gauss_seidel) or
                                               unshot power (shooting solvers) at which they stop
    form_factor_samples  int     16            ray samples per form factor
    rays_per_iteration   int     1048576       rays per stochastic_jacobi iteration
    smooth               bool    false         interpolate vertex values (else flat per patch)
    seed                 int     0             seed of the form factors and rays
    ===================  ======  ============  ============================================================
    """

    supports_moving_shapes = False   # its patches are the static shapes'
    name = "radiosity"

    def __init__(self, props):
        super().__init__(props)
        self.solver = props.string("solver", "gauss_seidel", choices=SOLVERS)
        # max_area not given: the finest uniform subdivision within patch_budget patches
        self.max_area = props.float("max_area", 0.0, min=0.0) if props.has("max_area") else None
        self.patch_budget = props.int("patch_budget", 512, min=1)
        self.wavelength_bins = props.int("wavelength_bins", 32, min=4)
        self.max_iterations = props.int("max_iterations", 10000, min=1)
        self.tolerance = props.float("tolerance", 1e-4, min=0.0)
        self.form_factor_samples = props.int("form_factor_samples", 16, min=1)
        self.rays_per_iteration = props.int("rays_per_iteration", 1 << 20, min=1)
        self.smooth = props.bool("smooth", False)
        self.seed = props.int("seed", 0, min=0)
        props.finish()
        self._scene = None
        self._solution = None

    # -- the solution -------------------------------------------------------------------
    @property
    def solution(self) -> RadiositySolution | None:
        """The cached solution (None before the first solve)."""
        return self._solution

    def solve(self, scene, force: bool = False, progress=None) -> RadiositySolution:
        """Solve ``scene`` (once: cached until ``force`` or another scene). ``progress``:
        None (a tqdm bar), False, or ``fn(solver, iteration, residual)``."""
        if not force and self._solution is not None and self._scene is not None and self._scene() is scene:
            return self._solution
        with dr.suspend_grad():
            sol = self._solve(scene, progress)
        self._scene, self._solution = weakref.ref(scene), sol
        return sol

    def _solve(self, scene, progress):
        t0 = time.perf_counter()
        check_materials(scene)
        max_area = self.max_area if self.max_area is not None else max_area_for(scene, self.patch_budget)
        patches = Patches(scene, max_area)
        bins = WavelengthBins(self.wavelength_bins)
        Le, rho = patches.spectra(scene, bins)
        geo = scene.geometry
        setup = time.perf_counter() - t0
        args = (Le, rho, patches.area, self.tolerance, self.max_iterations)
        S, seed, F = self.form_factor_samples, self.seed, None
        if self.solver in ("jacobi", "gauss_seidel"):
            if patches.count > MAX_DENSE_PATCHES:
                raise SceneError(f"{self.path}.max_area: {patches.count} patches exceed the {MAX_DENSE_PATCHES} "
                                 f"of the dense solvers; use solver 'progressive' or 'stochastic_jacobi', "
                                 f"or a larger max_area")
            t1 = time.perf_counter()
            bar = _form_factor_bar(progress, patches.count)
            F = form_factor_matrix(patches, geo, S, seed, bar and (lambda f: bar.update(f - bar.n)))
            if bar:
                bar.close()
            t_ff = time.perf_counter() - t1
            L, H, st = getattr(solvers, self.solver)(F, *args, progress=progress)
            st.form_factor_seconds = t_ff
        elif self.solver == "progressive":
            L, H, st = solvers.progressive(lambda j: form_factor_column(patches, geo, j, S, seed), *args,
                                           progress=progress)
        else:
            L, H, st = solvers.stochastic_jacobi(lambda src, s: shoot(patches, geo, src, s), Le, rho, patches.area,
                                                 self.rays_per_iteration, self.tolerance, self.max_iterations,
                                                 seed=seed, progress=progress)
        return RadiositySolution(patches, bins, Le, rho, L, H, st, F, geo, setup)

    # -- rendering ----------------------------------------------------------------------
    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        self.solve(scene, progress=progress)
        return super().render(scene, sensor=sensor, seed=seed, spp=spp, progress=progress)

    def sample(self, scene, rng, ray, wl, mode, dL, L_in, active):
        sol = self.solve(scene)
        si, shape = scene.geometry.intersect(ray, active)
        hit = active & si.is_valid()
        patch, w = sol.patches.patch_of_hit(shape, si.prim_index, si.p, hit)
        table = sol.table(self.smooth)
        if self.smooth:
            H = mi.Spectrum(0.0)
            for k in range(3):
                v = dr.gather(mi.UInt32, sol.patches.dr_faces[k], patch, hit)
                H += w[k] * sol.bins.lookup(table, v, wl.lambda_, hit)
        else:
            H = sol.bins.lookup(table, patch, wl.lambda_, hit)
        bsdf = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
        f, _ = scene.bsdfs.eval_pdf(bsdf, ShadingContext(si, wl), mi.Vector3f(0, 0, 1), hit)
        light = scene.lights.light_of_hit(scene, shape, si, hit)
        Le = scene.lights.L(light - 1, si, wl, hit & (light > 0))
        return dr.select(hit, Le + f * dr.pi * H, 0.0), hit
