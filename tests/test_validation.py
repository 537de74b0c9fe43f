"""One check for every parameter value, however it is given (issue 18): a dict, an XML
file, or ``pbr.traverse`` + ``params.update()``. Values must be finite (in float32) and
in the parameter's range; the error names the key path (and, for XML, file:line). And
samples that still come out NaN or infinite while rendering are counted and reported
(``on_nonfinite``), not silently zeroed.

Must-fail checks, done once by hand: with ``load_spectrum``'s check of plain floats
removed, the plain-float cases load (no error); with ``check_params`` out of
``params.update()``, every update case passes; with ``NonFinite.replace`` not counting,
the count tests fail (0 samples reported)."""

import os
import re
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr

NAN, INF = float("nan"), float("inf")


def _box(**changes):
    d = pbr.cornell_box(8, 4)
    for key, value in changes.items():
        d[key] = value
    return d


def _fog(interior):
    d = _box()
    d["fog"] = {"type": "sphere", "radius": 0.3, "bsdf": {"type": "null"}, "interior": interior}
    return d


def _set(d, path, value):
    *head, last = path.split(".")
    for k in head:
        d = d[k]
    d[last] = value


# (scene dict, key path in the message, value in the message)
BAD = {
    "reflectance nan": (lambda: _box(red={"type": "diffuse", "reflectance": NAN}), "scene.red.reflectance", "nan"),
    "reflectance inf": (lambda: _box(red={"type": "diffuse", "reflectance": INF}), "scene.red.reflectance", "inf"),
    "reflectance 5": (lambda: _box(red={"type": "diffuse", "reflectance": 5.0}), "scene.red.reflectance", "5"),
    "reflectance -1": (lambda: _box(red={"type": "diffuse", "reflectance": -1.0}), "scene.red.reflectance", "-1"),
    "reflectance 1e39 (float32 inf)": (lambda: _box(red={"type": "diffuse", "reflectance": 1e39}),
                                       "scene.red.reflectance", "1e+39"),
    "rgb reflectance 2": (lambda: _box(red={"type": "diffuse", "reflectance": {"type": "rgb", "value": [2, 0, 0]}}),
                          "scene.red.reflectance.value", "2"),
    "spectrum reflectance 3": (lambda: _box(red={"type": "diffuse", "reflectance": {"type": "spectrum", "value": 3}}),
                               "scene.red.reflectance.value", "3"),
    "spectrum pairs nan": (lambda: _box(red={"type": "diffuse", "reflectance": {
        "type": "spectrum", "value": [(400, 0.5), (500, NAN)]}}), "scene.red.reflectance.value", "nan at 500 nm"),
    "checkerboard colour": (lambda: _box(red={"type": "diffuse", "reflectance": {
        "type": "checkerboard", "color1": 1.5}}), "scene.red.reflectance.color1", "1.5"),
    "mix amount": (lambda: _box(red={"type": "diffuse", "reflectance": {
        "type": "mix", "tex1": 0.1, "tex2": 0.2, "amount": -0.5}}), "scene.red.reflectance.amount", "-0.5"),
    "bitmap nan": (lambda: _box(red={"type": "diffuse", "reflectance": {
        "type": "bitmap", "data": np.full((2, 2, 3), np.nan, np.float32)}}), "scene.red.reflectance.data", "nan"),
    "principled roughness 1e30": (lambda: _box(red={"type": "principled", "roughness": 1e30}),
                                  "scene.red.roughness", "1e+30"),
    "principled metallic nan": (lambda: _box(red={"type": "principled", "metallic": NAN}), "scene.red.metallic", "nan"),
    "principled metallic inf": (lambda: _box(red={"type": "principled", "metallic": INF}), "scene.red.metallic", "inf"),
    "alpha nan": (lambda: _box(red={"type": "roughconductor", "alpha": NAN}), "scene.red.alpha", "nan"),
    "alpha_v nan": (lambda: _box(red={"type": "roughconductor", "alpha_u": 0.1, "alpha_v": NAN}),
                    "scene.red.alpha_v", "nan"),
    "alpha -0.1": (lambda: _box(red={"type": "roughplastic", "alpha": -0.1}), "scene.red.alpha", "-0.1"),
    "ior 0": (lambda: _box(red={"type": "dielectric", "int_ior": 0.0}), "scene.red.int_ior", "0"),
    "ior nan": (lambda: _box(red={"type": "roughdielectric", "int_ior": NAN}), "scene.red.int_ior", "nan"),
    "conductor k -1": (lambda: _box(red={"type": "conductor", "eta": 0.2, "k": -1.0}), "scene.red.k", "-1"),
    "radiance -3": (lambda: _box(light={**_box()["light"], "emitter": {"type": "area", "radiance": -3.0}}),
                    "scene.light.emitter.radiance", "-3"),
    "rgb radiance": (lambda: _box(light={**_box()["light"], "emitter": {
        "type": "area", "radiance": {"type": "rgb", "value": [1, -2, 1]}}}), "scene.light.emitter.radiance.value", "-2"),
    "radiance nan": (lambda: _box(light={**_box()["light"], "emitter": {"type": "area", "radiance": NAN}}),
                     "scene.light.emitter.radiance", "nan"),
    "sigma_t nan": (lambda: _fog({"type": "homogeneous", "sigma_t": NAN}), "scene.fog.interior.sigma_t", "nan"),
    "sigma_t inf": (lambda: _fog({"type": "homogeneous", "sigma_t": INF}), "scene.fog.interior.sigma_t", "inf"),
    "sigma_t rgb -1": (lambda: _fog({"type": "homogeneous", "sigma_t": {"type": "rgb", "value": [1, -1, 1]}}),
                       "scene.fog.interior.sigma_t.value", "-1"),
    "medium albedo 2": (lambda: _fog({"type": "homogeneous", "albedo": 2.0}), "scene.fog.interior.albedo", "2"),
    "phase g": (lambda: _fog({"type": "homogeneous", "phase": {"type": "hg", "g": 1.5}}),
                "scene.fog.interior.phase.g", "1.5"),
    "blend weight": (lambda: _box(red={"type": "blendbsdf", "weight": 2.0, "a": {"type": "diffuse"},
                                       "b": {"type": "diffuse"}}), "scene.red.weight", "2"),
}


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_dict_values_are_checked(case):
    make, key, value = BAD[case]
    with pytest.raises(pbr.SceneError) as info:
        pbr.load_dict(make())
    msg = str(info.value)
    assert msg.startswith(f"{key}: must be"), msg
    assert f"got {value}" in msg, msg


# ------------------------------------------------------------------------------ XML

XML_BAD = [
    # (elements of a shape's bsdf, key path, value)
    ('<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/>\n'
     '<float name="alpha_v" value="nan"/></bsdf>', "scene.ball.bsdf.alpha_v", "nan"),
    ('<bsdf type="diffuse">\n<float name="reflectance" value="inf"/></bsdf>', "scene.ball.bsdf.reflectance", "inf"),
    ('<bsdf type="diffuse">\n<rgb name="reflectance" value="0.5, 5.0, 0.5"/></bsdf>',
     "scene.ball.bsdf.reflectance.value", "5"),
    ('<bsdf type="principled">\n<float name="roughness" value="1e30"/></bsdf>', "scene.ball.bsdf.roughness", "1e+30"),
    ('<bsdf type="dielectric">\n<float name="int_ior" value="-1.5"/></bsdf>', "scene.ball.bsdf.int_ior", "-1.5"),
    ('<emitter type="area">\n<rgb name="radiance" value="-1"/></emitter>', "scene.ball.emitter.radiance.value", "-1"),
    ('<bsdf type="null"/><medium type="homogeneous" name="interior">\n<float name="sigma_t" value="nan"/></medium>',
     "scene.ball.interior.sigma_t", "nan"),
]


@pytest.mark.parametrize("body, key, value", XML_BAD, ids=[k for _, k, _ in XML_BAD])
def test_xml_values_are_checked_with_file_and_line(tmp_path, body, key, value):
    text = ('<scene version="3.0.0">\n<sensor type="perspective"><float name="fov" value="40"/></sensor>\n'
            f'<shape type="sphere" id="ball">\n{body}\n</shape>\n</scene>\n')
    path = os.path.join(tmp_path, "bad.xml")
    with open(path, "w") as f:
        f.write(text)
    # The line of the offending element: the last line of the body that names the parameter.
    name = key.split(".")[3]
    line = 1 + max(i for i, ln in enumerate(text.splitlines()) if f'name="{name}"' in ln)
    with pytest.raises(pbr.SceneError) as info:
        pbr.load_file(path)
    msg = str(info.value)
    # (anonymous nested objects are keyed '<tag>_<n>' by the XML reader)
    root, shape, obj, *rest = key.split(".")
    pattern = (re.escape(f"{path}:{line}: {root}.{shape}.{obj}") + r"(_0)?"
               + re.escape("." + ".".join(rest) + ": must be"))
    assert re.match(pattern, msg), msg
    assert f"got {value}" in msg, msg


# --------------------------------------------------------------------- params.update

@pytest.fixture(scope="module")
def updatable():
    """A scene with a parameter of each kind of owner: constant textures (albedo, radiance,
    roughness), a bitmap, a dielectric's IOR, an environment map, a medium."""
    T = mi.ScalarTransform4f
    d = _box()
    d["red"] = {"type": "diffuse", "reflectance": {"type": "bitmap", "data": np.full((2, 2, 3), 0.5, np.float32)}}
    d["glass"] = {"type": "sphere", "radius": 0.2, "to_world": T().translate([0.5, 0.5, 0]),
                  "bsdf": {"type": "roughdielectric", "int_ior": 1.5, "alpha": 0.2}}
    d["sky"] = {"type": "envmap", "data": np.full((4, 8, 3), 0.1, np.float32)}
    d["fog"] = {"type": "sphere", "radius": 0.2, "to_world": T().translate([-0.5, 0.5, 0]), "bsdf": {"type": "null"},
                "interior": {"type": "homogeneous", "sigma_t": 1.0, "albedo": 0.5}}
    d["integrator"] = {"type": "volpath", "max_depth": 3}
    scene = pbr.load_dict(d)
    return scene, pbr.traverse(scene)


UPDATES = [
    ("white.reflectance.value", lambda v: mi.Color3f(0.5, NAN, 0.5), "nan"),
    ("white.reflectance.value", lambda v: mi.Color3f(0.5, 1.5, 0.5), "1.5"),
    ("light.emitter.radiance.value", lambda v: mi.Color3f(1, 1, -1), "-1"),
    ("red.reflectance.data", lambda v: mi.TensorXf(np.full((2, 2, 3), INF, np.float32)), "inf"),
    ("glass.bsdf.alpha.value", lambda v: mi.Float(-0.01), "-0.01"),
    ("glass.bsdf.eta", lambda v: mi.Float(0.0), "0"),
    ("sky.data", lambda v: mi.TensorXf(-np.ones((4, 8, 3), np.float32)), "-1"),
    ("sky.scale", lambda v: mi.Float(NAN), "nan"),
    ("fog.interior_medium.sigma_t.value.value", lambda v: mi.Float(NAN), "nan"),
    ("fog.interior_medium.albedo.value.value", lambda v: mi.Float(1.5), "1.5"),
]


@pytest.mark.parametrize("key, bad, value", UPDATES, ids=[f"{k}={v}" for k, _, v in UPDATES])
def test_updates_are_checked(updatable, key, bad, value):
    scene, params = updatable
    assert key in params, sorted(params.keys())
    old = type(params[key])(params[key])
    params[key] = bad(old)
    try:
        with pytest.raises(pbr.SceneError, match=r"^" + re.escape(key) + r": must be .*got " + re.escape(value)):
            params.update()
    finally:
        params[key] = old
        params.update()


def test_valid_values_still_load_and_update(updatable):
    """Values at the edges of their ranges, and ones Mitsuba scenes use beyond [0, 1]."""
    for d in (_box(red={"type": "roughconductor", "alpha": 2.0}),
              _box(red={"type": "conductor", "eta": {"type": "rgb", "value": [0.2, 0.9, 1.1]},
                        "k": {"type": "rgb", "value": [3.9, 2.4, 2.2]}}),
              _box(red={"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": 0.0, "color1": 1.0}}),
              _box(red={"type": "principled", "roughness": 0.0, "metallic": 1.0}),
              # a top-level texture (any finite values) referenced by an emitter
              _box(hot={"type": "spectrum", "value": 7.0},
                   light={**_box()["light"], "emitter": {"type": "area", "radiance": {"type": "ref", "id": "hot"}}})):
        pbr.load_dict(d)
    scene, params = updatable
    params["white.reflectance.value"] = mi.Color3f(0.0, 1.0, 0.25)
    params.update()
    params["white.reflectance.value"] = mi.Color3f(0.885809, 0.698859, 0.666422)
    params.update()


def test_albedo_bitmap_outside_unit_range_warns():
    """An albedo bitmap's texels are clipped to [0, 1] (as Mitsuba's upsampling): that is
    said, not silent (a reflectance image of 5 rendered as 1 without a word)."""
    d = _box()
    d["white"] = {"type": "diffuse", "reflectance": {"type": "bitmap", "data": np.full((2, 2, 3), 5.0, np.float32)}}
    with pytest.warns(UserWarning, match=r"scene\.white\.reflectance\.data: 12 of 12 texel values are outside "
                                         r"\[0, 1\] and are clipped"):
        pbr.load_dict(d)
    d["white"]["reflectance"]["data"] = np.full((2, 2, 3), 0.5, np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        pbr.load_dict(d)


# ------------------------------------------------------------- non-finite samples

def _overflowing_light(integrator):
    """A rectangle light filling the view whose radiance, finite in float32, overflows
    when it is upsampled (2 max(rgb) > 3.4e38): every camera sample sees inf."""
    return pbr.load_dict(_overflowing_light_dict(integrator))


def _overflowing_light_dict(integrator):
    T = mi.ScalarTransform4f
    return {
        "type": "scene", "integrator": integrator,
        "sensor": {"type": "perspective", "fov": 30.0,
                   "to_world": T().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 6, "height": 5, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 3}},
        "wall": {"type": "rectangle", "to_world": T().scale(10.0), "bsdf": {"type": "diffuse"},
                 "emitter": {"type": "area", "radiance": 3e38}}}


def test_nonfinite_samples_are_counted_and_reported():
    scene = _overflowing_light({"type": "path", "max_depth": 1})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        img = pbr.render(scene)
    msgs = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert len(msgs) == 1 and msgs[0].startswith(f"pbr.render: {6 * 5 * 3} samples were NaN or infinite"), msgs
    assert np.all(np.isfinite(np.asarray(img)))            # the image stays finite (the samples count as 0)
    with pytest.raises(FloatingPointError, match=r"^pbr.render: 90 samples"):
        pbr.render(scene, on_nonfinite="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pbr.render(scene, on_nonfinite="ignore")
        pbr.render(pbr.load_dict(_box()), on_nonfinite="raise")     # a clean scene: silent
    with pytest.raises(ValueError, match="on_nonfinite must be one of"):
        pbr.render(scene, on_nonfinite="stop")


@pytest.mark.parametrize("integrator", ["path", "prb", "volpath", "prbvolpath", "bdpt", "ptracer", "sppm",
                                        "simplepath"])
def test_a_nan_throughput_reaches_the_count(monkeypatch, integrator):
    """A BSDF whose sampled weight is NaN (here a conductor's Fresnel term made NaN, as
    eta = k = 0 once made it): the path goes on and its NaN estimate is counted. The
    integrators ended such a path where max(beta) > 0 is false, as it is for NaN, so
    the image lost its light without a warning. (Not randomwalk: it evaluates BSDFs
    toward uniformly sampled directions, and a mirror's value there is 0.)"""
    import pbr.bsdfs.conductor as conductor
    monkeypatch.setattr(conductor, "fresnel_conductor", lambda cos_i, eta, k: eta * k * float("nan"))
    d = _box(white={"type": "conductor", "id": "white", "material": "none"})
    d["light"]["bsdf"] = {"type": "diffuse"}
    d["integrator"] = {"type": integrator, "max_depth": 4} if integrator not in ("sppm", "bdpt") else \
        {"type": integrator, "maxdepth": 3}
    if integrator == "sppm":
        d["integrator"].update(photonsperiteration=2000, iterations=2)
    with pytest.raises(FloatingPointError, match=r"^pbr.render: \d+ samples? w"):
        pbr.render(pbr.load_dict(d), on_nonfinite="raise")


def test_nonfinite_samples_of_a_differentiable_render_are_reported_after_backward():
    """With gradients the count is read after the derivative pass (the render does not
    wait for its image): the primal samples' count, then the adjoint pass's."""
    scene = _overflowing_light({"type": "prb", "max_depth": 2})
    params = pbr.traverse(scene)
    key = "wall.bsdf.reflectance.value"
    dr.enable_grad(params[key])
    params.update()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        img = pbr.render(scene, params)
        assert not caught
        dr.backward(dr.sum(img, axis=None))
    assert [str(w.message)[:25] for w in caught] == ["pbr.render: 90 samples we"]
    img = pbr.render(scene, params, on_nonfinite="raise")
    with pytest.raises(FloatingPointError, match=r"^pbr.render: 90 samples"):
        dr.backward(dr.sum(img, axis=None))


def test_splatted_nonfinite_contributions_are_counted():
    """The light tracer splats its contributions: those are counted too."""
    scene = _overflowing_light({"type": "ptracer", "max_depth": 2})
    with pytest.raises(FloatingPointError, match=r"^pbr.render: \d+ samples? w"):
        pbr.render(scene, on_nonfinite="raise")


def test_mlt_nonfinite_path_contributions_are_counted():
    """mlt evaluates its paths itself (bootstrap and proposals): a non-finite estimate is
    counted, not zeroed silently; here every path overflows, and the black image comes
    with the count instead of the 'no bootstrap path carries light' advice (before: that
    advice alone, and on_nonfinite='raise' rendered)."""
    scene = _overflowing_light({"type": "mlt", "max_depth": 2, "bootstrapsamples": 64, "chains": 16,
                                "mutationsperpixel": 2})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        img = pbr.render(scene)
    msgs = [str(w.message) for w in caught if not issubclass(w.category, ResourceWarning)]
    assert len(msgs) == 1 and re.match(r"pbr.render: \d+ samples were NaN or infinite", msgs[0]), msgs
    assert np.all(np.isfinite(np.asarray(img)))
    with pytest.raises(FloatingPointError, match=r"^pbr.render: \d+ samples"):
        pbr.render(scene, on_nonfinite="raise")


def test_projective_boundary_nonfinite_estimates_are_counted():
    """prb_projective's primary-visibility boundary term evaluates its own edge samples:
    a non-finite one is counted in the derivative pass's report (it was zeroed silently).
    Only that term runs (sppc = sppi = 0): a blocker moved in front of the overflowing
    light."""
    T = mi.ScalarTransform4f
    d = _overflowing_light_dict({"type": "prb_projective", "max_depth": 2, "sppc": 0, "sppi": 0, "sppp": 4})
    d["wall"]["to_world"] = T().translate([0, 0, -1]).scale(10.0)
    d["blocker"] = {"type": "rectangle", "to_world": T().scale(0.3), "bsdf": {"type": "diffuse"}}
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    t = mi.Float(0.0)
    dr.enable_grad(t)
    params["blocker.to_world"] = mi.Transform4f().translate(mi.Vector3f(t, 0, 0)) @ mi.Transform4f(params["blocker.to_world"])
    params.update()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        img = pbr.render(scene, params)
        dr.forward(t)
        dr.eval(dr.grad(img))
    msgs = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert any(re.match(r"pbr.render \(forward derivative\): \d+ samples? w", m) for m in msgs), msgs


def test_radiosity_stops_at_a_non_finite_residual():
    """An overflowing emitter makes the radiosities NaN: the solver stops at once (it ran
    all 10000 iterations, 40 s, with residual nan) and the render reports the samples."""
    scene = _overflowing_light({"type": "radiosity"})
    with pytest.raises(FloatingPointError, match=r"^pbr.render: 90 samples"):
        pbr.render(scene, on_nonfinite="raise", progress=False)
    stats = scene.integrator.solution.stats
    assert stats.iterations == 1 and not stats.converged, stats


def test_cli_on_nonfinite(tmp_path, monkeypatch, capsys):
    from pbr import cli

    def fail(*args, on_nonfinite="warn", **kw):
        assert on_nonfinite == "raise"
        raise FloatingPointError("pbr.render: 3 samples were NaN or infinite")
    monkeypatch.setattr(pbr, "render", fail)
    out = os.path.join(tmp_path, "x.exr")
    assert cli.main(["render", "-o", out, "--backend", pbr.get_backend(), "--on-nonfinite", "raise"]) == 2
    assert "pbr: error: pbr.render: 3 samples were NaN or infinite" in capsys.readouterr().err
