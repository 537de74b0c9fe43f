"""pbrt-v4's ``remaproughness`` of roughness textures (pbr's ``sqrt`` texture) and its
``ColorSpace`` directive (RGB parameters of rec2020, dci-p3 and aces2065-1 scenes
converted to linear sRGB), each against an independent value."""
import numpy as np
import pytest

import pbr
from pbr.plugins.props import SceneError
from pbr.scene.pbrt import convert, to_dict
from pbr.scene.xml import XMLError
from test_textures_pbrt import _plane_scene, _texture_values


def write(tmp_path, text, name="scene.pbrt"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


# -- remaproughness of roughness textures -------------------------------------------------------

ROUGH = """
LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" 30
Film "rgb" "integer xresolution" 20 "integer yresolution" 20
Sampler "independent" "integer pixelsamples" 8
Integrator "path" "integer maxdepth" 2
WorldBegin
LightSource "distant" "point3 from" [1 1 3] "point3 to" [0 0 0] "rgb L" [3 3 3]
Texture "r" "float" "checkerboard" "float tex1" 0.09 "float tex2" 0.09
Material "{typ}" {rough} {extra}
Shape "sphere" "float radius" 1
"""


def _rough_image(tmp_path, typ, rough, extra=""):
    path = write(tmp_path, ROUGH.format(typ=typ, rough=rough, extra=extra), f"{typ}{abs(hash(rough + extra))}.pbrt")
    return np.asarray(pbr.render(pbr.load_file(path), seed=1), dtype=np.float64)


@pytest.mark.parametrize("typ", ["conductor", "dielectric", "coateddiffuse", "coatedconductor"])
def test_textured_roughness_is_remapped_as_the_constant(tmp_path, typ):
    """pbrt-v4 remaps a roughness texture's value (alpha = sqrt(roughness)) as it remaps a
    constant: a texture of value 0.09 renders the image of "float roughness" 0.09 (alpha
    0.3), not that of the texture unremapped (alpha 0.09)."""
    rough = "interface.roughness" if typ == "coatedconductor" else "roughness"
    tex = _rough_image(tmp_path, typ, f'"texture {rough}" "r"')
    const = _rough_image(tmp_path, typ, f'"float {rough}" 0.09')
    plain = _rough_image(tmp_path, typ, f'"texture {rough}" "r"', '"bool remaproughness" false')
    assert const.max() > 0.05
    np.testing.assert_allclose(tex, const, rtol=1e-4, atol=1e-5)
    assert np.abs(plain - const).max() > 0.05 * const.max()


def test_roughness_texture_dicts(tmp_path):
    """The reader wraps a remapped roughness texture in ``sqrt`` (one dict for both axes);
    Mitsuba 3 has no such texture: refused, or noted and used unremapped."""
    path = write(tmp_path, ROUGH.format(typ="conductor", rough='"texture roughness" "r"', extra=""))
    mats = [v["bsdf"] for v in to_dict(path).values() if isinstance(v, dict) and v.get("type") == "twosided"]
    assert mats[0]["alpha"] == {"type": "sqrt", "tex": {"type": "checkerboard", "tex1": 0.09, "tex2": 0.09,
                                                        "dimension": 2}}
    aniso = write(tmp_path, ROUGH.format(typ="dielectric", rough='"texture uroughness" "r" "float vroughness" 0.25',
                                         extra=""), "aniso.pbrt")
    m = [v for v in to_dict(aniso).values() if isinstance(v, dict) and v.get("type") == "roughdielectric"][0]
    assert m["alpha_u"]["type"] == "sqrt" and m["alpha_v"] == 0.5
    with pytest.raises(XMLError, match="remaproughness in a dict for Mitsuba 3"):
        to_dict(path, mitsuba=True)
    d, notes, _ = convert(path, mitsuba=True, approximate=True)
    mats = [v["bsdf"] for v in d.values() if isinstance(v, dict) and v.get("type") == "twosided"]
    assert mats[0]["alpha"]["type"] == "checkerboard"
    assert any("not remapped" in n for n in notes)


def test_sqrt_texture_values():
    """``sqrt`` of a spatially varying texture: sqrt(max(tex, 0)) at every lookup, nested
    in and around combinators (bilerp is t itself: extrapolated below 0 for v < 0)."""
    uv = np.random.default_rng(5).random((2, 400)) * [[1.0], [1.4]] - [[0.0], [0.2]]
    t = uv[1]
    got = _texture_values({"type": "sqrt", "tex": {"type": "bilerp"}}, uv)
    np.testing.assert_allclose(got, np.sqrt(np.maximum(t, 0.0)), atol=2e-6)
    mix = {"type": "mix", "tex1": 0.04, "tex2": {"type": "sqrt", "tex": {"type": "bilerp"}}, "amount": 0.25}
    got = _texture_values({"type": "sqrt", "tex": mix}, uv)
    np.testing.assert_allclose(got, np.sqrt(0.75 * 0.04 + 0.25 * np.sqrt(np.maximum(t, 0.0))), atol=2e-6)
    with pytest.raises(SceneError, match="reflectance.tex: sqrt needs a texture"):
        pbr.load_dict(_plane_scene({"type": "sqrt"}))
