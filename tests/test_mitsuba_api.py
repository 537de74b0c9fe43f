"""Mitsuba scripts port by changing the import: ``pbr.traverse`` has ``mi.traverse``'s
keys (a superset, less documented exceptions), updates of geometry and sensor keys change
the image as Mitsuba's do, ``SceneParameters``, ``Scene``, ``render`` and ``load_dict``
answer Mitsuba's calls, importing ``mitsuba`` before ``pbr`` works, and pbr leaves the
user's variant as it found it."""

import os
import re
import shutil
import site
import subprocess
import sys
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr import backend, validate
from pbr.media.grid import write_vol

from mitsuba_scenes import BATCHES, SPP, material_box
from test_media import blob, fog_ball, grid_cube

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
T = mi.ScalarTransform4f

# Mitsuba's keys pbr does not have, by design (pbr/scene/params.py's docstring says why).
EXCEPTIONS = [r"allow_thread_reordering", r".*\.silhouette_sampling_weight", r".*\.shutter_open(_time)?",
              r".*\.sampling_weight", r".*\.(radiance|intensity|irradiance)\.d65\..*"]


def mitsuba_keys(d) -> set:
    return set(mi.traverse(mi.load_dict(d, optimize=False)).keys())


def missing_keys(d) -> list:
    ours = set(pbr.traverse(pbr.load_dict(d)).keys())
    return sorted(k for k in mitsuba_keys(d) - ours if not any(re.fullmatch(e, k) for e in EXCEPTIONS))


def media_scene(tmp_path):
    """A homogeneous ball (hg phase), a grid cloud and a top-level medium referenced as
    the interior of a shape and around the camera."""
    write_vol(str(tmp_path / "blob.vol"), blob(8))
    d = grid_cube(str(tmp_path / "blob.vol"))
    d.update({k: v for k, v in fog_ball({"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.8,
                                         "phase": {"type": "hg", "g": 0.6}}).items() if k == "ball"})
    d["ball"]["center"] = [-0.5, 0.2, 0.3]
    d["fog"] = {"type": "homogeneous", "sigma_t": 0.05, "albedo": {"type": "rgb", "value": [0.5, 0.6, 0.7]}}
    d["sensor"]["medium"] = {"type": "ref", "id": "fog"}
    d["pane"] = {"type": "disk", "to_world": T().translate([0.0, 0.0, 0.8]).scale(0.2), "bsdf": {"type": "null"},
                 "interior": {"type": "ref", "id": "fog"}}
    return d


# -- keys ----------------------------------------------------------------------------------
def test_cornell_box_keys_are_a_superset_of_mitsubas():
    d = pbr.cornell_box(8, 4)
    assert missing_keys(d) == []
    keys = set(pbr.traverse(pbr.load_dict(d)).keys())
    assert {"light.to_world", "small-box.vertex_positions", "small-box.vertex_normals", "small-box.faces",
            "sensor.to_world", "sensor.x_fov", "sensor.film.size"} <= keys
    assert len(keys) >= 27             # 4 before; Mitsuba has 41 (optimize=False), 14 of them exceptions


def test_media_keys_follow_mitsuba(tmp_path):
    d = media_scene(tmp_path)
    assert missing_keys(d) == []
    keys = set(pbr.traverse(pbr.load_dict(d)).keys())
    assert {"ball.interior_medium.sigma_t.value.value", "ball.interior_medium.albedo.value.value",
            "ball.interior_medium.phase_function.g", "ball.interior_medium.scale",
            "cloud.interior_medium.sigma_t.data",
            # the top-level 'fog', declared after the sensor that references it: Mitsuba lists
            # an object where its traversal first reaches it
            "sensor.medium.sigma_t.value.value", "sensor.medium.albedo.value.value"} <= keys
    # pbr's own factor of a grid (1) is internal, and old names are gone
    assert not {k for k in keys if ".interior." in k or k == "cloud.interior_medium.sigma_t.value.value"}


def _wrapped(bsdf):
    d = pbr.cornell_box(8, 4)
    d["small-box"]["bsdf"] = bsdf
    return d


_D = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.2, 0.1]}}
_R = {"type": "roughconductor", "alpha": 0.2}
_BUMPS = np.linspace(0, 1, 16, dtype=np.float32).reshape(4, 4, 1)


@pytest.mark.parametrize("bsdf", [
    {"type": "blendbsdf", "weight": 0.3, "y": _D, "x": _R},
    {"type": "twosided", "front": _D, "back": _R},
    {"type": "mask", "opacity": 0.4, "inner": _D},
    {"type": "normalmap", "normalmap": {"type": "rawconstant", "value": [0.5, 0.5, 1.0]}, "inner": _D},
    {"type": "bumpmap", "bumps": {"type": "bitmap", "data": _BUMPS, "raw": True}, "inner": _D},
    {"type": "blendbsdf", "weight": 0.5, "p": _D, "q": {"type": "twosided", "z": _R}},
], ids=["blendbsdf", "twosided", "mask", "normalmap", "bumpmap", "blend-of-twosided"])
def test_nested_bsdf_keys_follow_mitsuba(bsdf):
    """Mitsuba names the BSDFs nested in a BSDF by position (``bsdf_0``/``bsdf_1`` in a
    blend, ``brdf_0``/``brdf_1`` in a twosided, ``nested_bsdf`` in mask, normalmap and
    bumpmap; a bump map's texture ``nested_texture``), whatever their keys in the dict or
    XML; pbr used the dict keys (``small-box.bsdf.y.reflectance.value``)."""
    if bsdf["type"] == "bumpmap":      # Mitsuba's dict loader takes a tensor, made under pbr's variant
        bsdf = {**bsdf, "bumps": {**bsdf["bumps"], "data": mi.TensorXf(_BUMPS)}}
    d = _wrapped(bsdf)
    p = pbr.traverse(pbr.load_dict(d))     # first: Mitsuba's bitmap takes the tensor's storage
    nested = {k for k in mitsuba_keys(d) if re.search(r"\.(bsdf_\d|brdf_\d|nested_bsdf|nested_texture\.data)", k)}
    assert len(nested) >= 1 + (bsdf["type"] in ("blendbsdf", "twosided", "bumpmap"))
    assert nested <= set(p.keys())
    assert not [k for k in p.keys() if re.search(r"\.(x|y|front|back|inner|bumps|p|q|z)\.", k)]


def test_nested_bsdf_keys_update_the_image():
    """A renamed key is the nested BSDF's parameter: setting the blend's first component's
    albedo gives the image of the scene loaded with it; a top-level blend referenced by a
    shape declared before it takes the shape's key (as Mitsuba lists it)."""
    d = _wrapped({"type": "ref", "id": "mix"})
    d["mix"] = {"type": "blendbsdf", "weight": 0.3, "y": _D, "x": _R}
    assert missing_keys(d) == []
    scene = pbr.load_dict(d)
    p = pbr.traverse(scene)
    p["small-box.bsdf.bsdf_0.reflectance.value"] = mi.Color3f(0.1, 0.6, 0.2)
    p.update()
    d["mix"]["y"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.1, 0.6, 0.2]}}
    want = np.asarray(pbr.render(pbr.load_dict(d), seed=1))
    assert np.array_equal(np.asarray(pbr.render(scene, seed=1)), want)


def test_nested_bsdf_keys_of_xml_scenes(tmp_path):
    """The XML reader's names for unnamed nested BSDFs become Mitsuba's too."""
    f = tmp_path / "s.xml"
    f.write_text("""<scene version="3.0.0"><sensor type="perspective" id="sensor"><float name="fov" value="40"/>
<film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>
<emitter type="constant" id="light"/>
<shape type="sphere" id="obj"><bsdf type="blendbsdf"><float name="weight" value="0.3"/>
<bsdf type="diffuse"><rgb name="reflectance" value="0.5,0.2,0.1"/></bsdf>
<bsdf type="twosided"><bsdf type="roughconductor"/></bsdf></bsdf></shape></scene>""")
    keys = set(pbr.traverse(pbr.load_file(str(f))).keys())
    mkeys = set(mi.traverse(mi.load_file(str(f), optimize=False)).keys())
    assert {"obj.bsdf.bsdf_0.reflectance.value", "obj.bsdf.bsdf_1.brdf_0.alpha.value"} <= keys
    assert {k for k in mkeys if k.startswith("obj.bsdf.")} <= keys


def _lacking_cases():
    """label -> (scene dict, key prefix of the plugin) for each row of the table of keys pbr
    does not expose yet (docs/porting_from_mitsuba.md)."""
    def scene(**objects):
        return {"type": "scene", "sensor": {"type": "perspective", "fov": 40.0,
                                            "film": {"type": "hdrfilm", "width": 4, "height": 4}}, **objects}
    sky = {"type": "constant"}

    def ball(bsdf):
        return scene(obj={"type": "sphere", "bsdf": bsdf}, light=sky)

    def bitmap():
        return {"type": "bitmap", "data": mi.TensorXf(np.full((4, 4, 3), 0.5, np.float32))}
    diffuse = {"type": "diffuse"}
    cases = {t: (ball({"type": t}), "obj.bsdf.") for t in ("plastic", "roughplastic", "principled", "principledthin")}
    cases["conductor"] = (ball({"type": "conductor", "material": "Au"}), "obj.bsdf.")
    cases["spectrum"] = (ball({"type": "diffuse", "reflectance": {"type": "spectrum", "value": [(400, 0.2), (700, 0.8)]}}),
                         "obj.bsdf.reflectance.")
    cases["bitmap"] = (ball({"type": "diffuse", "reflectance": bitmap()}), "obj.bsdf.reflectance.")
    cases["checkerboard"] = (ball({"type": "diffuse", "reflectance": {"type": "checkerboard"}}), "obj.bsdf.reflectance.")
    cases["normalmap"] = (ball({"type": "normalmap", "normalmap": {"type": "rawconstant", "value": [0.5, 0.5, 1.0]},
                                "b": diffuse}), "obj.bsdf.")
    cases["bumpmap"] = (ball({"type": "bumpmap", "t": {**bitmap(), "raw": True}, "b": diffuse}), "obj.bsdf.")
    for t in ("point", "spot", "directional"):
        cases[t] = (scene(obj={"type": "sphere"}, em={"type": t}), "em.")
    cases["envmap"] = (scene(obj={"type": "sphere"}, em={"type": "envmap", "bitmap": mi.Bitmap(np.ones((4, 8, 3), np.float32))}),
                       "em.")
    cases["projector"] = (scene(obj={"type": "sphere"}, em={"type": "projector", "irradiance": bitmap()}), "em.")
    return cases


def _documented_lacking() -> dict:
    """label -> the keys of its row in the docs' table (every backquoted name)."""
    text = open(os.path.join(ROOT, "docs", "porting_from_mitsuba.md"), encoding="utf-8").read()
    after = text.split("Mitsuba keys pbr does not expose yet", 1)[1]
    table = after[after.index("\n|"):].split("\n\n", 1)[0].strip().splitlines()
    rows = {}
    for line in table[2:]:
        plugin, keys = line.strip("|").split("|")[:2]
        for label in re.findall(r"`([^`]+)`", plugin)[:1 if "with" in plugin else None]:
            rows[label] = set(re.findall(r"`([^`]+)`", keys))
    return rows


def test_keys_pbr_lacks_are_listed():
    """Each Mitsuba key pbr does not expose yet (beyond the exceptions by design) is in
    docs/porting_from_mitsuba.md's table, and each listed key is still missing."""
    documented = _documented_lacking()
    for label, (d, prefix) in _lacking_cases().items():
        mkeys = mitsuba_keys(d)          # Mitsuba takes a bitmap's tensor: the dict is made again
        ours = set(pbr.traverse(pbr.load_dict(_lacking_cases()[label][0])).keys())
        missing = sorted(k for k in mkeys - ours if not any(re.fullmatch(e, k) for e in EXCEPTIONS))
        assert all(k.startswith(prefix) for k in missing), (label, missing)
        assert {k[len(prefix):] for k in missing} == documented[label], label


def test_xml_scene_keys_follow_mitsuba():
    """The XML reader names unnamed children (``emitter_0``); keys use Mitsuba's names."""
    path = os.path.join(ROOT, "scenes", "cornell_box.xml")
    keys = set(pbr.traverse(pbr.load_file(path, res=8, spp=4)).keys())
    mkeys = set(mi.traverse(mi.load_file(path, optimize=False)).keys())
    assert not [k for k in mkeys - keys if not any(re.fullmatch(e, k) for e in EXCEPTIONS)]


def test_medium_keys_change_the_image():
    d = fog_ball({"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.8, "phase": {"type": "hg", "g": 0.5}})
    d["sensor"]["film"].update(width=16, height=16)
    scene = pbr.load_dict(d)
    p = pbr.traverse(scene)
    a = np.asarray(pbr.render(scene, seed=1, spp=16))
    for key, value in (("ball.interior_medium.sigma_t.value.value", 0.5),
                       ("ball.interior_medium.phase_function.g", -0.5)):
        ref = fog_ball({"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.8, "phase": {"type": "hg", "g": 0.5}})
        ref["sensor"]["film"].update(width=16, height=16)
        if key.endswith("g"):
            ref["ball"]["interior"]["phase"]["g"] = value
            p["ball.interior_medium.sigma_t.value.value"] = 2.0
        else:
            ref["ball"]["interior"]["sigma_t"] = value
        p[key] = value
        p.update()
        b = np.asarray(pbr.render(scene, seed=1, spp=16))
        c = np.asarray(pbr.render(pbr.load_dict(ref), seed=1, spp=16))
        assert np.abs(b - a).mean() > 1e-3 and np.allclose(b, c, atol=1e-6), key


# -- geometry and sensor updates -------------------------------------------------------------
LIGHT_TF = T().translate([0.3, 0.99, 0.01]).rotate([1, 0, 0], 90).scale([0.23, 0.19, 0.19])
CAMERA_TF = T().look_at(origin=[0.5, 0.2, 3.9], target=[0, 0, 0], up=[0, 1, 0])


def moved(d, box_tf=None):
    d["light"]["to_world"] = LIGHT_TF
    d["sensor"]["to_world"] = CAMERA_TF
    d["sensor"]["fov"] = 45.0
    d["sensor"]["fov_axis"] = "x"
    if box_tf is not None:
        d["small-box"]["to_world"] = box_tf
    return d


def test_updates_equal_a_fresh_load():
    """Updating to_world, vertex_positions / vertex_normals and the sensor gives the image
    of the scene loaded with those values, bit for bit."""
    box = T().translate([0.335, -0.5, 0.38]).rotate([0, 1, 0], 30).scale(0.3)
    scene = pbr.load_dict(pbr.cornell_box(24, 8))
    before = np.asarray(pbr.render(scene, seed=2))
    target = pbr.load_dict(moved(pbr.cornell_box(24, 8), box))
    want = np.asarray(pbr.render(target, seed=2))
    tp = pbr.traverse(target)
    p = pbr.traverse(scene)
    p["light.to_world"] = LIGHT_TF
    p["small-box.vertex_positions"] = tp["small-box.vertex_positions"]
    p["small-box.vertex_normals"] = tp["small-box.vertex_normals"]
    p["sensor.to_world"] = CAMERA_TF
    p["sensor.x_fov"] = 45.0
    changed = p.update()
    names = {n for _, ns in changed for n in ns}
    assert {"to_world", "vertex_positions", "vertex_normals", "x_fov"} <= names
    got = np.asarray(pbr.render(scene, seed=2))
    assert np.abs(got - before).mean() > 0.01
    assert np.array_equal(got, want)
    assert np.allclose(np.array(scene.bbox().max), np.array(target.bbox().max))


def _thinlens_box(aperture, focus):
    d = pbr.cornell_box(16, 8)
    d["sensor"] = {**d["sensor"], "type": "thinlens", "aperture_radius": aperture, "focus_distance": focus}
    return d


def test_thinlens_keys_update_the_image():
    """A ``thinlens`` sensor's ``aperture_radius`` and ``focus_distance`` are keys (as in
    Mitsuba); updating them gives the image of the scene loaded with the new values."""
    assert missing_keys(_thinlens_box(0.05, 3.0)) == []
    scene = pbr.load_dict(_thinlens_box(0.05, 3.0))
    before = np.asarray(pbr.render(scene, seed=4))
    p = pbr.traverse(scene)
    assert float(p["sensor.aperture_radius"][0]) == pytest.approx(0.05)
    p["sensor.aperture_radius"] = 0.2
    p["sensor.focus_distance"] = 2.5
    p.update()
    got = np.asarray(pbr.render(scene, seed=4))
    assert np.abs(got - before).mean() > 1e-3
    assert np.array_equal(got, np.asarray(pbr.render(pbr.load_dict(_thinlens_box(0.2, 2.5)), seed=4)))
    with pytest.raises(ValueError, match="sensor.focus_distance: expected a distance >= 0"):
        p["sensor.focus_distance"] = -1.0


def test_in_place_change_with_set_dirty():
    """``dr.scatter`` into a mesh's vertex positions, then ``set_dirty``: the image of the
    scene loaded with the moved block."""
    d = pbr.cornell_box(16, 4)
    scene = pbr.load_dict(d)
    before = np.asarray(pbr.render(scene, seed=1))
    d["large-box"]["to_world"] = T().translate([0.0, 0.2, 0.0]) @ d["large-box"]["to_world"]
    target = pbr.load_dict(d)
    tp, p = pbr.traverse(target), pbr.traverse(scene)
    for key in ("large-box.vertex_positions", "large-box.vertex_normals"):   # normals: same up to rounding
        buf = p[key]
        dr.scatter(buf, tp[key], dr.arange(mi.UInt32, dr.width(buf)))
        p.set_dirty(key)
    p.update()
    got = np.asarray(pbr.render(scene, seed=1))
    assert np.abs(got - before).mean() > 1e-3
    assert np.array_equal(got, np.asarray(pbr.render(target, seed=1)))


def test_updates_match_mitsuba_after_the_same_update():
    """The moved light, block and camera against Mitsuba's render after the same updates
    (statistical test); against Mitsuba's scene left as it was, the test fails."""
    d = material_box({"type": "diffuse"})
    scene = pbr.load_dict(d)
    p = pbr.traverse(scene)
    ref = mi.load_dict(d, optimize=False)
    mp = mi.traverse(ref)
    shifted = (np.array(p["small-box.vertex_positions"]).reshape(-1, 3) + [0.0, 0.25, -0.1]).astype(np.float32)
    for params in (p, mp):
        params["light.to_world"] = LIGHT_TF
        params["small-box.vertex_positions"] = mi.Float(shifted.ravel())
        params["sensor.to_world"] = mi.Transform4f(CAMERA_TF.matrix.numpy().tolist())
        params.update()

    def ours(seed=0, spp=0):
        return np.asarray(pbr.render(scene, seed=seed, spp=spp))

    def theirs(seed=0, spp=0):
        return np.asarray(mi.render(ref, seed=seed, spp=spp), dtype=np.float32)[..., :3]

    res = validate.compare_renders(ours, theirs, spp=SPP, batches=BATCHES, seed_a=21, seed_b=22)
    assert res.passed, res
    stale = validate.mitsuba_render_fn(d)
    bad = validate.compare_renders(ours, stale, spp=SPP, batches=BATCHES, seed_a=21, seed_b=22)
    assert not bad.passed, bad


def test_geometry_gradients_need_an_integrator_that_has_them():
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": "volpath"}
    scene = pbr.load_dict(d)
    p = pbr.traverse(scene)
    dr.enable_grad(p["small-box.vertex_positions"])
    with pytest.raises(NotImplementedError, match="'volpath' integrator does not differentiate"):
        pbr.render(scene, p)


def test_bad_sensor_and_film_updates_name_the_key():
    p = pbr.traverse(pbr.load_dict(pbr.cornell_box(8, 4)))
    with pytest.raises(ValueError, match="sensor.to_world.*rigid"):
        p["sensor.to_world"] = T().scale(2.0)
    with pytest.raises(ValueError, match="sensor.film.size.*read-only"):
        p["sensor.film.size"] = mi.ScalarVector2u(4, 4)
    with pytest.raises(ValueError, match="sensor.far_clip"):
        p["sensor.far_clip"] = 0.0001
    assert list(p["sensor.film.size"]) == [8, 8] and p.flags("sensor.film.size") & int(mi.ParamFlags.ReadOnly)


def test_later_mitsubas_mesh_keys_point_to_mitsuba_3_9s():
    """The current Mitsuba tutorials write ``<mesh>.positions`` (a later Mitsuba's (N, 3)
    tensor); the error names the Mitsuba 3.9 key pbr has and how to convert."""
    p = pbr.traverse(pbr.load_dict(pbr.cornell_box(8, 4)))
    for last in ("positions", "normals", "texcoords"):
        with pytest.raises(KeyError, match=rf"'small-box.vertex_{last}', a flat array.*dr.unravel"):
            p[f"small-box.{last}"]
    with pytest.raises(KeyError) as e:
        p["red.positions"]           # a BSDF: no hint
    assert "vertex_" not in str(e.value).split("known keys")[0]


def test_sample_border_error_says_what_to_do():
    d = pbr.cornell_box(8, 4)
    d["sensor"]["film"]["sample_border"] = True
    with pytest.raises(pbr.SceneError, match="sensor.film.sample_border.*Mitsuba's default.*remove the entry"):
        pbr.load_dict(d)


# -- SceneParameters' methods ------------------------------------------------------------------
def test_scene_parameters_methods_follow_mitsuba():
    scene = pbr.load_dict(pbr.cornell_box(8, 4))
    p = pbr.traverse(scene)
    n = len(p)
    assert p.get("nope") is None and p.get("nope", 3) == 3
    assert np.allclose(np.array(p.get("red.reflectance.value")), [[0.570068], [0.0430135], [0.0443706]])
    k, v = next(iter(p))                                    # Mitsuba: iteration gives pairs
    assert k in p and type(v) is type(p[k])
    assert [k for k, _ in p.items()] == list(p.keys()) and len(p.values()) == n
    assert p.flags("red.reflectance.value") == 0
    assert p.flags("light.to_world") & int(mi.ParamFlags.NonDifferentiable)
    # update(values) skips keys the parameters lack (an optimizer's own variables)
    changed = p.update({"red.reflectance.value": mi.Color3f(0.2, 0.3, 0.4), "angle": mi.Float(1.0)})
    assert [names for _, names in changed] == [{"value"}]
    q = p.copy()
    q.keep(r".*\.reflectance\.value")
    assert sorted(q.keys()) == ["green.reflectance.value", "red.reflectance.value", "white.reflectance.value"]
    assert len(p) == n
    q = p.copy()
    q.keep(["sensor\\.to_world", "light\\..*"])
    assert sorted(q.keys()) == ["light.emitter.radiance.value", "light.to_world", "sensor.to_world"]
    q = p.copy()
    q.keep(None)
    assert all(not q.flags(k) & int(mi.ParamFlags.NonDifferentiable) for k in q.keys()) and "red.reflectance.value" in q
    assert "small-box.vertex_positions" in q and "light.to_world" not in q   # geometry: differentiable


# -- Scene, render, load_dict -----------------------------------------------------------------
def test_scene_methods_answer_like_mitsubas():
    d = pbr.cornell_box(8, 4)
    d["sky"] = {"type": "constant", "radiance": 0.1}
    scene = pbr.load_dict(d)
    ref = mi.load_dict(d, optimize=False)
    assert [s.id() for s in scene.shapes()] == [s.id() for s in ref.shapes()]
    for a, b in zip(scene.shapes(), ref.shapes()):
        assert np.allclose(np.array(a.bbox().min), np.array(b.bbox().min), atol=1e-6)
        assert a.is_emitter() == b.is_emitter() and a.is_mesh() == b.is_mesh()
    assert np.allclose(np.array(scene.bbox().max), np.array(ref.bbox().max))
    assert [e.id() for e in scene.emitters()] == [e.id() for e in ref.emitters()] == ["emitter", "sky"]
    assert scene.emitters()[0].shape().id() == "light" and scene.emitters()[1].is_environment()
    (s,), (r,) = scene.sensors(), ref.sensors()
    assert s.id() == r.id() == "sensor"
    assert np.allclose(s.world_transform().matrix.numpy(), r.world_transform().matrix.numpy(), atol=1e-6)
    assert list(s.film().size()) == list(r.film().size()) == list(s.film().crop_size())
    assert s.sampler().sample_count() == r.sampler().sample_count() == 4
    assert np.allclose(np.array(s.bbox().min), np.array(r.bbox().min))
    assert scene.sensors[0] is s.camera                       # pbr's own list still indexes
    with pytest.raises(NotImplementedError, match="pbr.traverse"):
        scene.shapes()[1].bsdf()


def test_render_takes_integrator_and_sensor_objects():
    d = pbr.cornell_box(16, 8)
    scene = pbr.load_dict(d, optimize=False, parallel=False)
    d2 = pbr.cornell_box(16, 8)
    d2["sensor"].update(to_world=CAMERA_TF, fov=45.0, fov_axis="x")
    d2["integrator"]["max_depth"] = 2
    want = np.asarray(pbr.render(pbr.load_dict(d2), seed=3))
    sensor = pbr.load_dict(dict(d2["sensor"]))
    integrator = pbr.load_dict({"type": "path", "max_depth": 2})
    for integ in (integrator, {"type": "path", "max_depth": 2}):
        got = np.asarray(pbr.render(scene, sensor=sensor, integrator=integ, seed=3))
        assert np.array_equal(got, want)
    assert len(scene.sensors) == 1
    same = np.asarray(pbr.render(scene, sensor=scene.sensors()[0], seed=3))
    assert np.array_equal(same, np.asarray(pbr.render(scene, sensor=0, seed=3)))
    with pytest.raises(TypeError, match="Mitsuba object"):
        pbr.render(scene, integrator=mi.load_dict({"type": "path"}))
    with pytest.raises(pbr.SceneError, match="expected a dict of type 'scene'"):
        pbr.load_dict({"type": "diffuse"})


# -- variants and libLLVM --------------------------------------------------------------------
def test_pbr_leaves_the_users_variant(monkeypatch):
    """Must-fail: with pbr's calls switching silently (the old behaviour), the variant
    after load_dict is pbr's."""
    mine = backend.variant()
    user = mine.replace("_ad_spectral", "_ad_rgb")
    if user not in mi.variants():
        pytest.skip(f"{user} is not in this Mitsuba build")
    monkeypatch.setattr(backend, "_warned", False)
    try:
        mi.set_variant(user)
        with pytest.warns(backend.VariantWarning, match="set_backend"):
            scene = pbr.load_dict(pbr.cornell_box(8, 4))
        assert mi.variant() == user
        with warnings.catch_warnings():
            warnings.simplefilter("error")                  # said once
            img = pbr.render(scene, seed=0)
            assert mi.variant() == user
            p = pbr.traverse(scene)
            p["light.to_world"] = LIGHT_TF
            p.update()
            assert mi.variant() == user and np.isfinite(np.asarray(img)).all()
        assert type(mi.load_dict({"type": "diffuse"})).__module__ == "mitsuba"
        assert mi.variant() == user
    finally:
        mi.set_variant(mine)


def test_backend_follows_the_users_variant(monkeypatch):
    monkeypatch.delenv("PBR_BACKEND", raising=False)
    for variant, want in (("llvm_ad_rgb", "llvm"), ("cuda_ad_mono", "cuda"), ("scalar_rgb", "auto"), (None, "auto")):
        monkeypatch.setattr(mi, "variant", lambda v=variant: v)
        assert backend._default_backend() == want


# libLLVM matters to the LLVM backend only: these checks run there (skipped otherwise).
IMPORT_FIRST = """
import os, sys
import mitsuba as mi
mi.set_variant(BACKEND + "_ad_spectral")
import drjit as dr
import pbr
pbr.set_backend(BACKEND)
img = pbr.render(pbr.load_dict(pbr.cornell_box(8, 4)), seed=0)
import numpy as np
print("OK", float(np.mean(np.asarray(img))), os.environ.get("DRJIT_LIBLLVM_PATH"))
"""


def _run(code, env):
    code = code.replace("BACKEND", repr("llvm"))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)


def _clean_env():
    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    env["PYTHONPATH"] = os.pathsep.join([os.path.join(ROOT, "src")] + [
        p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


llvm_only = pytest.mark.skipif(pbr.get_backend() != "llvm" or "llvm_ad_spectral" not in mi.variants(),
                               reason="libLLVM set-up: LLVM backend only")


@llvm_only
def test_the_start_up_hook_lets_mitsuba_be_imported_first():
    """What pbr-libllvm.pth runs at start-up, then a Mitsuba script's first lines."""
    out = _run("import _pbr_libllvm\n" + IMPORT_FIRST, _clean_env())
    assert out.returncode == 0 and out.stdout.startswith("OK"), out.stderr[-3000:]
    assert float(out.stdout.split()[1]) > 0.05


@llvm_only
def test_importing_mitsuba_first_works_in_this_environment():
    """The installed hook (``make test`` installs it); an environment installed before the
    hook existed lacks it: reinstall."""
    dirs = site.getsitepackages() + [site.getusersitepackages()]
    if not any(os.path.exists(os.path.join(d, "pbr-libllvm.pth")) for d in dirs):
        pytest.skip("pbr-libllvm.pth is not installed in this environment (an install older than the hook: "
                    "reinstall pbr, e.g. `make test`)")
    out = _run(IMPORT_FIRST, _clean_env())
    assert out.returncode == 0 and out.stdout.startswith("OK"), out.stderr[-3000:]


def _project_copy(tmp_path):
    src = tmp_path / "proj"
    src.mkdir()
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy(os.path.join(ROOT, name), src / name)
    shutil.copytree(os.path.join(ROOT, "src"), src / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    return src


def test_the_build_writes_the_start_up_hook(tmp_path):
    """setup.py's build_py puts pbr-libllvm.pth (``import _pbr_libllvm``) and
    _pbr_libllvm.py at the root of the tree a wheel installs into site-packages."""
    src = _project_copy(tmp_path)
    out = subprocess.run([sys.executable, "setup.py", "-q", "build_py", "--build-lib", str(tmp_path / "lib")],
                         capture_output=True, text=True, cwd=src, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert (tmp_path / "lib" / "pbr-libllvm.pth").read_text() == "import _pbr_libllvm\n"
    assert (tmp_path / "lib" / "_pbr_libllvm.py").exists() and (tmp_path / "lib" / "pbr" / "render.py").exists()


def _can_build_wheels() -> bool:
    """Whether this environment's setuptools can build pbr: pyproject.toml's license is an
    SPDX expression, which needs setuptools >= 77 (``make``'s venv has it; pip's isolated
    builds fetch it). Asked of the package metadata, not by importing setuptools: in a
    process where something already imported the standard library's distutils, importing
    setuptools fails (its distutils shim asserts)."""
    from importlib import metadata
    try:
        version = metadata.version("setuptools")
    except metadata.PackageNotFoundError:
        return False
    return tuple(int(x) for x in version.split(".")[:2] if x.isdigit()) >= (77, 0)


@pytest.mark.skipif(not _can_build_wheels(), reason="needs setuptools >= 77 (pyproject.toml's build requirement; "
                    "pip's isolated builds have it; checked by the build_py test otherwise)")
@pytest.mark.parametrize("hook", ["build_wheel", "build_editable"])
def test_wheels_install_the_start_up_hook(tmp_path, hook):
    """A wheel and an editable wheel (``pip install -e``, as ``make test`` does) carry
    pbr-libllvm.pth at their root (editable: _pbr_libllvm.py stays in src/, on the path
    the wheel adds)."""
    src = _project_copy(tmp_path)
    code = f"import setuptools.build_meta as b; print(b.{hook}({str(tmp_path / 'dist')!r}))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=src, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    import zipfile
    with zipfile.ZipFile(tmp_path / "dist" / out.stdout.split()[-1]) as z:
        names = z.namelist()
        assert z.read("pbr-libllvm.pth").decode() == "import _pbr_libllvm\n"
    assert ("_pbr_libllvm.py" in names) == (hook == "build_wheel")
