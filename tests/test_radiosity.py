"""The ``radiosity`` integrator (Mitsuba has none): checked against analytic answers
(form factors of unit squares, a closed furnace box), against pbr's ``path`` (an
independent estimator: radiance at patch centroids and whole images), against itself
(the four solvers) and against energy conservation audited with fresh rays. Two
deliberately wrong form-factor matrices (a reciprocity mix-up and a closed-box row
normalisation) must fail the same checks."""

import math

import numpy as np
import pytest

import pbr
import mitsuba as mi
from pbr import validate
from pbr.plugins.props import Props
from pbr.integrators.radiosity import RadiosityIntegrator, RadiositySolution, solvers
from pbr.integrators.radiosity import formfactors as ff
from pbr.integrators.radiosity.bins import WavelengthBins
from pbr.integrators.radiosity.patches import Patches
from pbr.integrators.radiosity.reference import path_at_centroids



def T():
    """An identity transform of the active variant (chain .translate() etc.)."""
    return mi.ScalarTransform4f()


def radiosity(**kw) -> RadiosityIntegrator:
    return RadiosityIntegrator(Props({"type": "radiosity", **kw}, "scene.integrator"))


def patch_error(sol: RadiositySolution, ref: np.ndarray, valid: np.ndarray) -> tuple[float, float]:
    """(area-weighted relative L1 error, ratio of area-weighted means) of the patches'
    radiance (mean over bins) against a reference, over the valid patches."""
    A = sol.patches.area[valid]
    a, b = sol.L[valid].mean(axis=1), ref[valid].mean(axis=1)
    return float(np.sum(A * np.abs(a - b)) / np.sum(A * b)), float(np.sum(A * a) / np.sum(A * b))


def resolve(sol: RadiositySolution, F: np.ndarray) -> RadiositySolution:
    """The Gauss-Seidel solution of ``sol``'s scene with another form-factor matrix."""
    L, H, st = solvers.gauss_seidel(F, sol.Le, sol.rho, sol.patches.area, 1e-7, 500, progress=False)
    return RadiositySolution(sol.patches, sol.bins, sol.Le, sol.rho, L, H, st, F, sol.geometry)


# Sabotaged form factors: F_ji for F_ij (the reciprocity A_i F_ij = A_j F_ji forgotten),
# and rows scaled to sum to 1 (as if no light escaped through the box's open front).
SABOTAGE = {"transposed": lambda F: F.T.copy(),
            "row-normalised": lambda F: F / np.maximum(F.sum(axis=1, keepdims=True), 1e-12)}


@pytest.fixture(scope="module")
def box():
    return pbr.load_dict(pbr.cornell_box(24, 16))


@pytest.fixture(scope="module")
def coarse(box):
    """Gauss-Seidel on the Cornell box, 140 patches."""
    return radiosity(max_area=0.25, tolerance=1e-7, form_factor_samples=32).solve(box, progress=False)


@pytest.fixture(scope="module")
def coarse_path(box, coarse):
    """Path-traced radiance at the coarse solution's centroids (256 spp per bin group)."""
    return path_at_centroids(box, coarse.patches, coarse.bins, spp=256, seed=7)


# -- patches -----------------------------------------------------------------------------

def test_patches_tile_the_meshes_and_hits_find_their_patch():
    d = pbr.cornell_box(24, 16)
    # Blocks lifted off the floor (no coincident faces); one wall with flipped normals.
    d["small-box"]["to_world"] = T().translate([0.335, -0.6, 0.38]).rotate([0, 1, 0], -17).scale(0.3)
    d["large-box"]["to_world"] = T().translate([-0.33, -0.3, -0.28]).rotate([0, 1, 0], 18.25).scale([0.3, 0.61, 0.3])
    d["back"]["to_world"] = T().translate([0.0, 0.0, -1.0]).rotate([0, 1, 0], 180)
    d["back"]["flip_normals"] = True
    scene = pbr.load_dict(d)
    P = Patches(scene, 0.1)
    shapes = scene.mi_scene.shapes()
    assert np.isclose(P.area.sum(), sum(float(s.surface_area()[0]) for s in shapes), rtol=1e-5)
    assert P.area.max() <= 0.1 * (1 + 1e-6)
    # The floor: 2 triangles of area 2 -> n = 5 -> a welded (n+1)^2 grid of vertices.
    floor = P.shape == scene.shape_ids.index("floor")
    assert floor.sum() == 50 and len(np.unique(P.faces[floor])) == 36
    # Probe rays aimed at random points of every patch from its front.
    rng = np.random.default_rng(1)
    k = 8
    ids = np.repeat(np.arange(P.count), k)
    b = rng.random((len(ids), 2))
    b = np.where(b.sum(axis=1, keepdims=True) > 1, 1 - b, b)
    pts = P.p[ids, 0] + b[:, :1] * (P.p[ids, 1] - P.p[ids, 0]) + b[:, 1:] * (P.p[ids, 2] - P.p[ids, 0])
    n = P.normal[ids]
    o = pts + 1e-3 * n
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, j].astype(np.float32)) for j in range(3)]),
                   mi.Vector3f(*[mi.Float(-n[:, j].astype(np.float32)) for j in range(3)]))
    si, shape = scene.geometry.intersect(ray, True)
    patch, w = P.patch_of_hit(shape, si.prim_index, si.p, si.is_valid())
    found = np.array(patch) == ids
    print(f"probe rays that found their patch: {found.mean():.5f}")
    assert found.mean() > 0.995
    # Mitsuba's normal at the hit agrees with the patch's front (flip_normals included).
    sn = np.array(si.n).T
    assert np.all(np.einsum("ij,ij->i", sn[found], n[found]) > 0.999)
    # The blend weights reproduce the hit point from the patch corners.
    W = np.stack([np.array(x) for x in w], axis=1)[found]
    hp = np.einsum("ik,ikj->ij", W, P.p[ids[found]])
    assert np.abs(hp - np.array(si.p).T[found]).max() < 1e-4


# -- form factors ------------------------------------------------------------------------

def parallel_squares(a=1.0, c=1.0):
    """Form factor between coaxial parallel squares of side a at distance c."""
    X = Y = a / c
    x, y = 1 + X * X, 1 + Y * Y
    return 2 / (math.pi * X * Y) * (0.5 * math.log(x * y / (1 + X * X + Y * Y))
                                     + X * math.sqrt(y) * math.atan(X / math.sqrt(y))
                                     + Y * math.sqrt(x) * math.atan(Y / math.sqrt(x))
                                     - X * math.atan(X) - Y * math.atan(Y))


def perpendicular_squares():
    """Form factor between unit squares at a right angle sharing an edge (W = H = 1)."""
    W = H = 1.0
    s = W * W + H * H
    t = (math.log((1 + W * W) * (1 + H * H) / (1 + s))
         + W * W * math.log(W * W * (1 + s) / ((1 + W * W) * s))
         + H * H * math.log(H * H * (1 + s) / ((1 + H * H) * s)))
    return (W * math.atan(1 / W) + H * math.atan(1 / H) - math.sqrt(s) * math.atan(1 / math.sqrt(s))
            + 0.25 * t) / (math.pi * W)


def test_form_factors_match_analytic_squares():
    scene = pbr.load_dict({
        "type": "scene",
        "a": {"type": "rectangle", "to_world": T().scale(0.5)},
        "b": {"type": "rectangle", "to_world": T().translate([0, 0, 1]).rotate([1, 0, 0], 180).scale(0.5)},
        "c": {"type": "rectangle", "to_world": T().translate([0, 0.5, 0.5]).rotate([1, 0, 0], 90).scale(0.5)}})
    P = Patches(scene, 0.05)
    F = ff.form_factor_matrix(P, scene.geometry, 256, seed=0)
    A = P.area
    s = [P.shape == i for i in range(3)]

    def agg(i, j):
        return float((A[s[i], None] * F[np.ix_(s[i], s[j])]).sum() / A[s[i]].sum())
    par, perp = parallel_squares(), perpendicular_squares()
    print(f"parallel: {agg(0, 1):.5f} {agg(1, 0):.5f} (exact {par:.5f}); "
          f"perpendicular: {agg(0, 2):.5f} {agg(2, 0):.5f} (exact {perp:.5f})")
    for i, j, exact in ((0, 1, par), (1, 0, par), (0, 2, perp), (2, 0, perp)):
        assert abs(agg(i, j) / exact - 1) < 0.01
    # Cosine rays from square a land on b and c in the same proportions (binomial noise).
    src = np.repeat(np.nonzero(s[0])[0], (1 << 20) // int(s[0].sum()))
    dst = ff.shoot(P, scene.geometry, src, seed=3)
    for j, exact in ((1, par), (2, perp)):
        frac = np.isin(dst, np.nonzero(s[j])[0]).mean()
        z = (frac - exact) / math.sqrt(exact * (1 - exact) / len(src))
        print(f"cosine rays to {'bc'[j - 1]}: {frac:.5f}, z = {z:.2f}")
        assert abs(z) < 4


def test_closed_furnace_box_is_exact():
    """Inside a closed cube whose walls all emit Le and reflect rho = 0.5, L = Le / (1 -
    rho) everywhere, in every bin (every row of F sums to 1). Tolerances: the noise of a
    row sum with 64 samples per pair, measured over seeds, is 1.1% per patch and 0.05%
    for the mean over the 300 patches (no bias seen to 1e-4 with 256 samples)."""
    scene = pbr.load_dict({"type": "scene", "cube": {
        "type": "cube", "flip_normals": True, "bsdf": {"type": "diffuse", "reflectance": 0.5},
        "emitter": {"type": "area", "radiance": 1.0}}})
    sol = radiosity(max_area=0.1, tolerance=1e-8, form_factor_samples=64).solve(scene, progress=False)
    assert np.allclose(sol.rho, 0.5, rtol=1e-3) and np.ptp(sol.Le, axis=0).max() < 1e-6
    r = sol.L / (sol.Le / (1 - sol.rho))
    rows = sol.F.sum(axis=1)
    print(f"furnace: {sol.patches.count} patches, L / exact in [{r.min():.4f}, {r.max():.4f}], mean {r.mean():.5f}; "
          f"row sums {rows.mean():.5f} +- {rows.std():.5f}")
    assert abs(r.mean() - 1) < 2e-3
    assert np.all(np.abs(r - 1) < 0.06)


# -- solvers -----------------------------------------------------------------------------

def test_solvers_agree(box, coarse):
    ref, A = coarse.L, coarse.patches.area

    def rel(L):
        return float(np.sum(A[:, None] * np.abs(L - ref)) / np.sum(A[:, None] * ref))
    jac = radiosity(max_area=0.25, solver="jacobi", tolerance=1e-7, form_factor_samples=32).solve(box, progress=False)
    pr = radiosity(max_area=0.25, solver="progressive", tolerance=1e-5, form_factor_samples=32).solve(
        box, progress=False)
    sj = [radiosity(max_area=0.25, solver="stochastic_jacobi", tolerance=1e-3, rays_per_iteration=1 << 17,
                    seed=s).solve(box, progress=False) for s in (1, 2)]
    e_sj = [rel(s.L) for s in sj]
    noise = float(np.sum(A[:, None] * np.abs(sj[0].L - sj[1].L)) / np.sum(A[:, None] * ref)) / math.sqrt(2)
    ratio = [float(np.sum(A[:, None] * s.L) / np.sum(A[:, None] * ref)) for s in sj]
    print(f"vs Gauss-Seidel ({coarse.stats.iterations} sweeps): Jacobi {rel(jac.L):.2e} "
          f"({jac.stats.iterations} sweeps), progressive {rel(pr.L):.2e} ({pr.stats.iterations} shots), "
          f"stochastic Jacobi {e_sj[0]:.4f} {e_sj[1]:.4f} ({sj[0].stats.iterations} iterations, noise "
          f"{noise:.4f}), power ratios {ratio[0]:.4f} {ratio[1]:.4f}")
    assert coarse.stats.converged and jac.stats.converged and pr.stats.converged
    # Same system (progressive recomputes the matrix's columns with its random numbers).
    assert rel(jac.L) < 1e-5 and rel(pr.L) < 1e-4
    # Stochastic Jacobi never forms F: it agrees within its own noise (measured between
    # two seeds) plus the matrix's form-factor noise (32 samples per pair), 1%.
    for e, r in zip(e_sj, ratio):
        assert e < 1.5 * noise + 0.01
        assert abs(r - 1) < 0.01
    # The sweeps' residuals fall monotonically. (Not so the unshot power of progressive
    # refinement: estimated form factors are only reciprocal on average, so a shot can
    # hand its receivers slightly more than the shooter's unshot power.)
    for s in (coarse, jac):
        assert np.all(np.diff(s.stats.residuals) <= 1e-12)


# Spread of the energy imbalance from the form factors' own noise (5 seeds, 32 and 128
# samples per pair, audits of 2.3M rays): 0.29% of which the audit explains 0.2%.
FF_IMBALANCE_NOISE = 0.002


def test_energy_balance(coarse):
    """Emitted = absorbed + escaped per bin, within 4 sigma (audit noise and the
    form factors' noise)."""
    eb = coarse.energy_balance(rays_per_patch=16384)
    imb = eb.imbalance
    sigma = np.sqrt(eb.relative_stderr ** 2 + FF_IMBALANCE_NOISE ** 2)
    print("imbalance per bin:", np.array2string(imb[::4], precision=4),
          "sigma", np.array2string(sigma[::4], precision=4))
    assert np.all(np.abs(imb) < 4 * sigma)


@pytest.mark.parametrize("kind", sorted(SABOTAGE))
def test_wrong_form_factors_are_detected(coarse, coarse_path, kind):
    """Must fail: the energy audit and the path-traced reference both see the error."""
    bad = resolve(coarse, SABOTAGE[kind](coarse.F))
    eb = bad.energy_balance(rays_per_patch=4096)
    z = np.abs(eb.imbalance) / np.sqrt(eb.relative_stderr ** 2 + FF_IMBALANCE_NOISE ** 2)
    ref, _, valid = coarse_path
    err, ratio = patch_error(bad, ref, valid)
    print(f"{kind}: imbalance {eb.imbalance.mean():+.4f} (min z {z.min():.1f}); vs path: error {err:.3f}, "
          f"ratio {ratio:.3f}")
    assert np.all(z > 5) and abs(eb.imbalance.mean()) > 0.02
    assert err > 0.1 and abs(ratio - 1) > 0.05


# -- against path tracing -------------------------------------------------------------------

def test_patches_match_path_at_centroids(box, coarse, coarse_path):
    """Patch radiance vs path-traced radiance at the patch centroids, bin by bin; the
    discretisation error shrinks with the patch size."""
    fine = radiosity(max_area=0.1, tolerance=1e-6).solve(box, progress=False)
    out = []
    for sol in (coarse, fine):
        ref, se, valid = coarse_path if sol is coarse else path_at_centroids(box, sol.patches, sol.bins, spp=256,
                                                                             seed=8)
        noise = float(np.median(se[valid].mean(axis=1) / np.maximum(ref[valid].mean(axis=1), 1e-6)))
        out.append(patch_error(sol, ref, valid) + (noise, sol.patches.count))
    for err, ratio, noise, n in out:
        print(f"{n} patches: area-weighted relative error {err:.4f}, power ratio {ratio:.4f} "
              f"(path noise per bin {noise:.4f})")
    assert out[1][0] < 0.75 * out[0][0]
    assert out[1][0] < 0.05 and abs(out[1][1] - 1) < 0.03


def test_image_matches_path():
    """A 24x24 image: radiosity (smooth) against path tracing (unlimited depth). The
    radiosity image is biased by the discretisation (see the centroid test), so the
    statistical z-test does not apply. Stated tolerance: channel means within 5% and
    relative MSE below 0.02, over the pixels that do not see the light directly (its two
    pixels carry identical spectra in both, but their wavelength-sampling noise would
    dominate the image means: 4% between two radiosity renders at 16 and 64 spp)."""
    d = pbr.cornell_box(24, 16)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = {"type": "path", "max_depth": -1}
    ip = np.asarray(pbr.render(pbr.load_dict(d), spp=1024, seed=1))
    d["integrator"] = {"type": "radiosity", "max_area": 0.06, "smooth": True}
    scene = pbr.load_dict(d)
    ir = np.asarray(pbr.render(scene, spp=256, seed=2, progress=False))
    m = ip.max(axis=2) < 1.0
    ratio = ir[m].mean(axis=0) / ip[m].mean(axis=0)
    rmse = validate.relative_mse(ir[m], ip[m])
    print(f"radiosity / path channel means {np.array2string(ratio, precision=4)}, relMSE {rmse:.4f} "
          f"({m.sum()} pixels)")
    assert np.all(np.abs(ratio - 1) < 0.05) and rmse < 0.02
    # Must fail: the same render from a solution with row-normalised form factors.
    sol = scene.integrator.solution
    scene.integrator._solution = resolve(sol, SABOTAGE["row-normalised"](sol.F))
    bad = np.asarray(pbr.render(scene, spp=256, seed=2, progress=False))
    bad_ratio = bad[m].mean(axis=0) / ip[m].mean(axis=0)
    print(f"sabotaged: channel means {np.array2string(bad_ratio, precision=4)}")
    assert np.all(bad_ratio > 1.2)


# -- spectra, export, API ----------------------------------------------------------------------

def test_bins_colour(coarse):
    bins = WavelengthBins(32)
    # A unit spectrum has unit luminance in pbr's normalisation.
    assert abs((bins.xyz_weights() @ np.ones(32))[1] - 1) < 0.005
    # The light's emission, binned, converts back to its RGB value.
    light = coarse.Le.sum(axis=1) > 0
    rgb = bins.to_srgb(coarse.Le[light])
    print("binned light colour:", rgb[0])
    assert np.allclose(rgb, [18.387, 13.9873, 6.75357], rtol=0.02)


def test_textured_reflectance():
    """Textured reflectance: the solution takes each patch's value at its centroid; the
    render evaluates the texture at the hit (detail finer than the patches stays)."""
    d = pbr.cornell_box(16, 4)
    d["integrator"] = {"type": "radiosity", "max_area": 0.1}
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": 0.2, "color1": 0.8,
                                                             "to_uv": np.diag([2.0, 2.0, 1.0, 1.0])}}
    scene = pbr.load_dict(d)
    sol = scene.integrator.solve(scene, progress=False)
    floor = sol.patches.shape == scene.shape_ids.index("floor")
    vals = np.unique(np.round(sol.rho[floor].mean(axis=1), 3))
    print("floor reflectances:", vals)
    assert np.allclose(vals, [0.2, 0.8], atol=2e-3)
    img = np.asarray(pbr.render(scene, spp=4, progress=False))
    assert np.isfinite(img).all() and img.mean() > 0


def test_export(coarse, tmp_path):
    import trimesh
    P = coarse.patches
    v = int(P.faces[0, 0])
    adj = np.nonzero((P.faces == v).any(axis=1))[0]
    want = coarse.bins.to_srgb((P.area[adj, None] * coarse.L[adj]).sum(axis=0) / P.area[adj].sum())
    assert np.allclose(coarse.vertex_colors("linear")[v], want, rtol=1e-6)
    for ext in ("ply", "glb"):
        path = str(tmp_path / f"box.{ext}")
        coarse.export(path, space="srgb", exposure=-4)
        m = trimesh.load(path, force="mesh", process=False)
        assert len(m.faces) == P.count and len(m.vertices) == P.n_vertices
        if ext == "ply":
            c = np.asarray(m.visual.vertex_colors)[v, :3] / 255.0
            enc = pbr.image.linear_to_srgb(np.clip(want / 16, 0, 1))
            assert np.allclose(c, enc, atol=1 / 255 + 1e-6)


def test_cache_progress_and_registry(box):
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": "radiosity", "max_area": 0.5}
    scene = pbr.load_dict(d)
    integ = scene.integrator
    calls = []
    sol = integ.solve(scene, progress=lambda *a: calls.append(a))
    assert calls and calls[0][0] == "gauss_seidel" and calls[-1][2] <= integ.tolerance
    img = np.asarray(pbr.render(scene, spp=4, progress=False))
    assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.mean() > 0
    assert integ.solve(scene) is sol                       # cached
    assert integ.solve(scene, force=True, progress=False) is not sol   # re-solved on request


def _block_errors(img, ref, res, light):
    """(mean luminance ratio, median over 8x8-pixel blocks of the relative error of the
    blocks' mean luminance), the light's pixels left out."""
    lum = np.array([0.2126, 0.7152, 0.0722])
    x, r = np.asarray(img, np.float64) @ lum, ref @ lum
    ratio = x[~light].mean() / r[~light].mean()
    bx, br = (a.reshape(res // 8, 8, res // 8, 8).mean(axis=(1, 3)) for a in (x, r))
    keep = ~light.reshape(res // 8, 8, res // 8, 8).any(axis=(1, 3))
    return float(ratio), float(np.median(np.abs(bx - br)[keep] / br[keep]))


def test_default_patch_budget_is_accurate():
    """The default (``patch_budget`` 512: 504 patches on the Cornell box) renders the box
    within the error docs/integrators.md states: image mean within 3% of ``path``
    (max_depth -1, 2048 spp) and a median 8x8-block error below 4% (measured here, 32x32:
    mean 0.975, block median 1.6%; 64x64, bench_defaults.py: 0.986, 2.5%). Must fail: the
    old default, max_area 0 (the 36 mesh triangles), fails both (here 0.930 and 20%)."""
    res = 32
    d = pbr.cornell_box(res)
    ref_scene = pbr.load_dict({**d, "integrator": {"type": "path", "max_depth": -1}})
    ref = validate.estimate(lambda seed, spp: pbr.render(ref_scene, seed=seed, spp=spp, progress=False),
                            2048, batches=16, seed=21).mean
    light = (ref @ np.array([0.2126, 0.7152, 0.0722])) > 5.0
    out = {}
    for name, integ in (("default", {"type": "radiosity"}), ("max_area 0", {"type": "radiosity", "max_area": 0})):
        s = pbr.load_dict({**d, "integrator": integ})
        img = pbr.render(s, spp=64, seed=3, progress=False)
        out[name] = (*_block_errors(img, ref, res, light), s.integrator.solution.patches.count)
    mean, block, n = out["default"]
    assert n == 504 and abs(mean - 1) < 0.03 and block < 0.04, out
    mean0, block0, _ = out["max_area 0"]
    assert abs(mean0 - 1) > 0.03 and block0 > 0.04, out


@pytest.mark.parametrize("change, key", [
    (lambda d: d.update(ball={"type": "sphere", "radius": 0.2}), "scene.ball"),
    (lambda d: d["small-box"].update(bsdf={"type": "conductor"}), "scene.small-box.bsdf"),
    (lambda d: d["floor"].update(bsdf={"type": "twosided", "b": {"type": "diffuse"}}), "scene.floor.bsdf"),
    (lambda d: d.update(lamp={"type": "point", "position": [0, 0, 0]}), "scene.lamp"),
    (lambda d: d["small-box"].update(interior={"type": "homogeneous"}), "scene.small-box"),
])
def test_unsupported_scenes_name_the_key(change, key):
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": "radiosity"}
    change(d)
    scene = pbr.load_dict(d)
    with pytest.raises(pbr.SceneError, match=key.replace(".", r"\.") + ":"):
        scene.integrator.solve(scene, progress=False)


@pytest.mark.parametrize("params, key", [({"solver": "magic"}, "solver"), ({"max_area": -1}, "max_area"),
                                         ({"wavelength_bins": 2}, "wavelength_bins"), ({"rays": 4}, "rays")])
def test_bad_parameters(params, key):
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": "radiosity", **params}
    with pytest.raises(pbr.SceneError, match=rf"scene\.integrator\.{key}"):
        pbr.load_dict(d)


# -- scaled up --------------------------------------------------------------------------------

@pytest.mark.slow
def test_discretisation_error_shrinks(box):
    errs = []
    for area in (0.25, 0.06, 0.015):
        sol = radiosity(max_area=area, tolerance=1e-6).solve(box, progress=False)
        ref, _, valid = path_at_centroids(box, sol.patches, sol.bins, spp=1024, seed=11)
        errs.append(patch_error(sol, ref, valid))
        print(f"max_area {area}: {sol.patches.count} patches, error {errs[-1][0]:.4f}, ratio {errs[-1][1]:.4f}")
    assert errs[0][0] > errs[1][0] > errs[2][0]
    assert errs[2][0] < 0.025 and abs(errs[2][1] - 1) < 0.015


@pytest.mark.slow
def test_no_power_bias_without_contact():
    """The Cornell box's remaining ~1% deficit comes from faces in contact (blocks
    standing on or sunk into the floor: a patch partly hidden spreads its power over
    its hidden part too). With the blocks lifted it is gone."""
    d = pbr.cornell_box(24, 16)
    d["small-box"]["to_world"] = T().translate([0.335, -0.6, 0.38]).rotate([0, 1, 0], -17).scale(0.3)
    d["large-box"]["to_world"] = T().translate([-0.33, -0.3, -0.28]).rotate([0, 1, 0], 18.25).scale([0.3, 0.61, 0.3])
    scene = pbr.load_dict(d)
    sol = radiosity(max_area=0.015, tolerance=1e-6).solve(scene, progress=False)
    ref, _, valid = path_at_centroids(scene, sol.patches, sol.bins, spp=1024, seed=12)
    err, ratio = patch_error(sol, ref, valid)
    print(f"lifted blocks: {sol.patches.count} patches, error {err:.4f}, ratio {ratio:.4f}")
    assert err < 0.02 and abs(ratio - 1) < 0.005
