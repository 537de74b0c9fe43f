"""Light samplers (uniform, power, bvh) and emissive meshes as one light per triangle.

Sampler tests: for shading points at random, the frequencies with which ``sample`` picks
each light match ``pmf`` (chi-square, low-expectation cells pooled), the probability
``sample`` returns equals ``pmf`` of the light it returns, the probabilities sum to 1
(for the BVH: to the probability that some light is chosen, which is 1 wherever no light
can be ruled out), zero-power lights are never chosen. Render tests: emissive meshes
match Mitsuba; the BVH sampler's image equals the uniform sampler's on a scene with ~50
lights (pbr.validate); extreme radiances and distances stay finite."""

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import trimesh

import pbr
from pbr import validate
from pbr.lights.bvh import BoundsTable, BVHLightSampler, LightBVH, cone_union, ensure_table
from pbr.lights.lightsamplers import make_light_sampler

RES, SPP, BATCHES = 24, 1024, 16


# ------------------------------------------------------------------------------ helpers

def chi2_sf(x: float, k: int) -> float:
    """P(X > x) for a chi-square variable with ``k`` degrees of freedom."""
    a, z = 0.5 * k, 0.5 * x
    if z <= 0:
        return 1.0
    if z < a + 1:       # series for the lower regularised gamma function
        term = s = 1.0 / a
        n = a
        while abs(term) > 1e-15 * abs(s):
            n += 1
            term *= z / n
            s += term
        return max(0.0, 1.0 - s * math.exp(-z + a * math.log(z) - math.lgamma(a)))
    # continued fraction for the upper one (Lentz)
    b, c, d = z + 1 - a, 1e300, 1.0 / (z + 1 - a)
    h = d
    for i in range(1, 10000):
        an = -i * (i - a)
        b += 2
        d = an * d + b
        d = 1e-300 if abs(d) < 1e-300 else d
        c = b + an / c
        c = 1e-300 if abs(c) < 1e-300 else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1) < 1e-15:
            break
    return math.exp(-z + a * math.log(z) - math.lgamma(a)) * h


def chi2_test(observed, expected, min_expected=5.0):
    """(p-value, dof) with cells of low expectation pooled (in order of expectation)."""
    obs, exp = np.asarray(observed, float), np.asarray(expected, float)
    assert np.all(obs[exp == 0] == 0), "an outcome of zero probability occurred"
    keep = exp >= min_expected
    o, e = list(obs[keep]), list(exp[keep])
    order = np.argsort(exp[~keep])
    po, pe = obs[~keep][order], exp[~keep][order]
    acc_o = acc_e = 0.0
    for a, b in zip(po, pe):
        acc_o += a
        acc_e += b
        if acc_e >= min_expected:
            o.append(acc_o); e.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0 and e:
        o[-1] += acc_o; e[-1] += acc_e
    o, e = np.array(o), np.array(e)
    stat = float(np.sum((o - e) ** 2 / e))
    dof = len(e) - 1
    return chi2_sf(stat, dof), dof


def random_lights(rng, n=40):
    """Bounds of a varied light population: planar one- and two-sided emitters, spheres,
    point and spot lights, one infinite light (None), two lights of zero power."""
    items = []
    for i in range(n):
        c = rng.uniform(-4, 4, 3)
        kind = i % 5
        e = rng.uniform(0.0, 0.6, 3) if kind != 3 else np.zeros(3)
        w = rng.normal(size=3)
        cos_o, cos_e, two = {0: (1.0, 0.0, False), 1: (1.0, 0.0, True), 2: (-1.0, 0.0, False),
                             3: (-1.0, 0.0, False), 4: (0.9, 0.7, False)}[kind]
        items.append({"p_min": c - e, "p_max": c + e, "phi": float(rng.lognormal(0.0, 2.0)), "w": w,
                      "cos_theta_o": cos_o, "cos_theta_e": cos_e, "two_sided": two})
    items[5] = None
    items[7]["phi"] = 0.0
    items[11]["phi"] = 0.0
    powers = np.array([0.0 if b is None else b["phi"] for b in items])
    powers[5] = 3.0
    return items, powers


def _splat(v, n):
    return [mi.Float(np.full(n, float(x), np.float32)) for x in v]


def sample_counts(sampler, p, nrm, n_lights, N, rng):
    u = mi.Float(rng.random(N).astype(np.float32))
    P, Nn = mi.Point3f(*_splat(p, N)), mi.Normal3f(*_splat(nrm, N))
    light, q = sampler.sample(u, P, Nn, mi.Bool(True))
    q_again = sampler.pmf(light, P, Nn, mi.Bool(True))
    light, q, q_again = np.array(light), np.array(q), np.array(q_again)
    ok = q > 0
    np.testing.assert_allclose(q[ok], q_again[ok], rtol=1e-6)
    counts = np.bincount(light[ok], minlength=n_lights)
    pmf = np.array(sampler.pmf(mi.UInt32(np.arange(n_lights, dtype=np.uint32)), mi.Point3f(*map(float, p)),
                               mi.Normal3f(*map(float, nrm)), mi.Bool(True)), dtype=np.float64)
    return counts, int((~ok).sum()), pmf


SHADING = [((0.5, 0.2, -0.3), (0.0, 0.0, 1.0)), ((3.0, -2.0, 1.0), (0.6, 0.0, 0.8)),
           ((-6.0, 5.0, 7.0), (0.0, 0.0, 0.0)), ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))]


# ------------------------------------------------------------------------------ samplers

@pytest.mark.parametrize("kind", ["uniform", "power", "bvh"])
def test_sampled_frequencies_match_pmf(kind):
    rng = np.random.default_rng(7)
    items, powers = random_lights(rng)
    n = len(items)
    s = make_light_sampler(kind, powers, items)
    N = 1 << 20
    for p, nrm in SHADING:
        counts, failed, pmf = sample_counts(s, p, nrm, n, N, rng)
        total = pmf.sum()
        assert total <= 1.0 + 1e-5
        if kind != "bvh":
            assert abs(total - 1.0) < 1e-5
        else:
            ref = s.pmf_all_np(p, nrm)               # float64 reference walk of the tree
            np.testing.assert_allclose(pmf, ref, rtol=2e-4, atol=1e-9)
        pval, dof = chi2_test(np.append(counts, failed), N * np.append(pmf, max(0.0, 1.0 - total)))
        assert pval > 1e-4, (kind, p, pval, dof)
        if kind != "uniform":
            assert counts[7] == 0 and counts[11] == 0 and pmf[7] == 0 and pmf[11] == 0


@pytest.mark.parametrize("n", [3, 9, 40])
def test_shallow_and_deep_trees_sample_their_pmf(n):
    """Trees of at most ``UNROLL_DEPTH`` levels are descended by straight-line code,
    deeper ones by a loop: both sample with the frequencies of their pmf, which matches
    the float64 walk of the tree (the 3- and 9-light trees with 2 tree lights and with 7
    are the straight-line case; light 1 of 3 is the infinite one)."""
    from pbr.lights import bvh
    rng = np.random.default_rng(11)
    items, powers = random_lights(rng)
    items, powers = items[:n], powers[:n]
    if n == 3:
        items[1], powers[1] = None, 3.0
    s = make_light_sampler("bvh", powers, items)
    assert (s.bvh.max_depth <= bvh.UNROLL_DEPTH) == (n < 40)
    for p, nrm in SHADING[:2]:
        counts, failed, pmf = sample_counts(s, p, nrm, n, 1 << 18, rng)
        np.testing.assert_allclose(pmf, s.pmf_all_np(p, nrm), rtol=2e-4, atol=1e-9)
        pval, _ = chi2_test(np.append(counts, failed), (1 << 18) * np.append(pmf, max(0.0, 1.0 - pmf.sum())))
        assert pval > 1e-4, (n, p, pval)


def test_bvh_pmf_sums_to_one_where_no_light_is_ruled_out():
    """Omnidirectional / two-sided lights seen from points without a normal: every
    importance is positive, so the probabilities sum to exactly 1."""
    rng = np.random.default_rng(3)
    items = []
    for i in range(200):
        c = rng.uniform(-10, 10, 3)
        items.append({"p_min": c - 0.1, "p_max": c + 0.1, "phi": float(rng.lognormal(0, 1.5)),
                      "w": rng.normal(size=3), "cos_theta_o": -1.0 if i % 2 else 1.0,
                      "cos_theta_e": 0.0, "two_sided": bool(i % 2 == 0)})
    items.append(None)
    s = make_light_sampler("bvh", np.ones(len(items)), items)
    for p in rng.uniform(-12, 12, (5, 3)):
        pmf = np.array(s.pmf(mi.UInt32(np.arange(len(items), dtype=np.uint32)), mi.Point3f(*map(float, p)),
                             mi.Normal3f(0.0), mi.Bool(True)))
        assert abs(pmf.sum() - 1.0) < 1e-5
        assert abs(pmf[-1] - 0.5) < 1e-7          # pInfinite = 1 / (1 + 1)
        assert np.all(pmf[:-1] > 0)


def test_zero_power_lights_never_sampled():
    rng = np.random.default_rng(11)
    items, powers = random_lights(rng, 30)
    for k in (3, 8, 17):
        items[k]["phi"] = 0.0
        powers[k] = 0.0
    for kind in ("power", "bvh"):
        s = make_light_sampler(kind, powers, items)
        for p, nrm in SHADING:
            counts, _, pmf = sample_counts(s, p, nrm, len(items), 1 << 18, rng)
            zero = powers == 0
            assert counts[zero].sum() == 0 and np.all(pmf[zero] == 0), kind


def test_bvh_tree_bounds_are_conservative():
    """Every node's box and normal cone contain those of every light below it (what
    makes a zero importance mean no contribution), its power is its children's sum, its
    emission angle and sidedness are the widest; bit trails lead to the right leaves;
    the depth fits a 32-bit trail."""
    rng = np.random.default_rng(5)
    n = 3000
    c = rng.uniform(-20, 20, (n, 3))
    e = rng.uniform(0, 0.5, (n, 3))
    w = rng.normal(size=(n, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    cos_o = rng.choice([1.0, 0.8, 0.0, -1.0], n)
    cos_e = rng.choice([0.0, 0.5], n)
    two = rng.random(n) < 0.1
    b = LightBVH(c - e, c + e, rng.lognormal(0, 1, n), w, cos_o, cos_e, two)
    assert b.max_depth <= 32 and b.leaf.sum() == n
    members = [[] for _ in range(b.n_nodes)]
    for light in range(n):
        node, t = 0, int(b.trail[light])
        while True:
            members[node].append(light)
            if b.leaf[node]:
                assert b.child[node] == light
                break
            node = b.child[node] + (t & 1)
            t >>= 1
    for k in range(b.n_nodes):
        m = np.array(members[k])
        assert np.all(b.p_min[k] <= c[m] - e[m] + 1e-12) and np.all(b.p_max[k] >= c[m] + e[m] - 1e-12)
        spread = np.arccos(np.clip(b.cos_o[k], -1, 1))
        d = np.arccos(np.clip(w[m] @ b.w[k], -1, 1))
        assert spread >= np.pi - 1e-6 or np.all(d + np.arccos(cos_o[m]) <= spread + 1e-6)
        assert b.cos_e[k] <= cos_e[m].min() and b.two[k] == two[m].any()
    inner = np.flatnonzero(~b.leaf)
    np.testing.assert_allclose(b.phi[inner], b.phi[b.child[inner]] + b.phi[b.child[inner] + 1], rtol=1e-12)


def test_cone_union_contains_both():
    rng = np.random.default_rng(2)
    wa, wb = rng.normal(size=(2, 2000, 3))
    wa /= np.linalg.norm(wa, axis=1, keepdims=True)
    wb /= np.linalg.norm(wb, axis=1, keepdims=True)
    ca, cb = rng.uniform(-1, 1, (2, 2000))
    w, c = cone_union(wa, ca, wb, cb)
    t = np.arccos(c)
    for wx, cx in ((wa, ca), (wb, cb)):
        d = 2 * np.arctan2(np.linalg.norm(w - wx, axis=1), np.linalg.norm(w + wx, axis=1))
        assert np.all((t >= np.pi - 1e-7) | (d + np.arccos(cx) <= t + 1e-7))


def test_bvh_degenerate_inputs():
    """One light; all lights at one point; nothing but infinite lights."""
    one = [{"p_min": [0, 0, 1], "p_max": [0, 0, 1], "phi": 2.0, "w": [0, 0, -1], "cos_theta_o": 1.0,
            "cos_theta_e": 0.0, "two_sided": False}]
    s = BVHLightSampler(ensure_table(one, 1))
    light, q = s.sample(mi.Float([0.3, 0.7]), mi.Point3f([0, 0], [0, 0], [0, 2]), mi.Normal3f(0, 0, 1))
    assert list(np.array(q)) == [1.0, 0.0]               # the second point is behind the light
    # The 'bvh' light sampler of a one-light scene chooses that light everywhere (where
    # the BVH gives 0 the light contributes nothing): the same image, no importance.
    s = make_light_sampler("bvh", [1.0], one)
    assert not isinstance(s, BVHLightSampler) and s.kind == "uniform"
    light, q = s.sample(mi.Float([0.3, 0.7]), mi.Point3f([0, 0], [0, 0], [0, 2]), mi.Normal3f(0, 0, 1))
    assert np.all(np.array(light) == 0) and np.all(np.array(q) == 1.0)
    same = [dict(one[0], w=[0, 0, 1], cos_theta_o=-1.0) for _ in range(9)]
    s = make_light_sampler("bvh", np.ones(9), same)
    pmf = np.array(s.pmf(mi.UInt32(np.arange(9, dtype=np.uint32)), mi.Point3f(1, 1, 0), mi.Normal3f(0, 0, 1)))
    np.testing.assert_allclose(pmf, 1 / 9, rtol=1e-6)
    s = make_light_sampler("bvh", [1.0, 1.0], [None, None])
    light, q = s.sample(mi.Float([0.2, 0.8]), mi.Point3f(0), mi.Normal3f(0))
    assert list(np.array(light)) == [0, 1] and np.allclose(np.array(q), 0.5)


def test_bounds_table_from_batched_items():
    b = {"p_min": np.zeros((3, 3)), "p_max": np.ones((3, 3)), "phi": np.array([1.0, 2.0, 0.0]),
         "w": np.tile([0, 0, 2.0], (3, 1)), "cos_theta_o": np.ones(3), "cos_theta_e": np.zeros(3),
         "two_sided": np.zeros(3, bool)}
    t = BoundsTable.from_items([None, b, one_point()], [1, 3, 1])
    assert t.n == 5 and list(t.finite) == [False, True, True, True, True]
    assert np.allclose(t.w[1:4], [0, 0, 1]) and t.phi[3] == 0.0
    s = BVHLightSampler(t)
    assert list(s.kind_np) == [1, 0, 0, 2, 0]


def one_point():
    return {"p_min": [1, 2, 3], "p_max": [1, 2, 3], "phi": 1.0, "w": [0, 0, 1], "cos_theta_o": -1.0,
            "cos_theta_e": 0.0, "two_sided": False}


# ------------------------------------------------------------------------------ emissive meshes

def small_box(scale=1):
    d = pbr.cornell_box(RES * scale, 16)
    d["integrator"] = {"type": "path", "max_depth": 6, "hide_emitters": True}
    return d


def test_emissive_mesh_is_one_light_per_triangle(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.2)
    path = str(tmp_path / "ico.obj")
    mesh.export(path)
    d = small_box()
    d["ico"] = {"type": "obj", "filename": path, "face_normals": True,
                "to_world": mi.ScalarTransform4f().translate([0.0, 0.3, 0.0]),
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [2.0, 2.0, 2.0]}}}
    d["cubelight"] = {"type": "cube", "to_world": mi.ScalarTransform4f().translate([-0.5, -0.7, 0.4]).scale(0.1),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 3.0, 1.0]}}}
    scene = pbr.load_dict(d)
    lights = scene.lights
    assert len(lights) == 3                                   # emitters
    assert len(lights.local_of) == 1 + len(mesh.faces) + 12   # lights
    sl = np.array(scene.shape_light)
    ids = scene.shape_ids
    assert sl[ids.index("light")] == 1
    assert sl[ids.index("ico")] == 2 and sl[ids.index("cubelight")] == 2 + len(mesh.faces)
    # Power of a mesh's lights: pi * area * radiance per triangle.
    p = scene.integrator.light_sampler
    assert isinstance(p, BVHLightSampler)
    tri_phi = p.table.phi[1:1 + len(mesh.faces)]
    np.testing.assert_allclose(tri_phi.sum(), np.pi * mesh.area * 2.0, rtol=1e-3)
    # A ray hitting the mesh finds the hit triangle's light, whose NEE density agrees.
    o = mi.Point3f(0.0, 0.3, 0.9)
    ray = mi.Ray3f(o, mi.Vector3f(0.0, 0.0, -1.0))
    si, shape = scene.geometry.intersect(ray, mi.Bool(True))
    light = np.array(lights.light_of_hit(scene, shape, si, mi.Bool(True)))[0]
    assert light - 2 == np.array(si.prim_index)[0]


def test_triangle_sampling_density_matches_pdf():
    """Points sampled on one triangle light: the returned density equals pdf_Li at the
    point a ray in that direction hits, and E[1/pdf] is the triangle's solid angle."""
    d = small_box()
    d["cubelight"] = {"type": "cube", "to_world": mi.ScalarTransform4f().translate([0.2, 0.1, 0.3]).scale(0.2),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}
    scene = pbr.load_dict(d)
    area = scene.lights.area
    N = 1 << 16
    rng = np.random.default_rng(0)
    first = area.first(1)
    checked = 0
    for ref in ((0.25, 0.0, 0.9), (-0.5, 0.6, 0.25), (0.7, 0.6, 0.6)):
        si0 = dr.zeros(mi.SurfaceInteraction3f, N)
        si0.p = mi.Point3f(*ref)
        wl = pbr.spectrum.SampledWavelengths.sample_visible(mi.Float(rng.random(N).astype(np.float32)))
        u = mi.Point2f(*[mi.Float(rng.random(N).astype(np.float32)) for _ in range(2)])
        for tri in range(12):
            idx = mi.UInt32(np.full(N, first + tri, np.uint32))
            ls = area.sample_Li(idx, si0, u, wl, mi.Bool(True))
            pdf = np.array(ls.pdf)
            if not np.any(pdf > 0):
                continue
            si, shape = scene.geometry.intersect(mi.Ray3f(si0.p, ls.wi), mi.Bool(True))
            back = np.array(area.pdf_Li(idx, si0.p, si, mi.Bool(True)))
            hit = (np.array(si.prim_index) == tri) & (np.array(shape) == scene.shape_ids.index("cubelight"))
            ok = (pdf > 0) & hit
            assert ok.mean() > 0.5, (ref, tri)     # rays may meet another block first
            np.testing.assert_allclose(back[ok], pdf[ok], rtol=2e-3)
            # E[1/pdf] is the triangle's solid angle (Van Oosterom and Strackee).
            if np.all(pdf > 0):
                a, b, c = (np.array(t)[:, first + tri] - np.array(ref) for t in area.P)
                la, lb, lc = np.linalg.norm(a), np.linalg.norm(b), np.linalg.norm(c)
                omega = 2 * np.arctan2(abs(a @ np.cross(b, c)),
                                       la * lb * lc + (a @ b) * lc + (a @ c) * lb + (b @ c) * la)
                np.testing.assert_allclose(np.mean(1.0 / pdf), omega, rtol=0.02)
            checked += 1
    assert checked >= 6


# Emitters with an explicit (grey) BSDF, so that light reflected by emitting surfaces is
# compared too (without one, Mitsuba and pbr give an emitting shape a black diffuse BSDF).
GREY = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.4, 0.4, 0.4]}}


def _compare_with_mitsuba(d, scale, seed_a=31, seed_b=32):
    scene = pbr.load_dict(d)
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))  # noqa: E731
    res = validate.compare_renders(fa, validate.mitsuba_render_fn(d), spp=SPP * scale, batches=BATCHES,
                                   seed_a=seed_a, seed_b=seed_b)
    print(res.summary())
    return res


def test_emissive_cube_matches_mitsuba(scale):
    d = small_box(scale)
    del d["light"]
    d["cubelight"] = {"type": "cube",
                      "to_world": mi.ScalarTransform4f().translate([-0.3, 0.55, 0.1]).scale([0.25, 0.1, 0.2]),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 5.0, 3.0]}},
                      "bsdf": GREY}
    res = _compare_with_mitsuba(d, scale)
    assert res.passed, res.summary()


def test_emissive_obj_matches_mitsuba(tmp_path, scale):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    path = str(tmp_path / "ico.obj")
    mesh.export(path)
    d = small_box(scale)
    d["light"]["emitter"]["radiance"]["value"] = [4.0, 4.0, 4.0]
    d["ico"] = {"type": "obj", "filename": path, "face_normals": True,
                "to_world": mi.ScalarTransform4f().translate([0.3, 0.35, -0.2]),
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [2.0, 4.0, 8.0]}},
                "bsdf": GREY}
    res = _compare_with_mitsuba(d, scale)
    assert res.passed, res.summary()


# ------------------------------------------------------------------------------ renders

def many_lights_scene(sampler: str, n_lights=48, res=24, seed=1):
    """A floor with two blocks under ``n_lights`` small emissive rectangles of varied
    power and orientation, and one emissive cube (12 triangle lights)."""
    rng = np.random.default_rng(seed)
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": 4, "light_sampler": sampler},
         "sensor": {"type": "perspective", "fov": 50.0,
                    "to_world": T().look_at(origin=[0, 6, 9], target=[0, 0, 0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": 16}},
         "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(8),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.6]}}},
         "block1": {"type": "cube", "to_world": T().translate([-1.5, 0.8, 0]).scale(0.8)},
         "block2": {"type": "cube", "to_world": T().translate([1.8, 0.5, -1]).scale(0.5),
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}},
         "glow": {"type": "cube", "to_world": T().translate([0.3, 0.3, 1.8]).scale(0.3),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [2.0, 1.0, 0.4]}}}}
    for i in range(n_lights):
        pos = [rng.uniform(-5, 5), rng.uniform(1.5, 4.0), rng.uniform(-5, 4)]
        tgt = [rng.uniform(-3, 3), 0.0, rng.uniform(-3, 3)]
        L = float(rng.lognormal(1.0, 1.2))
        col = rng.uniform(0.3, 1.0, 3) * L
        d[f"l{i:03d}"] = {"type": "rectangle", "to_world": T().look_at(origin=pos, target=tgt, up=[0, 1, 0]).scale(0.15),
                          "emitter": {"type": "area", "radiance": {"type": "rgb", "value": list(map(float, col))}}}
    return d


def test_bvh_render_matches_uniform():
    fns = {}
    for kind in ("bvh", "uniform"):
        scene = pbr.load_dict(many_lights_scene(kind))
        fns[kind] = (lambda sc: (lambda seed=0, spp=0: np.asarray(pbr.render(sc, seed=seed, spp=spp))))(scene)
    res = validate.compare_renders(fns["bvh"], fns["uniform"], spp=1024, batches=BATCHES, seed_a=3, seed_b=4)
    print(res.summary())
    assert res.passed, res.summary()


class Biased:
    """A light sampler whose probabilities are off by a factor (samples unchanged)."""

    def __init__(self, sampler, factor):
        self.sampler, self.factor = sampler, factor

    def sample(self, u, p, n, active=True):
        light, q = self.sampler.sample(u, p, n, active)
        return light, q * self.factor

    def pmf(self, light, p, n, active=True):
        return self.sampler.pmf(light, p, n, active) * self.factor


def test_bvh_render_biased_sampler_fails():
    """The same comparison detects a sampler whose pmf disagrees with its samples."""
    scene = pbr.load_dict(many_lights_scene("bvh"))
    ref = pbr.load_dict(many_lights_scene("uniform"))
    integ, prepare = scene.integrator, scene.integrator.prepare

    def biased(scene, sensor=0):    # the integrator's own sampler, wrapped at every render
        prepare(scene, sensor)
        integ.light_sampler = Biased(integ.light_sampler, 1.3)

    integ.prepare = biased
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))  # noqa: E731
    fb = lambda seed=0, spp=0: np.asarray(pbr.render(ref, seed=seed, spp=spp))  # noqa: E731
    res = validate.compare_renders(fa, fb, spp=512, batches=BATCHES, seed_a=3, seed_b=4)
    assert not res.passed and res.mean_ratio < 1.0, res.summary()


@pytest.mark.parametrize("kind", ["uniform", "power", "bvh"])
def test_extreme_lights_stay_finite(kind):
    """Radiance 1e6 next to 1e-6, and a light 1e5 away: finite images and probabilities."""
    T = mi.ScalarTransform4f
    d = many_lights_scene(kind, n_lights=0)
    d["hot"] = {"type": "rectangle", "to_world": T().translate([0, 2.0, 0]).rotate([1, 0, 0], 90).scale(0.1),
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1e6, 1e6, 1e6]}}}
    d["cold"] = {"type": "rectangle", "to_world": T().translate([0.3, 2.0, 0]).rotate([1, 0, 0], 90).scale(0.1),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1e-6, 1e-6, 1e-6]}}}
    d["far"] = {"type": "sphere", "center": [0, 1e5, 3e4], "radius": 100.0,
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1e3, 1e3, 1e3]}}}
    scene = pbr.load_dict(d)
    img = np.asarray(pbr.render(scene, spp=16, seed=1))
    assert np.all(np.isfinite(img)) and img.mean() > 0     # (spectral noise may leave sRGB slightly < 0)
    n = len(scene.lights.local_of)
    pmf = np.array(scene.integrator.light_sampler.pmf(mi.UInt32(np.arange(n, dtype=np.uint32)),
                                                      mi.Point3f(0.5, 0.0, 0.5), mi.Normal3f(0, 1, 0)))
    # (the BVH may find no light where a node's bounds face the point but none of its
    # children's do: then it chooses nothing, as pbrt-v4 does)
    assert np.all(np.isfinite(pmf)) and 0.999 < pmf.sum() < 1 + 1e-5
    hot, cold, far = pmf[-3:]
    assert hot > 0 and far > 0
    # power: the cold light (1e-12 of the hot one's power) owns no float32 CDF interval,
    # so its probability is 0 (BSDF sampling alone finds it, with full MIS weight)
    assert cold > 0 if kind != "power" else cold >= 0
