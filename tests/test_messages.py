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
