import os

import numpy as np
import pytest
import mitsuba as mi

import pbr


def test_render_returns_float32_rgb_image():
    scene = pbr.load_dict(pbr.cornell_box(16, 4))
    img = pbr.render(scene)
    a = np.asarray(img)
    assert a.shape == (16, 16, 3) and a.dtype == np.float32
    assert np.all(np.isfinite(a)) and a.mean() > 0.05
    assert scene.spp == 4


def test_same_seed_same_image_different_seed_differs():
    scene = pbr.load_dict(pbr.cornell_box(16, 4))
    a = np.asarray(pbr.render(scene, seed=3))
    b = np.asarray(pbr.render(scene, seed=3))
    c = np.asarray(pbr.render(scene, seed=4))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_multipass_equals_single_pass(monkeypatch):
    from pbr.integrators import base
    scene = pbr.load_dict(pbr.cornell_box(8, 16))
    a = np.asarray(pbr.render(scene, seed=1))
    monkeypatch.setenv("PBR_MAX_SAMPLES_PER_PASS", str(8 * 8 * 4))
    assert base.SamplingIntegrator._plan(scene.integrator, scene, 0, 0)[-1] == 4   # 4 passes
    b = np.asarray(pbr.render(scene, seed=1, progress=False))
    assert np.allclose(a, b, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("value", ["abc", "0", "-5", "1e6"])
def test_bad_samples_per_pass_is_a_clear_error(monkeypatch, value):
    scene = pbr.load_dict(pbr.cornell_box(8, 4))
    monkeypatch.setenv("PBR_MAX_SAMPLES_PER_PASS", value)
    with pytest.raises(ValueError, match=f"PBR_MAX_SAMPLES_PER_PASS='{value}': expected a positive integer"):
        pbr.render(scene)


def test_samples_per_pass_follow_the_backend(monkeypatch):
    from pbr.integrators import base
    monkeypatch.delenv("PBR_MAX_SAMPLES_PER_PASS", raising=False)
    assert base.max_samples_per_pass() == base.SAMPLES_PER_PASS[pbr.get_backend()]
    assert base.SAMPLES_PER_PASS == {"llvm": 1 << 22, "cuda": 1 << 26}


def test_traverse_keys_follow_mitsuba():
    scene = pbr.load_dict(pbr.cornell_box(8, 4))
    params = pbr.traverse(scene)
    assert {"red.reflectance.value", "green.reflectance.value", "white.reflectance.value",
            "light.emitter.radiance.value"} <= set(params.keys())
    mkeys = set(mi.traverse(mi.load_dict(mi.cornell_box())).keys())
    assert "red.reflectance.value" in mkeys
    old = np.asarray(pbr.render(scene, seed=0)).mean()
    params["light.emitter.radiance.value"] = mi.Color3f(params["light.emitter.radiance.value"]) * 2
    params.update()
    assert np.asarray(pbr.render(scene, seed=0)).mean() == pytest.approx(2 * old, rel=1e-3)


@pytest.mark.parametrize("mutate, where", [
    (lambda d: d["red"]["reflectance"].__setitem__("valeu", 1), "scene.red.reflectance.valeu"),
    (lambda d: d.__setitem__("x", {"type": "nonsense"}), "scene.x"),
    (lambda d: d["floor"].__setitem__("bsdf", {"type": "ref", "id": "nope"}), "scene.floor.bsdf"),
    (lambda d: d["red"]["reflectance"].__setitem__("value", [2, 0, 0]), "scene.red.reflectance.value"),
    (lambda d: d["sensor"]["film"].__setitem__("width", "wide"), "scene.sensor.film.width"),
    (lambda d: d["integrator"].__setitem__("max_depth", 2.5), "scene.integrator.max_depth"),
    (lambda d: d["sensor"].__setitem__("fov_axis", "z"), "scene.sensor.fov_axis"),
])
def test_bad_input_names_the_key_path(mutate, where):
    d = pbr.cornell_box(8, 4)
    mutate(d)
    with pytest.raises(pbr.SceneError) as e:
        pbr.load_dict(d)
    assert str(e.value).startswith(where), str(e.value)


def test_load_file_roundtrip(tmp_path):
    xml = tmp_path / "s.xml"
    xml.write_text("""<scene version="3.0.0">
  <default name="spp" value="4"/>
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
  </sensor>
  <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1,2,3"/></emitter></shape>
</scene>""")
    scene = pbr.load_file(str(xml), spp=512)
    assert scene.spp == 512
    a = np.asarray(pbr.render(scene))
    assert a.shape == (6, 8, 3)
    # The rectangle fills the centre of the view; its radiance is rgb (1, 2, 3).
    assert np.allclose(a[2:4, 3:5].mean(axis=(0, 1)), [1, 2, 3], rtol=0.05), a[2:4, 3:5]
    with pytest.raises(FileNotFoundError):
        pbr.load_file(str(tmp_path / "missing.xml"))


def test_backend_errors():
    with pytest.raises(pbr.BackendError):
        pbr.set_backend("metal")
    assert pbr.get_backend() in ("llvm", "cuda")


def test_scene_without_lights_renders_black():
    d = pbr.cornell_box(8, 4)
    del d["light"]["emitter"]
    img = np.asarray(pbr.render(pbr.load_dict(d)))
    assert img.shape == (8, 8, 3) and np.all(img == 0)


def test_render_with_another_integrator_uses_its_light_sampler():
    """``render(scene, integrator=X)`` samples lights with X's ``light_sampler``: on a
    scene loaded with path/uniform, X = path/power gives the power-sampled scene's image
    sample for sample, not the uniform one's (which it used to: the light sampler was
    built with the scene, from the scene's integrator)."""
    from pbr.integrators import INTEGRATORS
    from pbr.plugins.props import Props

    def scene(kind):
        d = pbr.cornell_box(16, 4)
        d["integrator"] = {"type": "path", "max_depth": 3, "light_sampler": kind}
        d["dim"] = {"type": "point", "position": [0.5, 0.5, 0.5], "intensity": 0.05}
        return pbr.load_dict(d)

    uniform, power = scene("uniform"), scene("power")
    x = INTEGRATORS["path"](Props({"type": "path", "max_depth": 3, "light_sampler": "power"}, "scene.integrator"))
    img = np.asarray(pbr.render(uniform, integrator=x, seed=1))
    assert np.array_equal(img, np.asarray(pbr.render(power, seed=1)))
    assert not np.array_equal(img, np.asarray(pbr.render(uniform, seed=1)))
    assert uniform.integrator.light_sampler.uniform and not x.light_sampler.uniform


def test_a_medium_reference_is_not_taken_for_the_shapes_bsdf():
    """A shape with an ``interior`` reference and no BSDF gets the medium and Mitsuba's
    default diffuse BSDF (the loader used to take any nested reference for the BSDF:
    "unsupported BSDF type 'homogeneous'")."""
    d = pbr.cornell_box(8, 2)
    d["fog"] = {"type": "homogeneous", "sigma_t": 1.0}
    d["small-box"]["interior"] = {"type": "ref", "id": "fog"}
    del d["small-box"]["bsdf"]
    d["integrator"] = {"type": "volpath"}
    scene = pbr.load_dict(d)
    s = scene.shape_ids.index("small-box")
    assert np.array(scene.shape_interior)[s] == 1
    assert scene.bsdfs.entries[np.array(scene.shape_bsdf)[s]][0] == "diffuse"


@pytest.mark.parametrize("kwargs, message", [
    ({"spp": 2.5}, "spp must be a non-negative integer, got 2.5"),
    ({"spp": -1}, "spp must be a non-negative integer, got -1"),
    ({"spp_grad": "4"}, "spp_grad must be a non-negative integer, got '4'"),
    ({"seed": 2**32}, r"seed must be an integer in \[0, 2\^32\) \(seeds are 32-bit\), got 4294967296"),
    ({"seed": -1}, r"seed must be an integer in \[0, 2\^32\)"),
    ({"seed_grad": True}, r"seed_grad must be an integer in \[0, 2\^32\) or a mi.UInt32, got True"),
])
def test_bad_spp_and_seeds_are_clear_errors(kwargs, message):
    scene = pbr.load_dict(pbr.cornell_box(8, 4))
    with pytest.raises(ValueError, match=f"render: {message}"):
        pbr.render(scene, **kwargs)


def test_largest_seed_and_numpy_counts_are_accepted():
    scene = pbr.load_dict(pbr.cornell_box(8, 4))
    a = np.asarray(pbr.render(scene, seed=2**32 - 1, spp=np.int64(4)))
    b = np.asarray(pbr.render(scene, seed=0, spp=4))
    assert a.shape == b.shape and not np.array_equal(a, b)


def test_load_string_equals_load_file():
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes", "cornell_box.xml")
    a = np.asarray(pbr.render(pbr.load_string(open(path).read(), res=8, spp=2), seed=1))
    b = np.asarray(pbr.render(pbr.load_file(path, res=8, spp=2), seed=1))
    assert a.shape == (8, 8, 3) and np.array_equal(a, b)
    with pytest.raises(pbr.scene.xml.XMLError, match="<string>:1:"):
        pbr.load_string("<scene version='3.0.0'><foo/></scene>")
