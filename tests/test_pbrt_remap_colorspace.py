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
from test_pbrt import write


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


# -- plymesh displacement -------------------------------------------------------------------------

def _pbrt_refine(pos, tri, m, max_dist):
    """pbrt-v4's TriQuadMesh::Refine transcribed as written: recursive longest-edge
    bisection with a shared edge -> midpoint map; returns the final triangles as
    sorted tuples of their vertex positions."""
    pos = [np.asarray(p, float) for p in pos]
    split, out = {}, []

    def dist(a, b):
        return np.linalg.norm((pos[a] - pos[b]) @ m[:3, :3].T)

    def refine(v0, v1, v2):
        d01, d12, d20 = dist(v0, v1), dist(v1, v2), dist(v2, v0)
        if d01 < max_dist and d12 < max_dist and d20 < max_dist:
            out.append(tuple(sorted(tuple(np.round(pos[v], 9)) for v in (v0, v1, v2))))
            return
        if d01 > d12:
            v = (v0, v1, v2) if d01 > d20 else (v2, v0, v1)
        else:
            v = (v1, v2, v0) if d12 > d20 else (v2, v0, v1)
        e = tuple(sorted(v[:2]))
        if e not in split:
            split[e] = len(pos)
            pos.append((pos[v[0]] + pos[v[1]]) / 2)
        refine(v[0], split[e], v[2])
        refine(split[e], v[1], v[2])

    for t in tri:
        refine(*t)
    return sorted(out)


def test_refine_mesh_is_pbrts_recursion():
    """The vectorised tessellation gives the triangles of pbrt-v4's recursion (render-space
    edge lengths under a non-uniform scale)."""
    from pbr.scene.pbrt import refine_mesh
    rng = np.random.default_rng(7)
    pos = np.concatenate([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], rng.random((4, 3)) + [2, 0, 0]])
    tri = np.array([[0, 1, 3], [0, 3, 2], [4, 5, 6], [5, 7, 6]])
    m = np.diag([2.0, 1.0, 0.5, 1.0])
    p2, t2, _, _ = refine_mesh(pos, tri, np.tile([0.0, 0.0, 1.0], (8, 1)), np.zeros((8, 2)), m, 0.3)
    got = sorted(tuple(sorted(tuple(np.round(p2[v], 9)) for v in t)) for t in t2)
    assert len(got) > 40
    assert got == _pbrt_refine(pos, tri, m, 0.3)


def test_plymesh_displacement(tmp_path):
    """A unit square (2 triangles, uv = xy) under Scale 2 1 1, displaced by a bilerp
    texture (0.1 u + 0.2 v) with edgelength 0.3: every world-space edge is shorter than
    0.3, the mesh has no cracks (each interior edge is shared by two triangles, the others
    lie on the square's border), every vertex is moved along +z by the texture's value at
    its uv, and the normals are those of the displaced plane."""
    from pbr.scene.pbrt import _read_ply, write_ply
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    write_ply(str(tmp_path / "sq.ply"), P, np.array([[0, 1, 3], [0, 3, 2]]), uv=P[:, :2].copy())
    body = ('Texture "h" "float" "bilerp" "float v00" 0 "float v10" 0.1 "float v01" 0.2 "float v11" 0.3\n'
            'Scale 2 1 1\nShape "plymesh" "string filename" "sq.ply" "texture displacement" "h" '
            '"float edgelength" 0.3')
    d, notes, _ = _dict(tmp_path, body, mesh_dir=str(tmp_path))
    assert notes == []
    pos, f, n, uv = _read_ply(_values(d, "ply")[0]["filename"], "x")
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    assert np.linalg.norm(pos[e[:, 0]] - pos[e[:, 1]], axis=1).max() < 0.3
    assert len(f) > 50
    keys, counts = np.unique(np.sort(e, axis=1), axis=0, return_counts=True)
    border = keys[counts == 1]
    x, y = pos[border][..., 0], pos[border][..., 1]
    on_border = ((np.abs(x[:, 0] - x[:, 1]) < 1e-6) & np.isin(np.round(x[:, 0], 6), [0, 2])) | (
        (np.abs(y[:, 0] - y[:, 1]) < 1e-6) & np.isin(np.round(y[:, 0], 6), [0, 1]))
    assert counts.max() == 2 and on_border.all()
    np.testing.assert_allclose(pos[:, 2], 0.1 * uv[:, 0] + 0.2 * uv[:, 1], atol=1e-6)
    np.testing.assert_allclose(pos[:, 0], 2 * uv[:, 0], atol=1e-6)
    ref = np.array([-0.05, -0.2, 1.0]) / np.linalg.norm([-0.05, -0.2, 1.0])
    np.testing.assert_allclose(n, np.tile(ref, (len(n), 1)), atol=1e-5)
    # pbrt-v4's Option "displacementedgescale" multiplies edgelength.
    d, notes, _ = _dict(tmp_path, body, film='Option "float displacementedgescale" 0.5', name="opt.pbrt",
                        mesh_dir=str(tmp_path))
    pos2, f2, _, _ = _read_ply(_values(d, "ply")[0]["filename"], "x")
    e2 = np.concatenate([f2[:, [0, 1]], f2[:, [1, 2]], f2[:, [2, 0]]])
    assert np.linalg.norm(pos2[e2[:, 0]] - pos2[e2[:, 1]], axis=1).max() < 0.15 and len(f2) > 3 * len(f)
    assert not any("displacementedgescale" in n for n in notes)
    # A constant displacement moves every vertex along its normal; no uvs: an error.
    d, _, _ = _dict(tmp_path, body.replace('"texture displacement" "h"', '"float displacement" 0.25'),
                    name="const.pbrt", mesh_dir=str(tmp_path))
    pos, _, _, _ = _read_ply(_values(d, "ply")[0]["filename"], "x")
    np.testing.assert_allclose(pos[:, 2], 0.25, atol=1e-6)
    write_ply(str(tmp_path / "nouv.ply"), P, np.array([[0, 1, 3], [0, 3, 2]]))
    with pytest.raises(XMLError, match="displacement needs vertex uvs"):
        _dict(tmp_path, body.replace("sq.ply", "nouv.ply"), name="nouv.pbrt", mesh_dir=str(tmp_path))


@pytest.mark.parametrize("mitsuba", [False, True])
def test_plymesh_displacement_by_an_image(tmp_path, mitsuba):
    """A displacement texture of textures (a `scale` of an `imagemap` of 0.4, by -0.5)
    is evaluated by pbr's texture set, also in a dict for Mitsuba 3 (its bitmap)."""
    from pbr.image import write_image
    from pbr.scene.pbrt import _read_ply, write_ply
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    write_ply(str(tmp_path / "sq.ply"), P, np.array([[0, 1, 3], [0, 3, 2]]), uv=P[:, :2].copy())
    write_image(str(tmp_path / "h.exr"), np.full((4, 4, 3), 0.4, np.float32))
    body = ('Texture "i" "float" "imagemap" "string filename" "h.exr"\n'
            'Texture "h" "float" "scale" "texture tex" "i" "float scale" -0.5\n'
            'Shape "plymesh" "string filename" "sq.ply" "texture displacement" "h" "float edgelength" 0.5')
    d, _, _ = _dict(tmp_path, body, mesh_dir=str(tmp_path), mitsuba=mitsuba, approximate=True)
    pos, f, _, _ = _read_ply(_values(d, "ply")[0]["filename"], "x")
    assert len(f) > 2
    np.testing.assert_allclose(pos[:, 2], -0.2, atol=1e-6)
