"""Loader messages a newcomer meets first (issue 16 item 4, issue 18 item 4): misspelt
names get the nearest known one suggested, XML errors carry file:line and the element's
id, and an XML element whose type belongs to another tag is refused (Mitsuba refuses
<sensor type="rectangle">; pbr used to load it as a shape)."""

import re

import pytest

import pbr
from pbr.scene.xml import XMLError, parse_string


def _mutated(change):
    d = pbr.cornell_box(8, 1)
    change(d)
    return d


@pytest.mark.parametrize("change, message", [
    (lambda d: d["red"]["reflectance"].__setitem__("valeu", 0.5),
     "scene.red.reflectance.valeu: unknown parameter 'valeu' for plugin type 'rgb' (did you mean 'value'?)"),
    (lambda d: d["red"].__setitem__("type", "difuse"), "scene.red: unknown plugin type 'difuse' (did you mean 'diffuse'?)"),
    (lambda d: d["light"]["emitter"].__setitem__("type", "aera"),
     "scene.light.emitter: unknown plugin type 'aera' (did you mean 'area'?)"),
    (lambda d: d["floor"].__setitem__("type", "rectangel"),
     "scene.floor: unknown plugin type 'rectangel' (did you mean 'rectangle'?)"),
    (lambda d: d["red"]["reflectance"].__setitem__("type", "bitmapp"),
     "scene.red.reflectance: unsupported texture/spectrum type 'bitmapp' (did you mean 'bitmap'?)"),
    (lambda d: d["integrator"].__setitem__("type", "pth"), "scene.integrator: unknown plugin type 'pth' (did you mean 'path'?)"),
    (lambda d: d["sensor"]["film"]["rfilter"].__setitem__("type", "gausian"),
     "scene.sensor.film.rfilter: unsupported reconstruction filter 'gausian' (did you mean 'gaussian'?)"),
    (lambda d: d["red"].__setitem__("type", "zzz"), "scene.red: unknown plugin type 'zzz'$"),   # nothing close
])
def test_misspelt_names_get_a_suggestion(change, message):
    with pytest.raises(pbr.SceneError, match="^" + re.escape(message).replace(r"\$", "$")):
        pbr.load_dict(_mutated(change))


def test_choices_get_a_suggestion():
    xml = ('<scene version="3.0.0"><shape type="sphere"><bsdf type="roughconductor">'
           '<string name="distribution" value="gxx"/></bsdf></shape></scene>')
    with pytest.raises(pbr.SceneError, match=r"expected one of 'beckmann', 'ggx', got 'gxx' \(did you mean 'ggx'\?\)"):
        pbr.load_dict(parse_string(xml))


def test_xml_errors_name_file_line_and_id(tmp_path):
    f = tmp_path / "s.xml"
    f.write_text('<scene version="3.0.0">\n<shape type="sphere" id="ball">\n<bsdf type="roughconductor" id="metal">\n'
                 '<float name="alpah" value="0.1"/>\n</bsdf>\n</shape>\n</scene>\n')
    with pytest.raises(pbr.SceneError, match=re.escape(f"{f}:4: scene.ball.metal.alpah: unknown parameter 'alpah'")
                       + r".*did you mean 'alpha'"):
        pbr.load_file(str(f))


@pytest.mark.parametrize("body, tag, t, owner", [
    ('<sensor type="rectangle"/>', "sensor", "rectangle", "shape"),
    ('<sampler type="sphere"/>', "sampler", "sphere", "shape"),
    ('<bsdf type="sphere"/>', "bsdf", "sphere", "shape"),
    ('<shape type="diffuse"/>', "shape", "diffuse", "bsdf"),
    ('<shape type="sphere">\n<bsdf type="area"/></shape>', "bsdf", "area", "emitter"),
])
def test_a_type_under_the_wrong_tag_is_refused(body, tag, t, owner):
    with pytest.raises(XMLError, match=rf"^<string>:\d+: <{tag}>: type '{t}' is an? {owner} type, not an? {tag} "
                                       rf"type \(write <{owner} type=\"{t}\">\)"):
        parse_string('<scene version="3.0.0">' + body + "</scene>")


def test_unknown_types_under_a_tag_are_left_to_the_loader():
    d = parse_string('<scene version="3.0.0"><sensor type="irradiancemeterr"/></scene>')   # no family knows it
    with pytest.raises(pbr.SceneError, match="unknown plugin type 'irradiancemeterr'"):
        pbr.load_dict(d)


def test_non_finite_transform_names_the_problem():
    xml = ('<scene version="3.0.0"><shape type="sphere" id="s"><transform name="to_world">'
           '<rotate x="1" angle="nan"/></transform></shape></scene>')
    with pytest.raises(pbr.SceneError, match=r"scene\.s\.to_world: the transform has non-finite entries \(\d+ of 16"):
        pbr.load_dict(parse_string(xml))


def test_non_finite_matrix_entries_are_refused_where_written():
    """A <matrix> entry that is NaN: composing transforms keeps only the affine rows, so a
    NaN in the last row was dropped and the scene loaded as if it were 1."""
    xml = ('<scene version="3.0.0"><shape type="sphere" id="s"><transform name="to_world">\n'
           '<matrix value="1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 nan"/></transform></shape></scene>')
    with pytest.raises(XMLError, match=r'<string>:2: <matrix>: attribute "value": expected finite numbers'):
        parse_string(xml)


# -- bad input found by the audit of issue-18's rule (wrong kinds of values, cycles, files) --

@pytest.mark.parametrize("change, message", [
    (lambda d: d["floor"].__setitem__("bsdf", 5),
     r"scene\.floor\.bsdf: expected a plugin dict with a 'type' \(or a reference .*\), got int 5"),
    (lambda d: d["floor"].__setitem__("interior", "fog"),
     r"scene\.floor\.interior: expected a plugin dict with a 'type' .*got str 'fog'"),
    (lambda d: d["sensor"].__setitem__("fov", "39"), r"scene\.sensor\.fov: expected a number, got '39'"),
    (lambda d: d["integrator"].__setitem__("max_depth", True), r"scene\.integrator\.max_depth: expected an integer, got True"),
    (lambda d: d["red"]["reflectance"].__setitem__("value", "0.5"),
     r"scene\.red\.reflectance\.value: expected 3 finite numbers, got '0\.5'"),
    (lambda d: d.__setitem__("alias", {"type": "ref", "id": "white"}),
     r"scene\.alias: a reference \('type': 'ref'\) belongs inside the plugin that uses"),
    (lambda d: d["red"].__setitem__("reflectance", {"type": "spectrum", "value": [(-400, 0.5), (600, 0.5)]}),
     r"scene\.red\.reflectance\.value: wavelengths must be .* in nm \(> 0\), got -400, 600"),
])
def test_values_of_the_wrong_kind_are_named(change, message):
    """Mitsuba refuses these ("has the wrong type"); pbr raised AttributeError from the
    loader for a non-dict BSDF, read "39" and True as numbers and the string "0.5" as a
    grey, and took negative wavelengths."""
    with pytest.raises(pbr.SceneError, match="^" + message):
        pbr.load_dict(_mutated(change))


@pytest.mark.parametrize("entries, message", [
    ({"b": {"type": "twosided", "bsdf": {"type": "ref", "id": "b"}}},
     r"^scene\.b\.bsdf: reference cycle: it leads back to scene\.b,"),
    ({"t": {"type": "scale", "scale": 0.5, "tex": {"type": "ref", "id": "u"}},
      "u": {"type": "checkerboard", "color1": {"type": "ref", "id": "t"}}},
     r"^scene\.s\.bsdf\.reflectance\.tex\.color1: reference cycle: it leads back to scene\.s\.bsdf\.reflectance,"),
])
def test_reference_cycles_are_refused(entries, message):
    """A BSDF or texture that refers (through others) to itself recursed until Python's
    RecursionError."""
    bsdf = {"type": "ref", "id": "b"} if "b" in entries else {"type": "diffuse", "reflectance": {"type": "ref", "id": "t"}}
    with pytest.raises(pbr.SceneError, match=message):
        pbr.load_dict({"type": "scene", "s": {"type": "sphere", "bsdf": bsdf}, **entries})


def test_spectrum_files_that_are_not_tables_are_named(tmp_path):
    """A spectrum file that is not a table of numbers raised ValueError without a key path;
    a specfilm's response file was opened relative to the working directory, not the
    scene's, and a missing one raised a bare FileNotFoundError."""
    (tmp_path / "bad.spd").write_text("400 0.5\nnot numbers\n")
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><shape type="sphere"><bsdf type="diffuse">\n'
        '<spectrum name="reflectance" filename="bad.spd"/></bsdf></shape></scene>')
    with pytest.raises(pbr.SceneError, match=re.escape(f"{tmp_path / 's.xml'}:2: scene.shape_0.bsdf_0.reflectance.filename: "
                                                       "not a spectrum file") + ".*bad.spd:2: expected numbers"):
        pbr.load_file(str(tmp_path / "s.xml"))
    d = {"type": "scene", "s": {"type": "sphere"}, "c": {"type": "perspective", "film": {
        "type": "specfilm", "width": 4, "height": 4, "band": {"type": "spectrum", "filename": "nope.spd"}}}}
    with pytest.raises(pbr.SceneError, match=r"^scene\.c\.film\.band\.filename: file not found: 'nope\.spd'"):
        pbr.load_dict(d, base_dir=str(tmp_path))


def test_thinlens_focus_distance_must_be_positive():
    """focus_distance 0 sent every ray along the lens plane: the image showed no geometry."""
    d = pbr.cornell_box(8, 1)
    d["sensor"].update(type="thinlens", aperture_radius=0.1, focus_distance=0.0)
    with pytest.raises(pbr.SceneError, match=r"^scene\.sensor\.focus_distance: must be positive, got 0"):
        pbr.load_dict(d)


def test_render_names_a_scene_that_is_not_loaded():
    with pytest.raises(TypeError, match=r"render: scene: expected a pbr scene .*got a scene dict: pass pbr\.load_dict"):
        pbr.render(pbr.cornell_box(8, 1))


def test_render_names_params_that_are_not_parameters():
    """``params=5`` was ignored without a word when no parameter had gradients."""
    with pytest.raises(TypeError, match=r"^render: params: expected the scene's parameters .*got int 5$"):
        pbr.render(pbr.load_dict(pbr.cornell_box(8, 1)), params=5)


@pytest.mark.parametrize("body, message", [
    ('WorldBegin\nShapee "sphere" "float radius" 1\n', r":2: unknown directive 'Shapee' \(did you mean 'Shape'\?\)$"),
    ('Shape "sphere"\nWorldBegin\n', r":1: Shape: must come after WorldBegin"),
    ('WorldBegin\nRotate a 0 0 1\nShape "sphere"\n', r":2: Rotate: expected 4 numbers, got \[\]$"),
    ('Integrator "volpath" "integer maxdepth" -1\nWorldBegin\nShape "sphere"\n',
     r":1: Integrator: parameter 'maxdepth': expected an integer >= 0, got -1"),
])
def test_pbrt_syntax_errors_name_the_directive(tmp_path, body, message):
    """A misspelt directive was read with its arguments as a parameter list ("expected a
    parameter declaration"); a shape before WorldBegin was rendered (pbrt-v4 refuses it);
    maxdepth -1 became Mitsuba's max_depth 0 (a black image) and -5 an error about -4."""
    f = tmp_path / "s.pbrt"
    f.write_text(body)
    with pytest.raises(XMLError, match="^" + re.escape(str(f)) + message):
        pbr.load_file(str(f))


@pytest.mark.parametrize("change, message", [
    (lambda d: d["sensor"].__setitem__("film", "hdrfilm"),
     r"scene\.sensor\.film: unknown parameter 'film' for plugin type 'perspective' \(a nested plugin is a dict with a "
     r"'type', got str 'hdrfilm'\)"),
    (lambda d: d["floor"].__setitem__("interior", {"type": "homogeneous", "phase": {"type": "ref", "id": "white"}}),
     r"scene\.floor\.interior\.phase: unknown parameter 'phase' for plugin type 'homogeneous', or a nested 'ref' "
     r"\(to a 'diffuse'\) plugin that it does not take"),
])
def test_nested_plugins_of_the_wrong_kind_say_so(change, message):
    """A film given as a string, or a BSDF given as a medium's phase function, was
    reported only as an unknown parameter, which 'film' and 'phase' are not."""
    with pytest.raises(pbr.SceneError, match="^" + message + "$"):
        pbr.load_dict(_mutated(change))
