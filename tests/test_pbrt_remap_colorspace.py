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


# -- ColorSpace ------------------------------------------------------------------------------------

CS = """
LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective"
{film}
WorldBegin
{body}
"""

# colour-science's names of pbrt-v4's spaces (pbrt-v4's "dci-p3" is P3-D65: D65 white).
COLOUR_NAMES = {"rec2020": "ITU-R BT.2020", "dci-p3": "Display P3", "aces2065-1": "ACES2065-1"}


def _colour():
    colour = pytest.importorskip("colour")
    return colour


def _colour_matrix(colour, name, cat):
    """colour-science's RGB-to-RGB matrix, both spaces with matrices derived from their
    primaries and whites (colour's sRGB otherwise uses IEC 61966-2-1's rounded matrix)."""
    spaces = []
    for n in (COLOUR_NAMES[name], "sRGB"):
        cs = colour.RGB_COLOURSPACES[n].copy()
        cs.use_derived_transformation_matrices(True)
        spaces.append(cs)
    return colour.matrix_RGB_to_RGB(spaces[0], spaces[1], cat)


def _values(d, typ):
    return [v for v in d.values() if isinstance(v, dict) and v.get("type") == typ]


def _dict(tmp_path, body, film="", name="cs.pbrt", **kw):
    return convert(write(tmp_path, CS.format(body=body, film=film), name), **kw)


@pytest.mark.parametrize("name", sorted(COLOUR_NAMES))
def test_color_space_rgb_becomes_srgb(tmp_path, name):
    """RGB parameters after ``ColorSpace`` are converted to linear sRGB as colour-science
    converts them: reflectances with Bradford's adaptation of the space's white to D65
    (pbrt-v4's RGB (1, 1, 1) is a flat reflectance in every space), light without
    (aces2065-1's (1, 1, 1) stays light of D60's colour); D65 spaces need neither."""
    colour = _colour()
    refl, light = [0.3, 0.5, 0.2], [2.0, 1.0, 0.5]
    fmt = lambda v: "[" + " ".join(map(str, v)) + "]"  # noqa: E731
    d, notes, _ = _dict(tmp_path, f'ColorSpace "{name.upper()}"\nLightSource "point" "rgb I" {fmt(light)}\n'
                                  f'Material "diffuse" "rgb reflectance" {fmt(refl)}\nShape "sphere"')
    got_r = np.asarray(_values(d, "twosided")[0]["bsdf"]["reflectance"]["value"])
    got_l = np.asarray(_values(d, "point")[0]["intensity"]["value"])
    np.testing.assert_allclose(got_r, _colour_matrix(colour, name, "Bradford") @ refl, atol=1e-9)
    np.testing.assert_allclose(got_l, _colour_matrix(colour, name, None) @ light, atol=1e-9)
    assert not any("gamut" in n for n in notes)
    if name == "aces2065-1":   # the adaptation matters here only
        assert np.abs(_colour_matrix(colour, name, None) @ refl - got_r).max() > 0.01


def test_rec2020_red_is_bt2087s(tmp_path):
    """ITU-R BT.2087's matrix (4 decimals) takes Rec. 2020's red to linear Rec. 709/sRGB
    (1.6605, -0.1246, -0.0182): outside sRGB's gamut, so an albedo is clipped to [0, 1] and
    an unbounded value at 0 only, each noted; "srgb" (pbrt-v4's default) leaves values as
    given; ColorSpace is scoped by AttributeBegin/End and ties Attribute defaults to the
    space they were given in, as in pbrt-v4."""
    from pbr.scene.pbrt import color_space_to_srgb
    np.testing.assert_allclose(color_space_to_srgb("rec2020", True) @ [1, 0, 0], [1.6605, -0.1246, -0.0182],
                               atol=1e-4)
    np.testing.assert_allclose(color_space_to_srgb("rec2020", True) @ [0, 0, 1], [-0.0728, -0.0083, 1.1187],
                               atol=1e-4)
    d, notes, _ = _dict(tmp_path, 'ColorSpace "rec2020"\n'
                                  'Material "diffuse" "rgb reflectance" [1 0 0]\nShape "sphere"\n'
                                  'Material "conductor" "rgb eta" [1 0 0] "rgb k" [1 1 1]\nShape "sphere"')
    mats = [m["bsdf"] for m in _values(d, "twosided")]
    np.testing.assert_allclose(mats[0]["reflectance"]["value"], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(mats[1]["eta"]["value"], [1.6605, 0.0, 0.0], atol=1e-4)
    np.testing.assert_allclose(mats[1]["k"]["value"], [1.0, 1.0, 1.0], atol=1e-12)
    assert sum("outside sRGB's gamut" in n for n in notes) == 2
    body = ('Attribute "material" "rgb reflectance" [0.6 0.3 0.2]\n'
            'AttributeBegin\nColorSpace "rec2020"\nMaterial "diffuse"\nShape "sphere"\n'
            'Material "diffuse" "rgb reflectance" [0.2 0.4 0.6]\nShape "sphere"\nAttributeEnd\n'
            'Material "diffuse" "rgb reflectance" [0.2 0.4 0.6]\nShape "sphere"')
    d, notes, _ = _dict(tmp_path, body, name="scoped.pbrt")
    vals = [np.asarray(m["bsdf"]["reflectance"]["value"]) for m in _values(d, "twosided")]
    np.testing.assert_allclose(vals[0], [0.6, 0.3, 0.2])      # given in sRGB, used in rec2020's scope
    np.testing.assert_allclose(vals[1], color_space_to_srgb("rec2020", True) @ [0.2, 0.4, 0.6])
    np.testing.assert_allclose(vals[2], [0.2, 0.4, 0.6])       # the scope ended


def test_color_space_directive_errors_and_film(tmp_path):
    with pytest.raises(XMLError, match=r"cs.pbrt:\d+: ColorSpace: unknown color space 'adobergb'"):
        _dict(tmp_path, 'ColorSpace "adobergb"\nShape "sphere"')
    _, notes, _ = _dict(tmp_path, 'Shape "sphere"', film='ColorSpace "aces2065-1"\nFilm "rgb"', name="film.pbrt")
    assert any("pbr's films write linear sRGB" in n for n in notes)


def test_rgbgrid_in_a_color_space(tmp_path):
    """An rgbgrid's sigma_a/sigma_s (unbounded) and Le (illuminant) grids are converted per voxel."""
    from pbr.scene.pbrt import color_space_to_srgb
    body = ('ColorSpace "aces2065-1"\nMakeNamedMedium "m" "string type" "rgbgrid" "integer nx" 2 "integer ny" 1 '
            '"integer nz" 1 "rgb sigma_a" [1 1 1  0.5 0.2 0.1] "rgb Le" [1 1 1  0 0 0]\n'
            'MediumInterface "m" ""\nMaterial "interface"\nShape "sphere"')
    d, _, _ = _dict(tmp_path, body)
    m = _values(d, "rgbgrid")[0]
    ref = [[1, 1, 1], color_space_to_srgb("aces2065-1", True) @ [0.5, 0.2, 0.1]]
    np.testing.assert_allclose(m["sigma_a"][0, 0], ref, atol=1e-6)
    np.testing.assert_allclose(m["Le"][0, 0, 0], color_space_to_srgb("aces2065-1", False) @ [1, 1, 1], atol=1e-6)


def test_aces_reflectance_seen_under_d60_keeps_its_rgb():
    """Why reflectances are adapted: pbrt-v4 upsamples an aces2065-1 albedo to a spectrum
    whose colour under ACES's D60 illuminant is that RGB. The converted sRGB value,
    upsampled by Mitsuba's sRGB model (pbr's), seen under a CIE D-series illuminant of
    ACES's white (colour-science) with the CIE 1931 observer, gives the ACES RGB back
    within 0.01 for colours inside sRGB's gamut; without adaptation white is off by > 0.05."""
    colour = _colour()
    import mitsuba as mi
    from pbr import backend
    from pbr.scene.pbrt import color_space_to_srgb
    aces = colour.RGB_COLOURSPACES["ACES2065-1"]
    shape = colour.SpectralShape(360, 830, 5)
    lam = np.arange(360, 831, 5.0)
    d60 = colour.sd_CIE_illuminant_D_series(aces.whitepoint).copy().align(shape).values
    cmf = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape).values

    def seen(srgb):
        with backend.pbr_variant():
            c = np.array(mi.srgb_model_fetch(mi.ScalarColor3f(*srgb)), np.float64)
        x = (c[0] * lam + c[1]) * lam + c[2]
        s = 0.5 + x / (2 * np.sqrt(1 + x * x))
        xyz = (s[:, None] * d60[:, None] * cmf).sum(0) / (d60 * cmf[:, 1]).sum()
        return np.linalg.solve(aces.matrix_RGB_to_XYZ, xyz)

    cols = np.concatenate([[[1, 1, 1], [0.5, 0.5, 0.5]], np.random.default_rng(2).uniform(0.15, 0.8, (20, 3))])
    M = color_space_to_srgb("aces2065-1", True)
    inside = [c for c in cols if ((M @ c >= 0) & (M @ c <= 1)).all()]
    assert len(inside) >= 12
    err = max(np.abs(seen(M @ c) - c).max() for c in inside)
    assert err < 0.01, err
    raw = color_space_to_srgb("aces2065-1", False) @ [1, 1, 1]
    assert np.abs(seen(np.clip(raw, 0, 1)) - 1).max() > 0.05
