"""Solvers of the radiosity system, one spectrum (K bins) per patch:

    L = Le + rho * H,    H = F L          (radiance; radiosity B = pi L, H = E / pi)

with F the form factors (:mod:`.formfactors`), ``Le`` the emitted radiance and ``rho``
the reflectance of each patch. Every solver returns the exitant radiance ``L`` and the
gathered incident radiance ``H`` (so that ``L = Le + rho H`` holds exactly) and a
:class:`SolveStats`.

* ``jacobi``: L <- Le + rho (F L), all patches at once (a matrix product per sweep).
* ``gauss_seidel``: the same, patch by patch, each update using the newest values.
  Both stop when a sweep changes the total power sum_i A_i L_i (all bins) by less than
  ``tolerance`` (relative).
* ``progressive`` (Cohen et al. 1988): shoot the patch with the most unshot power
  A_i sum_k dL_ik; its form factors toward all receivers (a column of F) are computed on
  the fly and never stored.
* ``stochastic_jacobi`` (incremental, Bekaert et al.): each iteration casts
  ``rays_per_iteration`` cosine-distributed rays from the patches in proportion to their
  unshot power; a ray carries its source's unshot power to the front it lands on. Form
  factors are never formed. Unbiased; its noise falls as 1/sqrt(rays).
  Both shooting methods stop when the unshot power is below ``tolerance`` times the
  emitted power.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .formfactors import deposit, tally


@dataclass
class SolveStats:
    solver: str
    iterations: int = 0
    residuals: list = field(default_factory=list)   # per iteration (see the module doc)
    converged: bool = False
    seconds: float = 0.0            # the solve, form factors excluded
    form_factor_seconds: float = 0.0
    rays: int = 0                   # rays cast by the solver itself


def _gather(F, L):
    """H = F L (float32 product, float64 result)."""
    return (np.asarray(F, np.float32) @ L.astype(np.float32)).astype(np.float64)


def _power(L, area):
    return float(np.sum(area[:, None] * L))


class _Progress:
    """tqdm bar (where available) and/or a callback ``fn(solver, iteration, residual)``."""

    def __init__(self, solver, progress):
        self.solver, self.fn, self.bar = solver, progress if callable(progress) else None, None
        if progress is not False and not callable(progress):
            try:
                from tqdm.auto import tqdm
                unit = "shot" if solver == "progressive" else "it"
                self.bar = tqdm(desc=f"radiosity {solver}", unit=unit, leave=False)
            except ImportError:  # pragma: no cover
                pass

    def __call__(self, it, residual):
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(residual=f"{residual:.2e}", refresh=False)
        if self.fn is not None:
            self.fn(self.solver, it, residual)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _iterate(st: SolveStats, step, tolerance, max_iterations, progress) -> None:
    """Call ``step(iteration)`` until the residual it returns is at most ``tolerance``
    (``None``: nothing is left to do) or ``max_iterations`` is reached, recording the
    residuals in ``st`` and reporting them to ``progress``."""
    bar = _Progress(st.solver, progress)
    for it in range(1, max_iterations + 1):
        with np.errstate(invalid="ignore", over="ignore"):   # non-finite: detected below
            r = step(it)
        if r is None:
            st.converged = True
            break
        st.residuals.append(r)
        st.iterations = it
        bar(it, r)
        if r <= tolerance:
            st.converged = True
            break
        if not np.isfinite(r):      # NaN/inf radiosities: more iterations cannot help
            break                   # (not converged; the render counts the samples)
    bar.close()


def jacobi(F, Le, rho, area, tolerance, max_iterations, progress=None):
    st = SolveStats("jacobi")
    t0 = time.perf_counter()
    L = Le.copy()

    def sweep(it):
        nonlocal L
        L_new = Le + rho * _gather(F, L)
        r = _power(np.abs(L_new - L), area) / max(_power(L_new, area), 1e-300)
        L = L_new
        return r

    _iterate(st, sweep, tolerance, max_iterations, progress)
    H = _gather(F, L)
    st.seconds = time.perf_counter() - t0
    return Le + rho * H, H, st


def gauss_seidel(F, Le, rho, area, tolerance, max_iterations, progress=None):
    st = SolveStats("gauss_seidel")
    t0 = time.perf_counter()
    L = Le.copy()

    def sweep(it):
        change = 0.0
        for i in range(len(L)):
            new = Le[i] + rho[i] * (F[i] @ L)
            change += area[i] * float(np.abs(new - L[i]).sum())
            L[i] = new
        return change / max(_power(L, area), 1e-300)

    _iterate(st, sweep, tolerance, max_iterations, progress)
    H = _gather(F, L)
    st.seconds = time.perf_counter() - t0
    return Le + rho * H, H, st


def progressive(column, Le, rho, area, tolerance, max_iterations, progress=None):
    """``column(j)``: F[:, j] (the receivers' form factors toward shooter j)."""
    st = SolveStats("progressive")
    t0 = time.perf_counter()
    H = np.zeros_like(Le)
    unshot = Le.copy()
    emitted = max(_power(Le, area), 1e-300)
    unshot_power = area * unshot.sum(axis=1)

    def shoot(it):
        nonlocal unshot_power
        j = int(np.argmax(unshot_power))
        t1 = time.perf_counter()
        col = column(j)
        st.form_factor_seconds += time.perf_counter() - t1
        dH = col[:, None] * unshot[j][None, :]
        H[:] += dH
        unshot[j] = 0.0
        unshot[:] += rho * dH
        unshot_power = area * unshot.sum(axis=1)
        return float(unshot_power.sum()) / emitted

    _iterate(st, shoot, tolerance, max_iterations, progress)
    st.seconds = time.perf_counter() - t0 - st.form_factor_seconds
    return Le + rho * H, H, st


def stochastic_jacobi(shoot, Le, rho, area, rays_per_iteration, tolerance, max_iterations, seed=0,
                      progress=None):
    """``shoot(sources, seed)``: where one cosine ray from each source patch lands (a
    patch index for a front, ``N`` for a back face, ``N + 1`` for nothing). Rays are
    tallied per (source, destination) pair before their power is deposited."""
    st = SolveStats("stochastic_jacobi")
    t0 = time.perf_counter()
    N, K = Le.shape
    rng = np.random.default_rng(seed)
    H = np.zeros_like(Le)
    unshot = Le.copy()                                   # radiance not yet propagated
    emitted = max(_power(Le, area), 1e-300)

    def iteration(it):
        nonlocal unshot
        phi = np.pi * area[:, None] * unshot             # unshot power per bin
        w = phi.sum(axis=1)
        total = float(w.sum())
        if total <= 0:
            return None
        # Rays per source in proportion to its power (systematic sampling: the expected
        # count is exactly R p_i), each carrying phi_i / (R p_i).
        p = w / total
        cum = np.cumsum(p * rays_per_iteration)
        edges = np.floor(np.concatenate([[0.0], cum]) + rng.random())
        counts = np.diff(edges).astype(np.int64)
        src = np.repeat(np.arange(N), counts)
        dst = shoot(src, int(rng.integers(1 << 31)))
        st.rays += len(src)
        carry = np.where(p[:, None] > 0, phi / np.maximum(p * rays_per_iteration, 1e-300)[:, None], 0.0)
        received = deposit(*tally(src, dst, N), carry, N)
        dH = np.where(area[:, None] > 0, received / (np.pi * np.maximum(area, 1e-300))[:, None], 0.0)
        H[:] += dH
        unshot = rho * dH
        return _power(unshot, area) / emitted

    _iterate(st, iteration, tolerance, max_iterations, progress)
    st.seconds = time.perf_counter() - t0
    return Le + rho * H, H, st
