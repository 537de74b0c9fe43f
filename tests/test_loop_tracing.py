"""The path tracers' symbolic loops (path, volpath, simplevolpath, simplepath, randomwalk,
ptracer, direct, whitted, prbvolpath, bdpt) are traced once per render.

Dr.Jit traces a loop body a second time when the loop state holds variables the body
leaves unchanged (to drop them), which doubled the Python tracing of every render, its
largest fixed cost (docs/performance.md, "Per-render fixed cost"). ``path`` and
``volpath`` keep such variables out of their loop state: the wavelengths, the ray's time
and wavelengths, the sample stream's constants (``SampleStream.varying``), and the
relative IOR, dispersion flag and forward derivative where they cannot change. These
tests count the traces of the loop bodies; a state variable that comes back unchanged
makes them fail."""

import drjit as dr
import numpy as np
import pytest

import pbr
from pbr.samplers import SAMPLERS


def _body_traces(monkeypatch, label, fn):
    """Run ``fn()`` and return, per ``dr.while_loop`` call labelled ``label``, how many
    times its body was traced."""
    traces = []
    orig = dr.while_loop

    def counting(state, cond, body, *args, **kw):
        name = kw.get("label", args[1] if len(args) > 1 else None)
        if name != label:
            return orig(state, cond, body, *args, **kw)
        traces.append(0)
        k = len(traces) - 1

        def traced(*a):
            traces[k] += 1
            return body(*a)
        return orig(state, cond, traced, *args, **kw)

    monkeypatch.setattr(dr, "while_loop", counting)
    fn()
    return traces


def _fog() -> dict:
    """A fog sphere (a scene with a medium), a fresh dict each time."""
    return {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.3, "bsdf": {"type": "null"},
            "interior": {"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.8}}


def _derivative_traces(monkeypatch, scene, label):
    """Assert that loop ``label`` is traced once per loop in forward mode (a primal and a
    forward replay) and in reverse mode (a primal and a backward replay), differentiating
    the red wall's reflectance."""
    for mode in ("forward", "backward"):
        params = pbr.traverse(scene)
        key = "red.reflectance.value"
        dr.enable_grad(params[key])
        params.update()

        def run():
            img = pbr.render(scene, params, seed=1)
            if mode == "forward":
                dr.forward(params[key])
                np.asarray(dr.grad(img))
            else:
                dr.backward(dr.mean(img, axis=None))
                np.asarray(dr.grad(params[key]))
        traces = _body_traces(monkeypatch, label, run)
        assert len(traces) >= 2 and set(traces) == {1}, (mode, traces)
        monkeypatch.undo()


def _cornell(**changes):
    d = pbr.cornell_box(8, 1)
    d.update(changes)
    return d


@pytest.mark.parametrize("sampler", sorted(SAMPLERS))
def test_path_loop_traced_once_with_every_sampler(monkeypatch, sampler):
    d = _cornell()
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": 4}
    scene = pbr.load_dict(d)
    traces = _body_traces(monkeypatch, "path", lambda: np.asarray(pbr.render(scene, seed=1)))
    assert traces == [1]


def test_path_loop_traced_once_with_unjittered_strata(monkeypatch):
    d = _cornell()
    d["sensor"]["sampler"] = {"type": "stratified", "sample_count": 4, "jitter": False}
    scene = pbr.load_dict(d)
    assert _body_traces(monkeypatch, "path", lambda: np.asarray(pbr.render(scene, seed=1))) == [1]


def test_path_loop_traced_once_with_refraction_and_dispersion(monkeypatch):
    for ior in (1.5, "glass-BK7"):
        d = pbr.scenes.glass_caustic(8, 1)
        d["glass"]["bsdf"] = {"type": "dielectric", "int_ior": ior}
        d["integrator"] = {"type": "path", "max_depth": 6}
        scene = pbr.load_dict(d)
        assert scene.bsdfs.refracts and scene.bsdfs.dispersive == (ior != 1.5)
        assert _body_traces(monkeypatch, "path", lambda: np.asarray(pbr.render(scene, seed=1))) == [1]


def test_path_loops_of_derivatives_traced_once(monkeypatch):
    """Forward mode: a primal and a forward replay; reverse mode: a primal and a
    backward replay per render_backward (and the primal image): each loop traced once."""
    _derivative_traces(monkeypatch, pbr.load_dict(_cornell(integrator={"type": "prb", "max_depth": 4})), "path")


@pytest.mark.parametrize("integrator", ["volpath", "simplevolpath"])
def test_volpath_loops_traced_once(monkeypatch, integrator):
    """On a scene with a medium (without media, the medium index, and volpath's spectral
    MIS ratio r_u, stay constant, and the loop is still traced twice)."""
    d = _cornell(integrator={"type": integrator, "max_depth": 5})
    d["fog"] = _fog()
    scene = pbr.load_dict(d)
    assert _body_traces(monkeypatch, integrator, lambda: np.asarray(pbr.render(scene, seed=1))) == [1]


def test_simplevolpath_without_media_traced_once(monkeypatch):
    """Without media the medium index is a constant, not loop state."""
    scene = pbr.load_dict(_cornell(integrator={"type": "simplevolpath", "max_depth": 5}))
    assert _body_traces(monkeypatch, "simplevolpath", lambda: np.asarray(pbr.render(scene, seed=1))) == [1]


def test_volpath_without_media_traced_once(monkeypatch):
    """Without media volpath's spectral MIS ratio, null-collision count and medium index
    are constants, not loop state; its shadow rays, with nothing to cross, are one
    occlusion test instead of a loop over surfaces (pbrt-v4 scenes use volpath by
    default, mostly without media)."""
    scene = pbr.load_dict(_cornell(integrator={"type": "volpath", "max_depth": 5}))
    assert _body_traces(monkeypatch, "volpath", lambda: np.asarray(pbr.render(scene, seed=1))) == [1]
    monkeypatch.undo()
    assert _body_traces(monkeypatch, "shadow_ray", lambda: np.asarray(pbr.render(scene, seed=1))) == []
    monkeypatch.undo()
    # A null surface is crossed by the shadow ray's loop, traced once per vertex call.
    d = _cornell(integrator={"type": "volpath", "max_depth": 5})
    d["pane"] = {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.3, "bsdf": {"type": "null"}}
    scene = pbr.load_dict(d)
    assert _body_traces(monkeypatch, "volpath", lambda: np.asarray(pbr.render(scene, seed=1))) == [1]


@pytest.mark.parametrize("integrator", [{"type": "simplepath"}, {"type": "simplepath", "samplelights": False},
                                        {"type": "simplepath", "samplebsdf": False}, {"type": "randomwalk"},
                                        {"type": "ptracer", "max_depth": 6}])
@pytest.mark.parametrize("ior", [1.5, "glass-BK7"])
def test_simplepath_randomwalk_ptracer_loops_traced_once(monkeypatch, integrator, ior):
    d = pbr.scenes.glass_caustic(8, 1)
    d["glass"]["bsdf"] = {"type": "dielectric", "int_ior": ior}
    d["integrator"] = integrator
    scene = pbr.load_dict(d)
    traces = _body_traces(monkeypatch, integrator["type"], lambda: np.asarray(pbr.render(scene, seed=1)))
    assert traces == [1]


@pytest.mark.parametrize("integrator, labels", [
    ({"type": "direct", "emitter_samples": 2, "bsdf_samples": 2}, ("direct_emitter", "direct_bsdf")),
    ({"type": "whitted", "max_depth": 3}, ("whitted_lights",))])
@pytest.mark.parametrize("sampler", ["independent", "sobol"])
def test_direct_and_whitted_light_loops_traced_once(monkeypatch, integrator, labels, sampler):
    """Their per-vertex light/BSDF sample loops keep the hit, its shading context, BSDF
    entry, mask and the sample stream's constants out of the loop state."""
    d = _cornell(integrator=integrator)
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": 4}
    d["glass"] = {"type": "sphere", "center": [0.2, -0.2, 0.1], "radius": 0.25, "bsdf": {"type": "dielectric"}}
    scene = pbr.load_dict(d)
    for label in labels:
        traces = _body_traces(monkeypatch, label, lambda: np.asarray(pbr.render(scene, seed=1)))
        assert traces and set(traces) == {1}, (label, traces)
        monkeypatch.undo()


@pytest.mark.parametrize("fog", [False, True])
def test_prbvolpath_loops_traced_once(monkeypatch, fog):
    """prbvolpath, primal and both derivative modes, with and without a medium: the
    forward derivative, medium index, null-collision count and adjoint radiance are loop
    state only where they change."""
    d = _cornell(integrator={"type": "prbvolpath", "max_depth": 4})
    if fog:
        d["fog"] = _fog()
    scene = pbr.load_dict(d)
    assert _body_traces(monkeypatch, "prbvolpath", lambda: np.asarray(pbr.render(scene, seed=1))) == [1]
    monkeypatch.undo()
    _derivative_traces(monkeypatch, scene, "prbvolpath")


@pytest.mark.parametrize("integrator", ["path", "volpath"])
def test_regularizing_loops_traced_once(monkeypatch, integrator):
    """``regularize`` adds one loop-state mask (a non-specular bounce happened); it
    changes, so the loop is still traced once (with a glass sphere to regularise; volpath
    with a medium, see above)."""
    d = pbr.scenes.glass_caustic(8, 1)
    d["integrator"] = {"type": integrator, "max_depth": 6, "regularize": True}
    if integrator == "volpath":
        d["fog"] = _fog()
    scene = pbr.load_dict(d)
    assert _body_traces(monkeypatch, integrator, lambda: np.asarray(pbr.render(scene, seed=1))) == [1]


BDPT_LOOPS = ("bdpt_light", "bdpt_camera", "bdpt_connect")


def _bdpt_scene(kind: str) -> dict:
    """bdpt on a diffuse Cornell box (its samples' delta flags are literals), with a
    sobol sampler, on a glass sphere (refraction; with dispersion, the subpaths carry
    ``term``), and with a point light and a constant environment (delta and infinite
    lights) instead of the area light."""
    if kind.startswith("caustic"):
        d = pbr.scenes.glass_caustic(8, 1)
        if kind == "caustic-dispersive":
            d["glass"]["bsdf"] = {"type": "dielectric", "int_ior": "glass-BK7"}
        d["integrator"] = {"type": "bdpt", "max_depth": 6}
        return d
    d = _cornell(integrator={"type": "bdpt", "max_depth": 5})
    if kind == "cornell-sobol":
        d["sensor"]["sampler"] = {"type": "sobol", "sample_count": 4}
    if kind == "lights":
        del d["light"], d["back"], d["ceiling"]
        d["pt"] = {"type": "point", "position": [0.3, 0.5, 0.4], "intensity": {"type": "rgb", "value": [2.0, 2.0, 2.0]}}
        d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.5, 0.6, 0.8]}}
    return d


@pytest.mark.parametrize("kind", ["cornell", "cornell-sobol", "caustic", "caustic-dispersive", "lights"])
def test_bdpt_loops_traced_once(monkeypatch, kind):
    """bdpt's light subpath, camera subpath and connection loops: the ray's constant
    parts, the streams' constants, the wavelengths, the vertex store (a scatter target)
    and what the connections read stay out of the loop state; the first vertex's delta
    flag is opaque (Dr.Jit drops a literal the body leaves the same)."""
    scene = pbr.load_dict(_bdpt_scene(kind))
    for label in BDPT_LOOPS:
        traces = _body_traces(monkeypatch, label, lambda: np.asarray(pbr.render(scene, seed=1)))
        assert traces == [1], (label, traces)
        monkeypatch.undo()


def test_mlt_bdpt_loops_traced_once(monkeypatch):
    """mlt runs bdpt's loops on its primary sample streams (one strategy per lane); a
    fresh scene for each loop, as mlt records its kernels for the next render."""
    for label in BDPT_LOOPS:
        scene = pbr.load_dict(_cornell(integrator={"type": "mlt", "maxdepth": 3, "mutationsperpixel": 4,
                                                   "bootstrapsamples": 256, "chains": 16}))
        traces = _body_traces(monkeypatch, label, lambda: np.asarray(pbr.render(scene, seed=1)))
        assert traces and set(traces) == {1}, (label, traces)
        monkeypatch.undo()
