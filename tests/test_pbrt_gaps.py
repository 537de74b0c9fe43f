"""pbrt-v4 features the reader maps to pbr plugins added for them: the infinite light's
``portal``, named camera sensors, the ``cloud`` medium, two-sided and image area lights.
Each is checked against an independent value (NumPy or a closed form)."""
import math

import numpy as np
import pytest

import pbr
from pbr.scene.pbrt import convert, to_dict
from pbr.scene.xml import XMLError


def write(tmp_path, text, name="scene.pbrt"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def render(path, **kw):
    return np.asarray(pbr.render(pbr.load_file(path, **kw), seed=1), dtype=np.float64)


# -- infinite light with a portal ------------------------------------------------------------

PORTAL = """
LookAt 0 0 0  1 0 0  0 0 1
Camera "perspective" "float fov" 90
Film "rgb" "integer xresolution" 40 "integer yresolution" 40
Sampler "independent" "integer pixelsamples" 32
Integrator "path" "integer maxdepth" 1
WorldBegin
Translate 0 0 3
Rotate 30 0 0 1
LightSource "infinite" {L}
    "point3 portal" [5 -1 -1  5 -1 1  5 1 1  5 1 -1]
Translate -20 0 0
Shape "sphere" "float radius" 0.1
"""


def _planck(lam_nm, t):
    lam = lam_nm * 1e-9
    c, h, k = 299792458.0, 6.62606957e-34, 1.3806488e-23
    return 2 * h * c * c / lam ** 5 / np.expm1(h * c / (lam * k * t))


def test_portal_light_window_and_radiance(tmp_path):
    """The portal's points are in world space (pbrt-v4 ignores the CTM for them) and light
    comes through toward the side cross(p3 - p0, p1 - p0) faces away from: a camera at the
    origin looking at the 2x2 portal at x = 5 (fov 90) sees the radiance in the central
    fifth of the image and black around it; an RGB L keeps its value times scale."""
    path = write(tmp_path, PORTAL.format(L='"rgb L" [0.3 0.5 0.7] "float scale" 2'))
    d = to_dict(path)
    light = [v for v in d.values() if isinstance(v, dict) and v.get("type") == "portalenvmap"]
    assert len(light) == 1 and light[0]["portal"][0] == [5.0, -1.0, -1.0]
    img = render(path)
    n = img.shape[0]
    inside = img[n // 2 - 3:n // 2 + 3, n // 2 - 3:n // 2 + 3].reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(inside, [0.6, 1.0, 1.4], rtol=0.03)
    outside = np.concatenate([img[:n // 2 - 5].ravel(), img[n // 2 + 5:].ravel(),
                              img[:, :n // 2 - 5].ravel(), img[:, n // 2 + 5:].ravel()])
    assert outside.max() == 0.0
    # pbrt-v4 converts L to sRGB for a portal light without normalising its luminance: a
    # blackbody (peak 1) keeps its own luminance (NumPy: Planck's law against CIE ybar).
    from pbr.spectrum import CIE_Y_INTEGRAL, cie_tables_np
    xyz, _ = cie_tables_np()
    lam = 360.0 + 5.0 * np.arange(len(xyz))
    b = _planck(lam, 6500.0) / _planck(np.array([2.8977721e6 / 6500.0]), 6500.0)
    Y = np.trapezoid(b * xyz[:, 1], lam) / CIE_Y_INTEGRAL
    d = to_dict(write(tmp_path, PORTAL.format(L='"blackbody L" 6500 "float scale" 7.5'), "bb.pbrt"))
    light = [v for v in d.values() if isinstance(v, dict) and v.get("type") == "portalenvmap"][0]
    rgb = np.asarray(light["data"])[0, 0]
    assert light["scale"] == 7.5
    assert rgb @ [0.2126, 0.7152, 0.0722] == pytest.approx(Y, rel=2e-3)
    assert rgb.max() / rgb.min() < 1.1     # 6500 K is nearly sRGB's white


def test_portal_light_errors_and_mitsuba(tmp_path):
    bad = write(tmp_path, PORTAL.format(L='"rgb L" [1 1 1]').replace("5 1 1  5 1 -1]", "5 1 1]"), "bad.pbrt")
    with pytest.raises(XMLError, match=r"bad.pbrt:11: LightSource: parameter 'portal': expected 4 points"):
        to_dict(bad)
    path = write(tmp_path, PORTAL.format(L='"rgb L" [1 1 1]'))
    with pytest.raises(XMLError, match="portal.*not supported"):
        to_dict(path, mitsuba=True)
    d, notes, _ = convert(path, mitsuba=True, approximate=True)
    assert any(v.get("type") == "envmap" for v in d.values() if isinstance(v, dict))
