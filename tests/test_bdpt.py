"""``bdpt`` (pbrt-v4's bidirectional path tracer; Mitsuba has none): checked against pbr's
``path``, an independent estimator, with the statistical image test (pbr.validate).

* The MIS sums kept along the subpaths equal pbrt-v4's ``MISWeight`` loop (a direct
  transcription, on random densities and delta flags).
* Diffuse Cornell box at max_depth 2, 3, 5 and a caustic scene (a glass sphere on a
  diffuse floor under a small light, which path tracing reaches only by BSDF sampling
  the light through the glass) at max_depth 4, 6: bdpt matches ``path``.
* Strategy images (pbrt-v4's visualizeweights) sum to the image.
* Must fail: MIS weights that forget the light subpath's strategies (every strategy
  then counts light that others also count) are detected by the same test.
"""

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import validate
from pbr.integrators import bdpt as bdpt_mod
from pbr.plugins.props import SceneError

RES, SPP, BATCHES = 24, 1024, 16


def cornell(integrator, max_depth, scale=1, res=RES):
    """The Cornell box (emitter visible: Mitsuba's hide_emitters has no bdpt equivalent),
    box filter (see tests/mitsuba_scenes.material_box)."""
    d = pbr.cornell_box(res * scale, 16)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = {"type": integrator, "max_depth": max_depth}
    return d


def caustic(integrator, max_depth, scale=1):
    """pbr.scenes.glass_caustic: the caustic under the sphere needs max_depth >= 4."""
    d = pbr.scenes.glass_caustic(16 * scale)
    d["integrator"] = {"type": integrator, "max_depth": max_depth}
    return d


def render_fn(d):
    scene = pbr.load_dict(d)
    return lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp, progress=False))


def check(make, max_depth, scale, expect_pass=True, spp=SPP):
    res = validate.compare_renders(render_fn(make("bdpt", max_depth, scale)), render_fn(make("path", max_depth, scale)),
                                   spp=spp * scale, batches=BATCHES, seed_a=31, seed_b=32)
    print(res.summary())
    assert bool(res.passed) == expect_pass, res.summary()
    return res


# ------------------------------------------------------------------- MIS bookkeeping

def pbrt_mis_weight(cam_fwd, cam_rev, cam_delta, light_fwd, light_rev, light_delta, delta_light, s, t):
    """pbrt-v4's ``MISWeight`` (src/pbrt/cpu/integrators.cpp) for one path, with the
    strategy's overrides already applied to the arrays."""
    if s + t == 2:
        return 1.0

    def remap0(f):
        return f if f != 0 else 1.0
    total, ri = 0.0, 1.0
    for i in range(t - 1, 0, -1):
        ri *= remap0(cam_rev[i]) / remap0(cam_fwd[i])
        if not cam_delta[i] and not cam_delta[i - 1]:
            total += ri
    ri = 1.0
    for i in range(s - 1, -1, -1):
        ri *= remap0(light_rev[i]) / remap0(light_fwd[i])
        prev_delta = light_delta[i - 1] if i > 0 else delta_light
        if not light_delta[i] and not prev_delta:
            total += ri
    return 1.0 / (1.0 + total)


def test_mis_sums_equal_pbrt_loop():
    rng = np.random.default_rng(5)
    n_paths, n = 300, 6

    def densities():
        x = rng.lognormal(0.0, 1.5, (n_paths, n))
        delta = rng.random((n_paths, n)) < 0.25
        return np.where(delta, 0.0, x), np.where(delta, 0.0, rng.lognormal(0.0, 1.5, (n_paths, n))), delta
    c_fwd, c_rev, c_delta = densities()
    l_fwd, l_rev, l_delta = densities()
    c_delta[:, 0] = l_delta[:, 0] = False          # endpoints are never specular vertices
    delta_light = rng.random(n_paths) < 0.3

    F = lambda a: mi.Float(np.ascontiguousarray(a, dtype=np.float32))   # noqa: E731
    B = lambda a: mi.Bool(np.ascontiguousarray(a))                      # noqa: E731
    # E along each subpath (the camera's E_0 = 0, the light's E_0 = [not a delta light]).
    Ec, El = [mi.Float(0.0)], [mi.Float(np.where(delta_light, 0.0, 1.0).astype(np.float32))]
    for k in range(1, n):
        Ec.append(bdpt_mod.advance_sum(Ec[-1], F(c_rev[:, k - 1]), F(c_fwd[:, k - 1]), B(c_delta[:, k]),
                                       B(c_delta[:, k - 1])))
        El.append(bdpt_mod.advance_sum(El[-1], F(l_rev[:, k - 1]), F(l_fwd[:, k - 1]), B(l_delta[:, k]),
                                       B(l_delta[:, k - 1])))
    checked = 0
    for t in range(1, n + 1):
        for s in range(0, n + 1):
            if s + t <= 2:     # (0, 2) has weight 1; (1, 1) and (0, 1) are no strategies
                continue
            # The connection's new reverse densities of the end vertices and their predecessors.
            new = rng.lognormal(0.0, 1.0, (4, n_paths))
            cr, lr, cd, ld = c_rev.copy(), l_rev.copy(), c_delta.copy(), l_delta.copy()
            if t >= 1:
                cr[:, t - 1], cd[:, t - 1] = new[0], False
            if t >= 2:
                cr[:, t - 2] = new[1]
            if s >= 1:
                lr[:, s - 1], ld[:, s - 1] = new[2], False
            if s >= 2:
                lr[:, s - 2] = new[3]
            ref = [pbrt_mis_weight(c_fwd[i], cr[i], cd[i], l_fwd[i], lr[i], ld[i], delta_light[i], s, t)
                   for i in range(n_paths)]
            sc = sl = mi.Float(0.0)
            if t >= 2:
                sc = bdpt_mod.side_sum(F(new[0]), F(c_fwd[:, t - 1]), F(new[1]), F(c_fwd[:, t - 2]),
                                       B(c_delta[:, t - 2]), Ec[t - 2])
            if s == 1:   # the light vertex alone (as the integrator's next-event estimation)
                sl = bdpt_mod.side_sum(F(new[2]), F(l_fwd[:, 0]), 0.0, 1.0, B(delta_light), 0.0)
            elif s >= 2:
                sl = bdpt_mod.side_sum(F(new[2]), F(l_fwd[:, s - 1]), F(new[3]), F(l_fwd[:, s - 2]),
                                       B(l_delta[:, s - 2]), El[s - 2])
            w = np.array(bdpt_mod.mis_weight(sc, sl), dtype=np.float64)
            np.testing.assert_allclose(w, ref, rtol=2e-4, err_msg=f"strategy s={s}, t={t}")
            checked += 1
    assert checked > 30


# ------------------------------------------------------------------- against path

@pytest.mark.parametrize("max_depth", [2, 3, 5])
def test_cornell_box_matches_path(max_depth, scale):
    check(cornell, max_depth, scale)


@pytest.mark.parametrize("max_depth", [4, 6])
def test_caustic_matches_path(max_depth, scale):
    check(caustic, max_depth, scale)


@pytest.mark.slow
def test_dispersive_caustic_matches_path(scale):
    """BK7 glass (a wavelength-dependent IOR): contributions through it keep one wavelength."""
    def make(integrator, max_depth, scale):
        d = caustic(integrator, max_depth, scale)
        d["glass"]["bsdf"]["int_ior"] = "glass-BK7"
        return d
    check(make, 5, scale, spp=2048)


def test_strategy_images_sum_to_image():
    d = cornell("bdpt", 4)
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 12
    scene = pbr.load_dict(d)
    img = np.asarray(pbr.render(scene, seed=3, spp=8), dtype=np.float64)
    parts = scene.integrator.render_strategies(scene, seed=3, spp=8, weighted=True)
    assert sorted(parts) == sorted((s, t) for dep in range(4) for t in range(1, dep + 3)
                                   for s in [dep + 2 - t] if (s, t) != (1, 1))
    total = sum(np.asarray(v, dtype=np.float64) for v in parts.values())
    np.testing.assert_allclose(total, img, rtol=1e-4, atol=1e-6)
    # Light tracing (t = 1) and next-event estimation (s = 1) both carry direct light.
    assert np.asarray(parts[(2, 1)]).mean() > 0 and np.asarray(parts[(1, 2)]).mean() > 0


def test_dropped_light_strategies_fail(monkeypatch, scale):
    """Sabotage: the MIS weight ignores the light subpath's strategies, so the weights of a
    path no longer sum to 1 (light is counted more than once): too bright."""
    monkeypatch.setattr(bdpt_mod, "mis_weight", lambda sum_camera, sum_light: 1.0 / (1.0 + sum_camera))
    res = check(cornell, 3, scale, expect_pass=False, spp=256)
    assert res.mean_ratio > 1.0


# ------------------------------------------------------------------- parameters

def test_depth_parameters():
    def make(**kw):
        d = pbr.cornell_box(8, 4)
        d["integrator"] = {"type": "bdpt", **kw}
        return pbr.load_dict(d).integrator
    assert (make().maxdepth, make().max_depth) == (5, 6)          # pbrt-v4's default
    assert make(maxdepth=2).max_depth == 3                         # Mitsuba = pbrt + 1
    assert make(max_depth=4).maxdepth == 3
    assert np.asarray(pbr.render(pbr.load_dict({**pbr.cornell_box(8, 4),
                                                "integrator": {"type": "bdpt", "max_depth": 0}}))).max() == 0
    for kw, key in ((dict(max_depth=-1), "max_depth"), (dict(maxdepth=2, max_depth=3), "max_depth"),
                    (dict(regularize=True), "regularize"), (dict(maxdepth=-2), "maxdepth"),
                    (dict(max_dept=3), "max_dept")):
        with pytest.raises(SceneError, match=rf"scene\.integrator\.{key}"):
            make(**kw)


def test_unsupported_scenes_are_rejected():
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": "bdpt"}
    d["portal"] = {"type": "portalenvmap", "bitmap": np.ones((4, 8, 3), np.float32),
                   "portal": [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]]}
    with pytest.raises(SceneError, match=r"scene\.portal: .*bdpt"):
        pbr.load_dict(d)
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": "bdpt"}
    d["fog"] = {"type": "homogeneous", "sigma_t": 1.0, "id": "fog"}
    d["large-box"]["interior"] = {"type": "ref", "id": "fog"}
    with pytest.raises(SceneError, match="media"):
        pbr.load_dict(d)


LIGHTS = {
    "point": {"pt": {"type": "point", "position": [0.3, 0.5, 0.4],
                     "intensity": {"type": "rgb", "value": [2.0, 2.0, 2.0]}}},
    "constant": {"sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.5, 0.6, 0.8]}}},
}


@pytest.mark.parametrize("light", sorted(LIGHTS))
def test_point_and_infinite_lights_match_path(light, scale):
    """A point light (a delta in position: no camera path reaches it) and a constant
    environment (an infinite light, seen through the box's open front and back)."""
    def make(integrator, max_depth, scale):
        d = cornell(integrator, max_depth, scale, res=16)
        del d["light"]
        if light == "constant":
            del d["back"], d["ceiling"]
        d.update(LIGHTS[light])
        return d
    check(make, 3, scale, spp=512)
