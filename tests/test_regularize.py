"""pbrt-v4's BSDF regularisation (``regularize`` of ``path`` and ``volpath``): after a
path's first non-specular bounce, microfacet alpha below 0.3 becomes
clamp(2 alpha, 0.1, 0.3) and smooth conductors and dielectrics become rough ones of alpha
0.1. Checked on a caustic (a point light reflected by a mirror onto a diffuse floor seen
from above): against the same scene with the rough BSDF regularisation yields, against
the analytic irradiance of the light and its mirror image, and unchanged images where
nothing is regularised."""

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr.scene.pbrt import convert
from pbr.scene.xml import XMLError

LIGHT, IMAGE = np.array([0.5, 0.0, 1.0]), np.array([1.5, 0.0, 1.0])   # the light, its mirror image


def caustic(integrator, mirror=None, res=32, spp=64):
    """A floor (z = 0, albedo 0.5) seen from above by an orthographic camera, a point light
    at LIGHT and a one-sided mirror in the plane x = 1 facing it. With max_depth 3 only
    the light and its reflection reach the floor: the reflection only through light
    sampling at the mirror, i.e. only when the mirror is (regularised to) rough."""
    T = mi.ScalarTransform4f
    return {"type": "scene", "integrator": integrator,
            "cam": {"type": "orthographic", "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": spp}},
            "floor": {"type": "rectangle", "to_world": T().scale(3), "bsdf": {"type": "diffuse", "reflectance": 0.5}},
            "mirror": {"type": "rectangle", "to_world": T().translate([1, 0, 1]).rotate([0, 1, 0], -90),
                       "bsdf": mirror or {"type": "conductor"}},
            "light": {"type": "point", "position": LIGHT.tolist(), "intensity": 1.0}}


def render(integrator, mirror=None, **kw):
    return np.asarray(pbr.render(pbr.load_dict(caustic(integrator, mirror, **kw)), seed=1), np.float64)


def irradiance(src, p):
    d = src - p
    r2 = (d * d).sum(-1)
    return d[..., 2] / np.sqrt(r2) / r2


@pytest.mark.parametrize("integrator", ["path", "volpath"])
def test_regularised_bsdfs_are_the_rough_ones(integrator):
    """Seen after the floor (a diffuse bounce), a regularised smooth mirror renders what a
    GGX mirror of alpha 0.1 renders (same random numbers: equal to 1e-6), a smooth
    dielectric what a GGX one of alpha 0.1 does, a rough one of alpha 0.2 what one of
    0.3 does; alpha 0.4 (Beckmann) is left as it is."""
    on = {"type": integrator, "max_depth": 3, "regularize": True}
    off = {"type": integrator, "max_depth": 3}
    ggx = lambda t, a, **kw: {"type": t, "distribution": "ggx", "alpha": a, **kw}  # noqa: E731
    for reg, ref, exact in [({"type": "conductor"}, ggx("roughconductor", 0.1), False),
                            ({"type": "dielectric", "int_ior": 1.5}, ggx("roughdielectric", 0.1, int_ior=1.5), False),
                            (ggx("roughconductor", 0.2), ggx("roughconductor", 0.3), True),
                            (ggx("roughdielectric", 0.01, int_ior=1.5), ggx("roughdielectric", 0.1, int_ior=1.5), True),
                            ({**ggx("roughconductor", 0.4), "distribution": "beckmann"},
                             {**ggx("roughconductor", 0.4), "distribution": "beckmann"}, True)]:
        a, b = render(on, reg), render(off, ref)
        assert np.abs(a - b).max() <= (0.0 if exact else 1e-6 * b.max()), (reg, np.abs(a - b).max())
    # ... and unregularised, the smooth mirror is not the rough one
    assert np.abs(render(off, {"type": "conductor"}) - render(off, ggx("roughconductor", 0.1))).max() > 0.01


def test_caustic_converges_to_the_mirror_image():
    """Without regularisation the floor receives the direct light only (the reflection of
    a point light in a smooth mirror is never sampled): its image is proportional to the
    analytic irradiance of the light (pixel ratios constant within 3%: the spectral
    noise). With it, the
    image adds the mirror image's irradiance: on/off over the image is the analytic
    (E_light + E_image) / E_light within 2% (1.405 against 1.415 at 1024 spp: the
    alpha-0.1 lobe blurs the reflection and loses a little energy)."""
    pos = render({"type": "aov", "aovs": "p:position"}, spp=4)
    off = render({"type": "path", "max_depth": 3}, spp=256).mean(-1)
    on = render({"type": "path", "max_depth": 3, "regularize": True}, spp=256).mean(-1)
    direct = irradiance(LIGHT, pos)
    k = off / direct
    assert k.std() < 0.03 * k.mean()      # spectral noise 1.6%; the caustic would vary it by ~15%
    expected = (off * (1.0 + irradiance(IMAGE, pos) / direct)).sum() / off.sum()
    measured = on.sum() / off.sum()
    assert expected > 1.3
    assert abs(measured / expected - 1.0) < 0.02, (measured, expected)


@pytest.mark.parametrize("integrator", ["path", "volpath"])
def test_nothing_to_regularise_renders_the_same_image(integrator):
    """The Cornell box (diffuse walls) renders bit for bit the same image with
    ``regularize`` on (nothing to regularise) and off."""
    imgs = []
    for reg in (False, True):
        d = pbr.cornell_box(16, 8)
        d["integrator"] = {"type": integrator, "regularize": reg}
        imgs.append(np.asarray(pbr.render(pbr.load_dict(d), seed=3)))
    assert np.array_equal(imgs[0], imgs[1])


PBRT = """
LookAt 0 0 3  0 0 0  0 1 0
Camera "perspective"
Film "rgb" "integer xresolution" 8 "integer yresolution" 8
Integrator "{integrator}" "bool regularize" true
WorldBegin
Shape "sphere"
"""


def test_pbrt_reader_maps_regularize(tmp_path):
    p = tmp_path / "s.pbrt"
    for integrator in ("path", "volpath"):
        p.write_text(PBRT.format(integrator=integrator))
        d, _, _ = convert(str(p))
        assert d["integrator"]["regularize"] is True
    p.write_text(PBRT.format(integrator="bdpt"))
    with pytest.raises(XMLError, match="'regularize' with 'bdpt'"):
        convert(str(p))
    p.write_text(PBRT.format(integrator="path"))
    with pytest.raises(XMLError, match="Mitsuba's integrators do not regularise"):
        convert(str(p), mitsuba=True)
