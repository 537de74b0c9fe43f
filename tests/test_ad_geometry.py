"""Derivatives with respect to geometry: traverse's geometry keys, interior derivatives
(hits that move with the shapes) in ``prb`` and ``prbvolpath``, forward and reverse, against
finite differences and Mitsuba's ``prb`` on the same scene.

Interior scene: a diffuse mesh plane filling the view under a point light, translated
along its normal (the shading changes continuously: no visibility discontinuity).
Finite differences use the same seed on both sides (a point light and no indirect light:
the only randomness is the pixel filter's, so the difference is smooth in the step) with
a central step of 0.01 (the error of the O(h^2) term is below 1e-4 relative here).
Must-fail: the light direction toward a point light computed detached in the local
frame (a bug this test caught while the code was written: 5.9% too large) is rejected.
"""

from __future__ import annotations

import importlib

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr

RES = 16
PLANE_OBJ = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"


def ramp(h=RES, w=RES) -> np.ndarray:
    """A horizontal ramp weight image (H, W, 3): the loss is <ramp, image>."""
    return (np.linspace(0.0, 1.0, w)[None, :, None] * np.ones((h, w, 3))).astype(np.float32)


@pytest.fixture(scope="module")
def plane_obj(tmp_path_factory):
    path = tmp_path_factory.mktemp("geom") / "plane.obj"
    path.write_text(PLANE_OBJ)
    return str(path)


def lit_plane(obj, integrator="prb"):
    """A diffuse mesh plane (the 'plane' key) under a point light, seen from above."""
    T = mi.ScalarTransform4f
    return {"type": "scene", "integrator": {"type": integrator, "max_depth": 3},
            "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": RES, "height": RES}},
            "light": {"type": "point", "position": [0.5, 0.5, 2.0], "intensity": {"type": "rgb", "value": [5, 5, 5]}},
            "plane": {"type": "obj", "filename": obj, "bsdf": {"type": "diffuse"}, "to_world": T().scale(3.0)}}


def _shifted(v0, t, axis=2):
    pos = dr.unravel(mi.Point3f, type(v0)(v0))
    pos[axis] += t
    return dr.ravel(pos)


def _fd(render, params, key, v0, h=0.01, spp=512, seed=3):
    """Central finite difference of <ramp, image> along z for vertex positions ``v0``."""
    w = ramp()
    out = []
    for s in (h, -h):
        params[key] = _shifted(dr.detach(v0), s)
        params.update()
        out.append(float((np.asarray(render(spp, seed)) * w).sum()))
    params[key] = dr.detach(v0)
    params.update()
    return (out[0] - out[1]) / (2 * h)


def _ad(render, params, key, v0, mode, spp=64, seed=1):
    t = mi.Float(0.0)
    dr.enable_grad(t)
    params[key] = _shifted(dr.detach(v0), t)
    params.update()
    img = render(spp, seed)
    w = mi.TensorXf(ramp())
    if mode == "forward":
        dr.forward(t)
        g = float(dr.sum(dr.grad(img) * w).array[0])
    else:
        dr.backward(dr.sum(img * w))
        g = float(dr.grad(t)[0])
    params[key] = dr.detach(v0)
    params.update()
    return g


# -- parameters --------------------------------------------------------------------------------
def test_geometry_keys_and_flags(plane_obj):
    d = lit_plane(plane_obj)
    d["lamp"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 3]).scale(0.1),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1, 1, 1]}}}
    d["ball"] = {"type": "sphere", "radius": 0.2, "bsdf": {"type": "diffuse"}}
    p = pbr.traverse(pbr.load_dict(d))
    nd = int(mi.ParamFlags.NonDifferentiable)
    for key in ("plane.vertex_positions", "plane.vertex_normals", "plane.vertex_texcoords", "ball.to_world"):
        assert not p.flags(key) & nd, key
    assert p.flags("plane.vertex_positions") & int(mi.ParamFlags.Discontinuous)
    # faces and the geometry of emissive shapes (host-built light tables) are not differentiable
    assert p.flags("plane.faces") & nd and p.flags("lamp.to_world") & nd
    q = p.copy()
    q.keep(None)
    assert "plane.vertex_positions" in q and "ball.to_world" in q and "lamp.to_world" not in q


def test_geometry_update_rebuilds_only_the_geometry(plane_obj):
    scene = pbr.load_dict(lit_plane(plane_obj))
    p = pbr.traverse(scene)
    before = np.asarray(pbr.render(scene, spp=4))
    builds = []
    build = scene.build
    scene.build = lambda: (builds.append(1), build())
    v0 = dr.detach(p["plane.vertex_positions"])
    p["plane.vertex_positions"] = _shifted(v0, 0.5)      # toward the light: brighter
    p.update()
    after = np.asarray(pbr.render(scene, spp=4))
    assert builds == [] and after.mean() > 1.2 * before.mean()


def test_geometry_update_inside_plain_dr_freeze_is_refused(plane_obj):
    """Only pbr.freeze rebuilds Mitsuba's acceleration structure (built on the host, which
    a recording does not replay) after each frozen call (tests/test_freeze_geometry.py);
    under dr.freeze alone a replay would trace stale geometry, so pbr says so."""
    scene = pbr.load_dict(lit_plane(plane_obj))
    p = pbr.traverse(scene)
    v0 = dr.detach(p["plane.vertex_positions"])
    scene_state = importlib.import_module("pbr.freeze").scene_state

    @dr.freeze(state_fn=lambda params, z: scene_state(params.scene))
    def step(params, z):
        params["plane.vertex_positions"] = v0 + z      # (no scatter: nothing left dirty)
        params.update()
        return pbr.render(params.scene, spp=1, seed=dr.opaque(mi.UInt32, 0))

    with pytest.raises(RuntimeError) as e:
        step(p, mi.Float(0.1))
    chain, x = [], e.value
    while x is not None:
        chain.append(str(x))
        x = x.__cause__ or x.__context__
    assert any("plane.vertex_positions cannot be updated inside a dr.freeze-recorded function" in m
               and "use pbr.freeze" in m for m in chain), chain


def test_integrators_without_geometry_derivatives_refuse(plane_obj):
    scene = pbr.load_dict(lit_plane(plane_obj, "volpath"))
    p = pbr.traverse(scene)
    dr.enable_grad(p["plane.vertex_positions"])
    p.update()
    with pytest.raises(NotImplementedError, match="'volpath' integrator does not differentiate.*prb"):
        pbr.render(scene, p)


# -- interior derivatives -----------------------------------------------------------------------
@pytest.mark.parametrize("integrator", ["prb", "prbvolpath"])
def test_interior_derivative_matches_fd_forward_reverse_and_mitsuba(plane_obj, integrator):
    scene = pbr.load_dict(lit_plane(plane_obj, integrator))
    p = pbr.traverse(scene)
    key = "plane.vertex_positions"
    v0 = dr.detach(p[key])

    def render(spp, seed):
        return pbr.render(scene, p, spp=spp, seed=seed)

    fd = _fd(render, p, key, v0)
    fwd = _ad(render, p, key, v0, "forward")
    rev = _ad(render, p, key, v0, "reverse")
    assert fd > 10.0                            # the quantity does change
    assert abs(fwd - rev) <= 1e-3 * abs(fd), (fwd, rev)
    assert abs(rev - fd) <= 0.02 * abs(fd), (rev, fd)
    # Mitsuba's prb (llvm_ad_spectral) on the same scene (its prbvolpath agrees with it
    # on surfaces; measured 44.24 vs FD 44.35, pbr 44.22)
    ms = mi.load_dict({**lit_plane(plane_obj), "integrator": {"type": "prb", "max_depth": 3}}, optimize=False)
    mp = mi.traverse(ms)
    mv0 = mi.Float(np.array(mp[key]))

    def mrender(spp, seed):
        return mi.render(ms, mp, spp=spp, seed=seed)

    g_mi = _ad(mrender, mp, key, mv0, "reverse", spp=256)
    assert abs(rev - g_mi) <= 0.02 * abs(g_mi), (rev, g_mi)


# -- boundary derivatives (projective integrators) ------------------------------------------------
# Scenes: an icosphere (trimesh, watertight) that moves along x. Gradients are
# d <ramp, image> / dx, estimated in K independent batches (new seeds), compared by a
# z-score with the standard errors of both sides.
Z_MAX = 4.0
T = mi.ScalarTransform4f


def _sphere_obj(path, radius):
    trimesh = pytest.importorskip("trimesh")
    m = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    with open(path, "w") as f:
        f.writelines(f"v {x} {y} {z}\n" for x, y, z in m.vertices)
        f.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in m.faces)
    return str(path)


@pytest.fixture(scope="module")
def ball_obj(tmp_path_factory):
    return _sphere_obj(tmp_path_factory.mktemp("geom") / "ball.obj", 0.5)


@pytest.fixture(scope="module")
def occluder_obj(tmp_path_factory):
    return _sphere_obj(tmp_path_factory.mktemp("geom") / "occ.obj", 0.3)


def ball_before_lamp(obj, integrator="direct_projective", res=RES):
    """A black icosphere ('ball') in front of an area light that fills the background:
    primary visibility only (the ball reflects nothing, so the first-hit term is off:
    sppi = 0)."""
    return {"type": "scene", "integrator": {"type": integrator, "sppi": 0},
            "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": res, "height": res}},
            "ball": {"type": "obj", "filename": obj,
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}},
            "lamp": {"type": "rectangle", "to_world": T().translate([0, 0, -1]).scale(2),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 0.8, 0.6]}}}}


def shadow_on_floor(obj, integrator="direct_projective", res=RES):
    """A black icosphere ('occ') between a small area light and a grey floor: its shadow
    (and its silhouette against the floor) moves with it."""
    return {"type": "scene", "integrator": {"type": integrator},
            "sensor": {"type": "perspective", "fov": 45, "to_world": T().look_at([0, -3, 3], [0, 0, 0], [0, 0, 1]),
                       "film": {"type": "hdrfilm", "width": res, "height": res}},
            "occ": {"type": "obj", "filename": obj, "to_world": T().translate([0, 0, 0.8]),
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}},
            "floor": {"type": "rectangle", "to_world": T().scale(2),
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.7]}}},
            "lamp": {"type": "rectangle", "to_world": T().translate([0, 0, 2.5]).rotate([1, 0, 0], 180).scale(0.5),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [4.0, 4.0, 4.0]}}}}


class _Mover:
    """Moves mesh ``key`` of ``params`` along x (detached shifts, or an attached one)."""

    def __init__(self, params, key):
        self.p, self.key = params, key
        self.v0 = mi.Float(np.array(dr.detach(params[key])))

    def set(self, t):
        pos = dr.unravel(mi.Point3f, mi.Float(self.v0))
        pos.x += t
        self.p[self.key] = dr.ravel(pos)
        self.p.update()


def _stats(xs):
    xs = np.asarray(xs, np.float64)
    return float(xs.mean()), float(xs.std(ddof=1) / np.sqrt(len(xs)))


def _z(a, b):
    return abs(a[0] - b[0]) / np.hypot(a[1], b[1])


def fd_batches(render, mover, res, k, spp, h=0.02, seed0=100):
    w = ramp(res, res)
    out = []
    for i in range(k):
        vals = []
        for s in (h, -h):
            mover.set(s)
            vals.append(float((np.asarray(render(spp, seed0 + i)) * w).sum()))
        out.append((vals[0] - vals[1]) / (2 * h))
    mover.set(0.0)
    return _stats(out)


def ad_batches(render, mover, res, k, spp, mode="reverse", seed0=1):
    w = mi.TensorXf(ramp(res, res))
    out = []
    for i in range(k):
        t = mi.Float(0.0)
        dr.enable_grad(t)
        mover.set(t)
        img = render(spp, seed0 + i)
        if mode == "forward":
            dr.forward(t)
            out.append(float(dr.sum(dr.grad(img) * w).array[0]))
        else:
            dr.backward(dr.sum(img * w))
            out.append(float(dr.grad(t)[0]))
    mover.set(0.0)
    return _stats(out) if k > 1 else out[0]


def test_split_vertex_cube_is_welded():
    """Mitsuba's cube has 24 vertices (4 per face); welded, it has the 12 edges of a cube,
    each between two faces (the 6 face diagonals are coplanar and dropped)."""
    from pbr.integrators.projective import EdgeSet
    scene = pbr.load_dict({"type": "scene", "integrator": {"type": "direct_projective"},
                           "box": {"type": "cube", "bsdf": {"type": "diffuse"}}})
    edges = EdgeSet(scene)
    assert edges.count == 12 and bool(dr.all(edges.has_d)) and edges.n_vertices == 8


def test_mesh_edges():
    """A quad's diagonal (coplanar faces) is dropped, its sides are boundary edges; a
    tetrahedron's six edges each have two faces; a non-manifold edge is kept per face."""
    from pbr.integrators.projective import _mesh_edges
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    a, b, c, d = _mesh_edges(np.array([[0, 1, 2], [0, 2, 3]]), quad)
    assert sorted(zip(a.tolist(), b.tolist())) == [(0, 1), (0, 3), (1, 2), (2, 3)] and (d == -1).all()
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    a, b, c, d = _mesh_edges(np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]), tet)
    assert len(a) == 6 and (d >= 0).all() and (c != d).all()
    fan = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0.5], [0, 0, 1]], float)
    a, b, c, d = _mesh_edges(np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]]), fan)
    assert len(a) == 9 and sum((x, y) == (0, 1) for x, y in zip(a.tolist(), b.tolist())) == 3


def test_projective_parameters_are_mitsubas():
    scene = pbr.load_dict({"type": "scene", "integrator": {"type": "prb_projective", "sppc": 4, "sppp": 8, "sppi": 2,
                                                            "guiding": "grid", "guiding_proj": False,
                                                            "proj_seed_spp": 16, "max_depth": 3, "rr_depth": 2},
                           "box": {"type": "cube"}})
    i = scene.integrator
    assert (i.spp_c, i.spp_p, i.spp_i, i.max_depth, i.rr_depth) == (4, 8, 2, 3, 2)
    # Mitsuba's rule: 0 turns a term off, the render's spp wins over the others
    assert i._counts(scene, 0, 16) == (16, 16, 16) and i._counts(scene, 0, 0) == (4, 8, 2)
    i.spp_i, i.spp_p = 0, None
    assert i._counts(scene, 0, 16) == (16, 16, 0) and i._counts(scene, 0, 0)[1] == scene.spp
    with pytest.raises(pbr.SceneError, match="guiding"):
        pbr.load_dict({"type": "scene", "integrator": {"type": "direct_projective", "guiding": "tree"},
                       "box": {"type": "cube"}})


def test_primary_silhouette_matches_fd_mitsuba_and_needs_the_boundary(ball_obj):
    res = 16
    scene = pbr.load_dict(ball_before_lamp(ball_obj, res=res))
    p = pbr.traverse(scene)
    mover = _Mover(p, "ball.vertex_positions")

    def render(spp, seed, integrator=None):
        return pbr.render(scene, p, spp=spp, seed=seed, integrator=integrator)

    fd = fd_batches(render, mover, res, 4, 2048)
    ad = ad_batches(render, mover, res, 4, 64)
    assert _z(ad, fd) < Z_MAX, (ad, fd)
    # forward == reverse on the same samples
    fwd = ad_batches(render, mover, res, 1, 32, "forward")
    rev = ad_batches(render, mover, res, 1, 32, "reverse")
    assert abs(fwd - rev) < 1e-3 * abs(rev), (fwd, rev)
    # must fail: prb has the interior derivative only
    no_boundary = ad_batches(lambda spp, seed: render(spp, seed, {"type": "prb", "max_depth": 2}), mover, res, 4, 64)
    assert _z(no_boundary, fd) > 3 * Z_MAX and abs(no_boundary[0]) < 0.1 * abs(fd[0]), (no_boundary, fd)
    # Mitsuba's direct_projective in its RGB variant of pbr's backend (llvm_ad_rgb on the
    # CPU; its spectral variant is off, see docs/inverse.md)
    variant = mi.variant()
    try:
        mi.set_variant(variant.replace("_spectral", "_rgb"))
        ms = mi.load_dict(ball_before_lamp(ball_obj, res=res), optimize=False)
        mp = mi.traverse(ms)
        mm = _Mover(mp, "ball.vertex_positions")
        ref = ad_batches(lambda spp, seed: mi.render(ms, mp, spp=spp, seed=seed)[..., :3], mm, res, 4, 64, seed0=50)
    finally:
        mi.set_variant(variant)
    print(f"primary silhouette: pbr {ad}, FD {fd}, prb {no_boundary}, Mitsuba rgb {ref}")
    assert _z(ad, ref) < Z_MAX, (ad, ref)


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["direct_projective", "prb_projective"])
def test_primary_silhouette_within_5_percent_of_fd(ball_obj, integrator):
    """The issue's requirement (pbr is spectral; Mitsuba 3.9's spectral prb_projective is
    10.6% off on a similar check): within 5% of finite differences on a watertight mesh."""
    res = 24
    scene = pbr.load_dict(ball_before_lamp(ball_obj, integrator, res=res))
    p = pbr.traverse(scene)
    mover = _Mover(p, "ball.vertex_positions")

    def render(spp, seed):
        return pbr.render(scene, p, spp=spp, seed=seed)

    fd = fd_batches(render, mover, res, 8, 4096)
    ad = ad_batches(render, mover, res, 8, 128)
    print(f"{integrator}: pbr {ad}, FD {fd}")
    assert _z(ad, fd) < Z_MAX and abs(ad[0] - fd[0]) < 0.05 * abs(fd[0]), (ad, fd)


@pytest.mark.slow
def test_shadow_boundary_matches_fd_and_needs_the_first_hit_term(occluder_obj):
    """A black occluder moving between a small area light and a floor: its silhouette
    against the floor (primary) and its shadow (first-hit term). Measured: FD -4.99 +-
    0.06; the primary term alone -1.70, the first-hit term -3.3 (noisy: edges are chosen
    without guiding)."""
    res = RES
    scene = pbr.load_dict(shadow_on_floor(occluder_obj, res=res))
    p = pbr.traverse(scene)
    mover = _Mover(p, "occ.vertex_positions")

    def render(spp, seed, integrator=None):
        return pbr.render(scene, p, spp=spp, seed=seed, integrator=integrator)

    fd = fd_batches(render, mover, res, 4, 2048)
    ad = ad_batches(render, mover, res, 6, 1024)
    # must fail: without the first-hit term (sppi = 0 turns it off, as in Mitsuba)
    primary = ad_batches(lambda spp, seed: render(spp, seed, {"type": "direct_projective", "sppi": 0}),
                         mover, res, 1, 1024)
    print(f"shadow: pbr {ad}, FD {fd}, primary only ~{primary}")
    assert _z(ad, fd) < Z_MAX and abs(ad[0] - fd[0]) < 0.25 * abs(fd[0]), (ad, fd)
    assert abs(primary - fd[0]) > 0.4 * abs(fd[0]), (primary, fd)


def box_before_lamp(res=RES):
    """Mitsuba's split-vertex cube (black) before an area light, seen at an angle
    (primary visibility only: sppi = 0)."""
    return {"type": "scene", "integrator": {"type": "direct_projective", "sppi": 0},
            "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at([1.5, 1.2, 4], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": res, "height": res}},
            "box": {"type": "cube", "to_world": T().scale(0.4),
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}},
            "lamp": {"type": "rectangle", "to_world": T().translate([0, 0, -1]).scale(3),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 0.8, 0.6]}}}}


def test_split_vertex_cube_silhouette_is_not_doubled():
    """Mitsuba's cube has its seams split (24 vertices): Mitsuba 3.9's projective
    integrators take the seams for silhouettes and double the term (measured: -38.8 +- 0.9
    in llvm_ad_rgb vs FD -20.2 +- 0.5); pbr welds them (-20.5 +- 0.1)."""
    res = RES
    scene = pbr.load_dict(box_before_lamp(res))
    p = pbr.traverse(scene)
    mover = _Mover(p, "box.vertex_positions")

    def render(spp, seed):
        return pbr.render(scene, p, spp=spp, seed=seed)

    fd = fd_batches(render, mover, res, 4, 2048)
    ad = ad_batches(render, mover, res, 4, 64)
    print(f"cube: pbr {ad}, FD {fd}")
    assert _z(ad, fd) < Z_MAX, (ad, fd)
    assert _z((2 * ad[0], 2 * ad[1]), fd) > Z_MAX      # a doubled term would be detected


class _CameraMover:
    """Moves the sensor along world x (detached shifts, or an attached one)."""

    def __init__(self, params, key="sensor.to_world"):
        self.p, self.key = params, key
        self.m0 = np.array(params[key].matrix, dtype=np.float64).reshape(4, 4)

    def set(self, t):
        if isinstance(t, float):
            m = self.m0.copy()
            m[0, 3] += t
            self.p[self.key] = mi.Transform4f(m.tolist())
        else:
            m = mi.Matrix4f(self.m0.tolist())
            m[0][3] = m[0][3] + t
            self.p[self.key] = mi.Transform4f(m)
        self.p.update()


def test_camera_translation_matches_fd(ball_obj):
    """Moving the camera by +x is moving the scene by -x: FD 20.13 +- 0.92 (16x16); the
    primary boundary term follows the camera's projection. Border pixels: the film drops
    samples outside it, so edges outside the film (here the light's) do not count, and a
    border pixel's filter is normalised over the film (a first version counted them:
    16.5 instead of 21.3)."""
    res = RES
    scene = pbr.load_dict(ball_before_lamp(ball_obj, res=res))
    p = pbr.traverse(scene)
    assert not p.flags("sensor.to_world") & int(mi.ParamFlags.NonDifferentiable)
    mover = _CameraMover(p)

    def render(spp, seed, integrator=None):
        return pbr.render(scene, p, spp=spp, seed=seed, integrator=integrator)

    fd = fd_batches(render, mover, res, 4, 2048)
    ad = ad_batches(render, mover, res, 4, 64)
    fwd = ad_batches(render, mover, res, 1, 32, "forward")
    rev = ad_batches(render, mover, res, 1, 32, "reverse")
    no_boundary = ad_batches(lambda spp, seed: render(spp, seed, {"type": "direct_projective", "sppp": 0}),
                             mover, res, 4, 64)
    print(f"camera: pbr {ad}, FD {fd}, without the primary term {no_boundary}")
    assert _z(ad, fd) < Z_MAX, (ad, fd)
    assert abs(fwd - rev) < 1e-3 * abs(rev), (fwd, rev)
    assert _z(no_boundary, fd) > 3 * Z_MAX, (no_boundary, fd)
    # integrators without camera derivatives refuse
    t = mi.Float(0.0)
    dr.enable_grad(t)
    mover.set(t)
    with pytest.raises(NotImplementedError, match="'prb' integrator does not differentiate.*prb_projective"):
        render(4, 0, {"type": "prb"})
    mover.set(0.0)


def test_first_hit_term_forward_equals_reverse(occluder_obj):
    """The shadow scene's derivative (all three terms) in forward and reverse mode on the
    same samples."""
    res = 12
    scene = pbr.load_dict(shadow_on_floor(occluder_obj, res=res))
    p = pbr.traverse(scene)
    mover = _Mover(p, "occ.vertex_positions")

    def render(spp, seed):
        return pbr.render(scene, p, spp=spp, seed=seed)

    fwd = ad_batches(render, mover, res, 1, 16, "forward")
    rev = ad_batches(render, mover, res, 1, 16, "reverse")
    assert abs(rev) > 0.1 and abs(fwd - rev) < 1e-3 * abs(rev), (fwd, rev)


def glossy_reflection(res=RES, sppi=None, occluder=None):
    """A black box (Mitsuba's cube; or ``occluder``, a dict ``{key: shape}``) standing on a
    rough metal floor under a white sky, turned about the vertical: seen directly and in
    the floor's glossy reflection."""
    integrator = {"type": "prb_projective", "max_depth": 3}
    if sppi is not None:
        integrator["sppi"] = sppi
    if occluder is None:
        occluder = {"box": {"type": "cube", "to_world": T().translate([0, 0.6, 0.6]).rotate([0, 0, 1], 20).scale(0.3),
                            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}}}
    return {"type": "scene", "integrator": integrator,
            "sensor": {"type": "perspective", "fov": 45, "to_world": T().look_at([0, -3, 1.2], [0, 0, 0.3], [0, 0, 1]),
                       "film": {"type": "hdrfilm", "width": res, "height": res}},
            **occluder,
            "floor": {"type": "rectangle", "to_world": T().scale(3), "bsdf": {"type": "roughconductor", "alpha": 0.15}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}


class _Turner(_Mover):
    """Turns mesh ``key`` about the vertical axis through (0, 0.6)."""

    def set(self, t):
        pos = dr.unravel(mi.Point3f, mi.Float(self.v0))
        x, y = pos.x, pos.y - 0.6
        cs, sn = dr.cos(mi.Float(t)), dr.sin(mi.Float(t))
        self.p[self.key] = dr.ravel(mi.Point3f(cs * x - sn * y, sn * x + cs * y + 0.6, pos.z))
        self.p.update()


@pytest.mark.slow
def test_rotating_mesh_in_a_glossy_reflection(tmp_path):
    """Indirect visibility: the box's silhouette in the floor's reflection is a
    discontinuity of the light reaching the floor (prb_projective's first-hit term).
    Measured (16x16): FD -14.82 +- 0.61 (-14.72 +- 0.16 at 8x8192), pbr -14.67 +- 0.05
    (-14.50 +- 0.05 at 8x1024); without the first-hit term (sppi = 0) -8.25 +- 0.04,
    rejected."""
    res = RES
    out = {}
    for name, sppi in (("full", None), ("primary", 0)):
        scene = pbr.load_dict(glossy_reflection(res, sppi))
        p = pbr.traverse(scene)
        turner = _Turner(p, "box.vertex_positions")

        def render(spp, seed):
            return pbr.render(scene, p, spp=spp, seed=seed)

        if name == "full":
            out["fd"] = fd_batches(render, turner, res, 4, 2048)
        out[name] = ad_batches(render, turner, res, 4, 256)
    print(f"glossy reflection: {out}")
    assert _z(out["full"], out["fd"]) < Z_MAX, out
    assert _z(out["primary"], out["fd"]) > Z_MAX, out


def lit_ball(obj, res=24):
    """The issue's held-out kind of check: a grey diffuse icosphere (interpolated
    normals) under a constant environment, translated; prb_projective."""
    return {"type": "scene", "integrator": {"type": "prb_projective", "max_depth": 4},
            "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": res, "height": res}},
            "ball": {"type": "obj", "filename": obj,
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}


@pytest.mark.slow
def test_lit_mesh_under_an_environment_within_5_percent(ball_obj):
    """Measured (24x24): FD -28.68 +- 0.21; pbr -28.13 +- 1.20 (6x128 spp), Mitsuba 3.9
    prb_projective llvm_ad_rgb -28.78 +- 1.07 and llvm_ad_spectral -58.89 +- 0.70. Must
    fail: before the shading normal of silhouette faces was turned toward the viewer for
    the radiance beside the silhouette (face_the_ray), pbr gave -48.1 +- 1.3: interpolated
    normals facing away left a dark rim whose inner boundary was not counted."""
    res = 24
    scene = pbr.load_dict(lit_ball(ball_obj, res))
    p = pbr.traverse(scene)
    mover = _Mover(p, "ball.vertex_positions")

    def render(spp, seed):
        return pbr.render(scene, p, spp=spp, seed=seed)

    fd = fd_batches(render, mover, res, 6, 4096)
    ad = ad_batches(render, mover, res, 8, 256)
    print(f"lit ball under a sky: pbr {ad}, FD {fd}")
    assert _z(ad, fd) < Z_MAX and abs(ad[0] - fd[0]) < 0.05 * abs(fd[0]), (ad, fd)


@pytest.mark.parametrize("integrator", ["prb", pytest.param("direct_projective", marks=pytest.mark.slow)])
def test_receiver_moving_under_an_area_light(plane_obj, integrator):
    """A mesh plane moving toward a small tilted area light. prb keeps a light sample on
    the light (area measure: no boundary); the projective integrators keep its direction
    (solid angle), and the light's own edges are then a boundary whose term they add.
    Measured (16x16): FD 63.39 +- 0.03; prb 63.19 +- 0.06; direct_projective 63.45 +- 0.52,
    all of it from the light's edges (its interior part is 0 here; with the emitter left
    out of the edge set it gives 0: must-fail checked)."""
    d = lit_plane(plane_obj, integrator)
    del d["light"]
    d["integrator"]["max_depth"] = 2
    d["lamp"] = {"type": "rectangle", "to_world": T().translate([0.8, 0.5, 1.5]).rotate([0, 1, 0], 200).scale(0.3),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [20.0, 20.0, 20.0]}}}
    scene = pbr.load_dict(d)
    p = pbr.traverse(scene)
    mover = _Mover(p, "plane.vertex_positions")
    mover.set = lambda t, m=mover: _shift_z(m, t)

    def render(spp, seed):
        return pbr.render(scene, p, spp=spp, seed=seed)

    fd = fd_batches(render, mover, RES, 4, 1024)
    ad = ad_batches(render, mover, RES, 4, 128)
    assert _z(ad, fd) < Z_MAX and abs(ad[0] - fd[0]) < 0.05 * abs(fd[0]), (ad, fd)


def _shift_z(mover, t):
    pos = dr.unravel(mi.Point3f, mi.Float(mover.v0))
    pos.z += t
    mover.p[mover.key] = dr.ravel(pos)
    mover.p.update()


@pytest.mark.slow
def test_glossy_first_hit_jump_is_aimed_from_the_spawned_origin():
    """The first-hit term's two rays beside an edge start at the spawned origin, which
    lies off the hit point along the normal by about as much as the offset beside the
    edge: aimed from the hit point, both rays fell on one side of edges seen at a low
    angle (a glossy floor's reflection directions) and the jump was lost. Measured: the
    black cube on the rough metal floor translated along x (16x16): FD -32.70 +- 0.11
    (8x8192, step 0.04); pbr -33.08 +- 0.16 (8x1024); before the fix -29.77 +- 0.24 (9%
    low: must-fail)."""
    res = RES
    scene = pbr.load_dict(glossy_reflection(res))
    p = pbr.traverse(scene)
    mover = _Mover(p, "box.vertex_positions")

    def render(spp, seed):
        return pbr.render(scene, p, spp=spp, seed=seed)

    fd = fd_batches(render, mover, res, 8, 8192, h=0.04, seed0=4000)
    ad = ad_batches(render, mover, res, 8, 1024, seed0=8000)
    print(f"glossy cube translated: pbr {ad}, FD {fd}")
    assert _z(ad, fd) < Z_MAX and abs(ad[0] - fd[0]) < 0.03 * abs(fd[0]), (ad, fd)
