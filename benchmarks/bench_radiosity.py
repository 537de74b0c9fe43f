"""The ``radiosity`` solvers on the Cornell box: time vs error.

One subdivision (``--max-area``), one set of patch spectra, and for each solver a range
of stopping points (tolerances, or rays per iteration for stochastic Jacobi). Errors are
area-weighted relative L1 distances of the patch radiance (all bins):

- ``err_gs``: against the converged Gauss-Seidel solution (tolerance 1e-7) of the same
  form factors, i.e. the solver's own error (for stochastic Jacobi also the noise of
  the matrix's form factors, which it never uses);
- ``err_path``: against pbr's ``path`` at the patch centroids (``--path-spp`` per bin
  group), i.e. solver + discretisation error (+ the reference's noise, printed).

Jacobi and Gauss-Seidel share one form-factor matrix (its time is listed once and
included in their totals); progressive refinement computes columns on the fly
(included in its time); stochastic Jacobi casts its own rays.

    python benchmarks/bench_radiosity.py [--max-area 0.03] [--samples 16] [--path-spp 512]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import pbr


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-area", type=float, default=0.03)
    ap.add_argument("--samples", type=int, default=16, help="form-factor samples per patch pair")
    ap.add_argument("--path-spp", type=int, default=512)
    ap.add_argument("--backend", default="llvm")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    from pbr.plugins.props import Props
    from pbr.integrators.radiosity import RadiosityIntegrator, solvers
    from pbr.integrators.radiosity.reference import path_at_centroids

    scene = pbr.load_dict(pbr.cornell_box(32, 16))

    def integrator(**kw):
        return RadiosityIntegrator(Props({"type": "radiosity", "max_area": a.max_area,
                                          "form_factor_samples": a.samples, **kw}, "bench.integrator"))

    t0 = time.perf_counter()
    ref = integrator(tolerance=1e-7).solve(scene, progress=False)
    P, A = ref.patches, ref.patches.area
    t_ff = ref.stats.form_factor_seconds
    print(f"Cornell box, max_area {a.max_area}: {P.count} patches, {ref.bins.count} bins; setup "
          f"{ref.setup_seconds:.2f} s, dense form factors ({a.samples} samples/pair) {t_ff:.2f} s; "
          f"reference solve {time.perf_counter() - t0:.2f} s")
    t0 = time.perf_counter()
    path, se, valid = path_at_centroids(scene, P, ref.bins, spp=a.path_spp, seed=3)
    # Standard error of a patch's bin mean: bin groups are independent paths, the four
    # bins of a group share a path (taken as fully correlated: an upper bound).
    groups = len(ref.bins.groups())
    noise = float(np.sum(A[valid] * se[valid].mean(axis=1)) / np.sum(A[valid] * path[valid].mean(axis=1)))
    print(f"path reference: {a.path_spp} spp at {valid.sum()} centroids, {time.perf_counter() - t0:.2f} s; "
          f"relative standard error per bin {noise:.4f}, of the bin mean <= {noise / np.sqrt(groups):.4f}")

    def err(L, R, mask=slice(None)):
        m = A[mask, None]
        return float(np.sum(m * np.abs(L[mask] - R[mask])) / np.sum(m * R[mask]))

    rows = []

    def add(name, setting, seconds, L, iterations, rays=0):
        rows.append((name, setting, seconds, iterations, rays, err(L, ref.L),
                     err(L.mean(axis=1, keepdims=True), path.mean(axis=1, keepdims=True), valid)))

    for name in ("jacobi", "gauss_seidel"):
        for tol in (1e-2, 1e-3, 1e-4, 1e-6):
            L, H, st = getattr(solvers, name)(ref.F, ref.Le, ref.rho, A, tol, 10000, progress=False)
            add(name, f"tol {tol:g}", t_ff + st.seconds, L, st.iterations)
    for tol in (1e-2, 1e-3, 1e-4):
        s = integrator(solver="progressive", tolerance=tol).solve(scene, progress=False)
        add("progressive", f"tol {tol:g}", s.stats.seconds + s.stats.form_factor_seconds, s.L, s.stats.iterations)
    for rays in (1 << 16, 1 << 18, 1 << 20, 1 << 22):
        s = integrator(solver="stochastic_jacobi", tolerance=1e-3, rays_per_iteration=rays).solve(scene, progress=False)
        add("stochastic_jacobi", f"2^{rays.bit_length() - 1} rays/it", s.stats.seconds, s.L, s.stats.iterations,
            s.stats.rays)
    print(f"\n{'solver':<18} {'setting':<15} {'time s':>7} {'iters':>6} {'rays':>9} {'err_gs':>9} {'err_path':>9}")
    for name, setting, sec, it, rays, e1, e2 in rows:
        print(f"{name:<18} {setting:<15} {sec:7.2f} {it:6d} {rays:9d} {e1:9.2e} {e2:9.4f}")
    eb = ref.energy_balance(rays_per_patch=max(64, (1 << 20) // P.count))
    print(f"\nenergy balance of the reference: imbalance {eb.imbalance.mean():+.4f} "
          f"(per bin {eb.imbalance.min():+.4f} .. {eb.imbalance.max():+.4f}, audit stderr "
          f"{eb.relative_stderr.mean():.4f})")


if __name__ == "__main__":
    main()
