"""The ``mesh_attribute`` texture and PLY/OBJ mesh attributes: attribute names as Mitsuba's
PLY loader gives them, per-hit values against Mitsuba's ``Mesh.eval_attribute``, images
against Mitsuba (with sabotaged variants that must fail), gradients, errors."""

import numpy as np
import drjit as dr
import mitsuba as mi
import pytest
import trimesh

import pbr
from pbr import validate
from pbr.textures import meshattr
from mitsuba_scenes import BATCHES, SPP, material_box

N_GRID = 5


def T():
    return mi.ScalarTransform4f()


def _write(tm: trimesh.Trimesh, path, encoding="binary") -> str:
    with open(path, "wb") as f:
        f.write(trimesh.exchange.ply.export_ply(tm, encoding=encoding))
    return str(path)


def _grid(n=N_GRID, seed=3):
    """An n x n vertex grid on [-1, 1]^2 (z = 0, facing +z) with random float vertex
    colours (r, g, b), a 1-channel attribute ``w_0`` and a 3-channel ``albedo_r/g/b``."""
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)
    q = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    f = np.concatenate([np.stack([q, q + 1, q + n], 1), np.stack([q + 1, q + n + 1, q + n], 1)])
    tm = trimesh.Trimesh(v, f, process=False)
    rng = np.random.default_rng(seed)
    for k in "rgb":
        tm.vertex_attributes[k] = rng.uniform(0.05, 0.95, n * n).astype(np.float32)
    tm.vertex_attributes["w_0"] = rng.uniform(0.2, 0.8, n * n).astype(np.float32)
    for k in ("albedo_r", "albedo_g", "albedo_b"):
        tm.vertex_attributes[k] = rng.uniform(0.1, 0.9, n * n).astype(np.float32)
    return tm


def _box(seed=4):
    """Mitsuba's cube ([-1, 1]^3) with random float face colours (red, green, blue)."""
    tm = trimesh.creation.box(extents=(2, 2, 2))
    tm = trimesh.Trimesh(tm.vertices, tm.faces, process=False)
    rng = np.random.default_rng(seed)
    for k in ("red", "green", "blue"):
        tm.face_attributes[k] = rng.uniform(0.05, 0.95, len(tm.faces)).astype(np.float32)
    return tm


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("meshattr")
    return {"grid": _write(_grid(), d / "grid.ply"), "box": _write(_box(), d / "box.ply"), "dir": d}


def _tex(name, scale=None):
    t = {"type": "mesh_attribute", "name": name}
    if scale is not None:
        t["scale"] = scale
    return t


def _attr(name, scale=None):
    return {"type": "diffuse", "reflectance": _tex(name, scale)}


def _mirror(name, scale=None):
    return {"type": "roughconductor", "alpha": 0.3, "specular_reflectance": _tex(name, scale)}


def _scene(files, wall=None, small=None, large=None):
    """material_box whose back wall is the colour grid (diffuse, vertex_color) and whose
    blocks are PLY cubes with face colours: a diffuse one and a coloured rough metal (two BSDF
    families, so textures are evaluated inside the family dispatch)."""
    d = material_box({"type": "diffuse"})
    d["back"] = {"type": "ply", "filename": files["grid"], "to_world": T().translate([0, 0, -1]),
                 "bsdf": wall or _attr("vertex_color")}
    for k, b in (("small-box", small or _attr("face_color")), ("large-box", large or _mirror("face_color"))):
        d[k] = {"type": "ply", "filename": files["box"], "face_normals": True, "to_world": d[k]["to_world"],
                "bsdf": b}
    return d


# ------------------------------------------------------------------------- loading

def test_attribute_names_match_mitsubas_ply_loader(files, tmp_path):
    """Attribute names and channel counts as Mitsuba's PLY loader gives them, including
    the grouping rules (``albedo_r/g/b`` -> ``vertex_albedo_color``, ``w_0`` -> ``vertex_w``,
    two fields -> dropped, no postfix -> dropped), and the file's values."""
    tm = _grid()
    tm.vertex_attributes["q_x"] = np.ones(len(tm.vertices), np.float32)   # 2 fields: ignored
    tm.vertex_attributes["q_y"] = np.ones(len(tm.vertices), np.float32)
    tm.vertex_attributes["quality"] = np.ones(len(tm.vertices), np.float32)   # no postfix: ignored
    tm.face_attributes["id_0"] = np.arange(len(tm.faces)).astype(np.float32)
    path = _write(tm, tmp_path / "attrs.ply")
    with pytest.warns(UserWarning, match="2 fields"):
        scene = pbr.load_dict({"type": "scene", "m": {"type": "ply", "filename": path}})
    mesh = scene.mi_scene.shapes()[0]
    ref = mi.load_dict({"type": "ply", "filename": path})
    ours, theirs = meshattr.attribute_channels(mesh), meshattr.attribute_channels(ref)
    assert ours == theirs == {"vertex_color": 3, "vertex_w": 1, "vertex_albedo_color": 3, "face_id": 1}
    p_ours, p_ref = mi.traverse(mesh), mi.traverse(ref)
    for k in ("vertex_w", "face_id"):     # Mitsuba stores colours as sigmoid coefficients
        assert np.allclose(p_ours[k], p_ref[k])
    rgb = np.stack([tm.vertex_attributes[k] for k in "rgb"], 1)
    assert np.allclose(np.array(p_ours["vertex_color"]).reshape(-1, 3), rgb)


def test_trimesh_default_rgba_colours(tmp_path):
    """trimesh writes uchar RGBA: 4 channels (as in Mitsuba, unnormalised); the texture
    refuses them (Mitsuba silently evaluates them to 0)."""
    tm = _grid()
    tm = trimesh.Trimesh(tm.vertices, tm.faces, process=False,
                         vertex_colors=np.full((len(tm.vertices), 4), 200, np.uint8))
    path = _write(tm, tmp_path / "rgba.ply")
    ref = mi.load_dict({"type": "ply", "filename": path})
    d = {"type": "scene", "m": {"type": "ply", "filename": path, "bsdf": _attr("vertex_color")}}
    with pytest.warns(UserWarning, match="integer"):
        with pytest.raises(pbr.SceneError, match=r"scene\.m\.bsdf\.reflectance\.name: .*4 channels"):
            pbr.load_dict(d)
    assert meshattr.attribute_channels(ref)["vertex_color"] == 4


def test_obj_vertex_colours(tmp_path):
    path = tmp_path / "c.obj"
    path.write_text("v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0.5 1\nf 1 2 3\n")
    scene = pbr.load_dict({"type": "scene", "m": {"type": "obj", "filename": str(path)}})
    p = mi.traverse(scene.mi_scene.shapes()[0])
    assert np.allclose(np.array(p["vertex_color"]).reshape(-1, 3), [[1, 0, 0], [0, 1, 0], [0, 128 / 255, 1]])


# ---------------------------------------------------------------- per-hit values

def _hits(n=512, seed=1):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-0.95, 0.95, (2, n))
    o = mi.Point3f(mi.Float(xy[0]), mi.Float(xy[1]), mi.Float(np.full(n, 5.0)))
    return mi.Ray3f(o, mi.Vector3f(0, 0, -1))


@pytest.mark.parametrize("name, fn", [("vertex_color", "eval_attribute"), ("face_color", "eval_attribute"),
                                      ("vertex_w", "eval_attribute_1"), ("vertex_albedo_color", "eval_attribute")])
def test_values_equal_mitsubas_eval_attribute(files, name, fn):
    """The texture's spectrum at random hits equals Mitsuba's ``Mesh.eval_attribute`` on
    the same file (Mitsuba interpolates the spectra of the three vertices, too)."""
    path = files["box" if name == "face_color" else "grid"]
    tf = T().translate([0.1, -0.2, 0.3]).rotate([0, 0, 1], 20).scale([0.9, 1.1, 0.8])
    scale = 0.7
    scene = pbr.load_dict({"type": "scene", "m": {"type": "ply", "filename": path, "to_world": tf,
                                                  "bsdf": _attr(name, scale)}})
    ray = _hits()
    si, _ = scene.geometry.intersect(ray, mi.Bool(True))
    lam = mi.Spectrum(430.0, 510.0, 590.0, 680.0) + dr.zeros(mi.Spectrum, dr.width(ray))
    slot = scene.textures.mesh_attrs[0]
    ours = np.array(scene.textures.eval(slot, si, lam, illuminant=False))
    ref_scene = mi.load_dict({"type": "scene", "m": {"type": "ply", "filename": path, "to_world": tf}})
    rsi = ref_scene.ray_intersect(ray)
    rsi.wavelengths = lam
    ref = getattr(rsi.shape, fn)(name, rsi)
    ref = np.array(ref * scale)
    ref = np.broadcast_to(ref, ours.shape)
    ok = np.array(si.is_valid())
    assert ok.sum() > 300 and np.array_equal(ok, np.array(rsi.is_valid()))
    print(name, "hits", ok.sum(), "max |pbr - Mitsuba|", np.abs(ours - ref)[:, ok].max())
    assert np.allclose(ours[:, ok], ref[:, ok], atol=2e-5, rtol=1e-4), np.abs(ours - ref)[:, ok].max()
    # At plain surface coordinates (no hit) a mesh attribute is 0.
    assert np.all(np.array(scene.textures.eval(slot, si.uv, lam)) == 0)


def test_inside_combinators(files):
    """Nested in ``scale`` and ``mix`` (the hit reaches the leaves of a texture tree)."""
    ray = _hits(64)
    lam = mi.Spectrum(450.0, 520.0, 600.0, 680.0)

    def values(refl):
        scene = pbr.load_dict({"type": "scene", "m": {"type": "ply", "filename": files["grid"],
                                                      "bsdf": {"type": "diffuse", "reflectance": refl}}})
        si, _ = scene.geometry.intersect(ray, mi.Bool(True))
        top = len(scene.textures.items) - 1     # the root of the texture tree is added last
        return np.array(scene.textures.eval(top, si, lam + dr.zeros(mi.Spectrum, 64), illuminant=False))

    plain = values(_tex("vertex_color"))
    assert plain.min() > 0.01
    assert np.allclose(values({"type": "scale", "tex": _tex("vertex_color"), "scale": 0.5}), 0.5 * plain, atol=1e-6)
    mixed = values({"type": "mix", "tex1": _tex("vertex_color"), "tex2": 0.2, "amount": 0.25})
    assert np.allclose(mixed, 0.75 * plain + 0.25 * 0.2, atol=1e-6)


def test_scenes_without_mesh_attributes_do_not_trace_them(monkeypatch):
    calls = []
    monkeypatch.setattr(meshattr, "evaluate", lambda *a: calls.append(1))
    pbr.render(pbr.load_dict(pbr.cornell_box(8, 4)))
    assert not calls


# ------------------------------------------------------------------------- images

@pytest.fixture(scope="module")
def mitsuba_estimate(files, scale):
    return validate.estimate(validate.mitsuba_render_fn(_scene(files)), SPP * scale, BATCHES, seed=22)


def _compare(d, ref, scale):
    scene = pbr.load_dict(d)
    ours = validate.estimate(lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp)),
                             SPP * scale, BATCHES, seed=21)
    return validate.compare(ours.mean, ours.var, ref.mean, ref.var, image_mean_var_a=ours.image_mean_var,
                            image_mean_var_b=ref.image_mean_var)


def test_matches_mitsuba(files, mitsuba_estimate, scale):
    """Back wall: vertex colours (barycentric interpolation); blocks: face colours."""
    res = _compare(_scene(files), mitsuba_estimate, scale)
    print(res.summary())
    assert res.passed, res.summary()


@pytest.mark.parametrize("sabotage", ["vertex_scale", "face_scale", "barycentrics"])
def test_sabotage_is_detected(files, mitsuba_estimate, scale, sabotage, monkeypatch):
    """Must fail: colours scaled by 0.9 (wall or blocks), or barycentric coordinates
    assigned to the wrong corners (same colours, wrong interpolation)."""
    d = _scene(files)
    if sabotage == "vertex_scale":
        d = _scene(files, wall=_attr("vertex_color", 0.9))
    elif sabotage == "face_scale":
        d = _scene(files, small=_attr("face_color", 0.9), large=_mirror("face_color", 0.9))
    else:
        bary = meshattr.barycentric
        monkeypatch.setattr(meshattr, "barycentric", lambda *a: bary(*a)[::-1])
    res = _compare(d, mitsuba_estimate, scale)
    print(sabotage, res.summary())
    assert not res.passed, res.summary()


# ---------------------------------------------------------------------- gradients

def test_traverse_and_gradient(files):
    """``back.vertex_color`` is a parameter; d mean(R) / d (red of every vertex) by PRB
    reverse mode agrees with central finite differences."""
    d = _scene(files)
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 12
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    key = "back.vertex_color"
    assert key in params and "back.bsdf.reflectance.scale" in params
    v0 = np.array(params[key])
    red = np.zeros_like(v0)
    red[0::3] = 1.0
    spp, eps, seeds = 256, 0.02, range(3)
    fd = []
    for s in seeds:
        vals = []
        for sign in (1, -1):
            params[key] = mi.Float(v0 + sign * eps * red)
            params.update()
            vals.append(np.asarray(pbr.render(scene, spp=spp, seed=s))[..., 0].mean())
        fd.append((vals[0] - vals[1]) / (2 * eps))
    rev = []
    for s in seeds:
        params[key] = mi.Float(v0)
        dr.enable_grad(params[key])
        params.update()
        img = pbr.render(scene, params, spp=spp, seed=s, seed_grad=100 + s)
        dr.backward(dr.mean(img[..., 0], axis=None))
        rev.append(float(np.sum(np.array(dr.grad(params[key])) * red)))
    params[key] = mi.Float(v0)
    params.update()
    fd_mean, fd_se = np.mean(fd), np.std(fd) / np.sqrt(len(fd))
    assert fd_mean > 0.01
    assert abs(np.mean(rev) - fd_mean) < 4 * fd_se + 0.05 * fd_mean, (rev, fd)


# -------------------------------------------------------------------------- errors

def test_unknown_attribute_names_the_key(files):
    d = _scene(files, wall=_attr("vertex_foo"))
    with pytest.raises(pbr.SceneError, match=r"scene\.back\.bsdf\.reflectance\.name: shape 'back' has no mesh "
                                             r"attribute 'vertex_foo' \(it has: .*vertex_color"):
        pbr.load_dict(d)


def test_referenced_bsdf_is_checked_on_each_shape(files):
    """A top-level BSDF (referenced by id, also inside a twosided) is checked on every
    shape that uses it: the blocks have face colours but no vertex colours."""
    d = _scene(files)
    d["tinted"] = _attr("vertex_color")
    d["back"]["bsdf"] = {"type": "ref", "id": "tinted"}
    pbr.load_dict(d)
    d["small-box"]["bsdf"] = {"type": "twosided", "b": {"type": "ref", "id": "tinted"}}
    with pytest.raises(pbr.SceneError, match=r"scene\.tinted\.reflectance\.name: shape 'small-box' has no mesh "
                                             r"attribute 'vertex_color'"):
        pbr.load_dict(d)


def test_non_mesh_shape_is_an_error(files):
    d = material_box(_attr("face_color"))
    with pytest.raises(pbr.SceneError, match=r"scene\.small-box\.bsdf\.reflectance: mesh_attribute 'face_color' "
                                             r"is evaluated on shape 'small-box', a 'cube': it needs a mesh"):
        pbr.load_dict(d)


@pytest.mark.parametrize("tex, match", [
    ({"name": "color"}, r"reflectance\.name: a mesh attribute name starts with 'vertex_' or 'face_'"),
    ({"name": "vertex_color", "scael": 1.0}, r"reflectance\.scael: unknown parameter"),
    ({}, r"reflectance\.name: missing required string"),
])
def test_bad_parameters_name_the_key(files, tex, match):
    d = _scene(files, wall={"type": "diffuse", "reflectance": {"type": "mesh_attribute", **tex}})
    with pytest.raises(pbr.SceneError, match=r"scene\.back\.bsdf\." + match):
        pbr.load_dict(d)


def test_emitter_is_refused(files):
    d = _scene(files)
    d["back"]["emitter"] = {"type": "area", "radiance": {"type": "mesh_attribute", "name": "vertex_color"}}
    with pytest.raises(pbr.SceneError, match=r"scene\.back\.emitter\.radiance: mesh_attribute is supported in BSDF"):
        pbr.load_dict(d)


def test_xml(files, tmp_path):
    xml = tmp_path / "s.xml"
    xml.write_text(f"""<scene version="3.0.0">
    <shape type="ply"><string name="filename" value="{files['grid']}"/>
        <bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">
            <string name="name" value="vertex_color"/><float name="scale" value="0.5"/>
        </texture></bsdf>
    </shape>
</scene>""")
    scene = pbr.load_file(str(xml))
    assert len(scene.textures.mesh_data) == 1
