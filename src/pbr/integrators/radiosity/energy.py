"""Energy balance of a radiosity solution, audited with fresh rays.

Power leaves each patch, pi A_i L_i per bin, and is traced by cosine-distributed rays
(independent of the rays or samples that made the form factors). A ray landing on a
front gives up (1 - rho) of its power there, on a back face all of it; a ray that hits
nothing escapes. A solution of L = Le + rho F L conserves energy exactly when

    emitted = sum_i pi A_i Le_i  =  absorbed + escaped,

so the relative imbalance measures what the solver, the form-factor normalisation and
the patch spectra got wrong, within the audit's own noise (its standard error is
measured across ``batches`` groups of rays).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .formfactors import deposit, shoot, tally


@dataclass
class EnergyBalance:
    emitted: np.ndarray       # (K,) W/nm in scene units
    absorbed: np.ndarray
    escaped: np.ndarray
    stderr: np.ndarray        # standard error of absorbed + escaped

    @property
    def imbalance(self) -> np.ndarray:
        """(absorbed + escaped - emitted) / emitted per bin (0 where nothing is emitted)."""
        e = self.emitted
        return np.where(e > 0, (self.absorbed + self.escaped - e) / np.where(e > 0, e, 1.0), 0.0)

    @property
    def relative_stderr(self) -> np.ndarray:
        e = self.emitted
        return np.where(e > 0, self.stderr / np.where(e > 0, e, 1.0), 0.0)


def energy_balance(solution, geo, rays_per_patch: int = 256, seed: int = 1, batches: int = 8) -> EnergyBalance:
    P = solution.patches
    N = P.count
    out = np.pi * P.area[:, None] * solution.L                       # (N, K)
    src = np.repeat(np.nonzero(out.sum(axis=1) > 0)[0], rays_per_patch)
    dst = shoot(P, geo, src, seed)
    batch = np.arange(len(src)) % batches
    w = out / rays_per_patch
    # Per batch: power absorbed at fronts (1 - rho), at back faces (all), escaped (all).
    absorbed, escaped = np.zeros((batches, out.shape[1])), np.zeros((batches, out.shape[1]))
    for b in range(batches):
        s, d, c = tally(src[batch == b], dst[batch == b], N)
        landed = deposit(s, d, c, w, N + 2)                               # (N + 2, K)
        absorbed[b] = (landed[:N] * (1.0 - solution.rho)).sum(axis=0) + landed[N]
        escaped[b] = landed[N + 1]
    per = (absorbed + escaped) * batches
    return EnergyBalance(np.pi * (P.area[:, None] * solution.Le).sum(axis=0), absorbed.sum(axis=0),
                         escaped.sum(axis=0), per.std(axis=0, ddof=1) / np.sqrt(batches))
