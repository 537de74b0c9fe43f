"""``whitted``: recursive specular ray tracing with direct lighting.

(a) Without specular surfaces Whitted's estimate is the direct illumination, so it must
    match Mitsuba's ``direct`` (light samples with MIS there, one sample of every light
    here: different noise, same mean), with one light and with two of different kinds.
(b) Specular chains are checked against pbr's ``path`` (itself checked against Mitsuba)
    on scenes where the two estimate the same sum of paths:
    * only emitters and specular surfaces (a dispersive glass sphere, a gold cube,
      emitting walls):
      both integrators sum exactly the chains camera -> specular* -> emitter of at most
      max_depth segments; ``path`` picks reflection or refraction at random, whitted
      follows both. Dropping the refracted branch must fail.
    * a diffuse floor lit by a point light, seen directly, in a tilted gold mirror and
      through a thin glass pane, at max_depth 3: the only paths of <= 3 segments that
      carry light are camera -> [specular] -> floor -> light (a plane cannot see itself,
      a point light cannot be hit), i.e. exactly Whitted's set, shadows included.
"""

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import validate
from pbr.integrators.whitted import WhittedIntegrator
from mitsuba_scenes import BATCHES, RES, material_box

SPP = 512


def render_fn(d, integrator_cls=None):
    s = pbr.load_dict(d)
    if integrator_cls is not None:
        s.integrator.__class__ = integrator_cls
    return lambda seed=0, spp=0: np.asarray(pbr.render(s, seed=seed, spp=spp))


def compare(fa, fb, scale, spp=SPP):
    res = validate.compare_renders(fa, fb, spp=spp * scale, batches=BATCHES, seed_a=41, seed_b=42)
    print(res.summary())
    return res


def with_integrator(d, **integrator):
    d = dict(d)
    d["integrator"] = integrator
    return d


@pytest.mark.parametrize("two_lights", [False, True])
def test_whitted_diffuse_matches_mitsuba_direct(two_lights, scale):
    d = material_box({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}}, scale=scale)
    if two_lights:
        d["point"] = {"type": "point", "position": [0.3, 0.5, 0.4],
                      "intensity": {"type": "rgb", "value": [1.0, 1.5, 2.0]}}
    w = with_integrator(d, type="whitted", hide_emitters=True)
    m = with_integrator(d, type="direct", hide_emitters=True)
    assert compare(render_fn(w), validate.mitsuba_render_fn(m), scale)


def specular_box(integrator, max_depth, scale=1):
    """Emitting walls (a checkerboard floor), a dispersive glass sphere (BK7: refraction
    keeps only the first wavelength, once per ray) and a gold cube."""
    T = mi.ScalarTransform4f
    d = pbr.cornell_box(RES * scale, 16)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = {"type": integrator, "max_depth": max_depth}
    walls = {"floor": None, "ceiling": [0.3, 0.3, 0.9], "back": [0.9, 0.6, 0.2],
             "green-wall": [0.1, 0.9, 0.2], "red-wall": [0.9, 0.1, 0.1]}
    for k, rgb in walls.items():
        del d[k]["bsdf"]
        d[k]["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": rgb} if rgb else {
            "type": "checkerboard", "color0": {"type": "rgb", "value": [0.9, 0.9, 0.9]},
            "color1": {"type": "rgb", "value": [0.1, 0.1, 0.1]}, "to_uv": T().scale([6, 6, 1])}}
    del d["light"]
    d["small-box"] = {"type": "sphere", "center": [0.3, -0.55, 0.3], "radius": 0.4,
                      "bsdf": {"type": "dielectric", "int_ior": "glass-BK7"}}
    d["large-box"]["bsdf"] = {"type": "conductor", "material": "Au"}
    return d


def mirror_floor(integrator, scale=1):
    """A checkerboard floor under a point light, a tilted gold mirror, a glass sphere and
    a thin glass pane; nothing else (black background)."""
    T = mi.ScalarTransform4f
    d = pbr.cornell_box(RES * scale, 16)
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["integrator"] = {"type": integrator, "max_depth": 3}
    for k in ("ceiling", "back", "green-wall", "red-wall", "light", "large-box"):
        del d[k]
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "checkerboard", "to_uv": T().scale([5, 5, 1])}}
    d["point"] = {"type": "point", "position": [0.0, 0.8, 0.5], "intensity": {"type": "rgb", "value": [10.0, 8.6, 7.2]}}
    d["small-box"] = {"type": "sphere", "center": [0.3, -0.55, 0.3], "radius": 0.4,
                      "bsdf": {"type": "dielectric", "int_ior": 1.5}}
    d["mirror"] = {"type": "rectangle", "to_world": T().translate([-0.2, 0.0, -0.8]).rotate([1, 0, 0], 30).scale(
        [0.7, 0.6, 1]), "bsdf": {"type": "conductor", "material": "Au"}}
    d["pane"] = {"type": "rectangle", "to_world": T().translate([0.45, -0.55, 1.2]).rotate([0, 1, 0], 20).scale(0.4),
                 "bsdf": {"type": "thindielectric", "int_ior": 1.8}}
    return d


def test_whitted_specular_chains_match_path(scale):
    assert compare(render_fn(specular_box("whitted", 5, scale)), render_fn(specular_box("path", 5, scale)), scale)


def test_whitted_direct_light_after_specular_matches_path(scale):
    assert compare(render_fn(mirror_floor("whitted", scale)), render_fn(mirror_floor("path", scale)), scale)


class _ReflectionOnly(WhittedIntegrator):
    """Sabotage: follows only the first delta lobe (the reflection), drops refraction."""
    branch_u = (0.0,)


def test_whitted_without_refraction_fails(scale):
    res = compare(render_fn(specular_box("whitted", 5, scale), _ReflectionOnly),
                  render_fn(specular_box("path", 5, scale)), scale, spp=128)
    assert not res.passed and res.mean_ratio < 1.0


def test_whitted_depth_limits():
    """max_depth 1: only emitters seen directly; 0: black."""
    d = specular_box("whitted", 1)
    img = np.asarray(pbr.render(pbr.load_dict(d), spp=16))
    ref = np.asarray(pbr.render(pbr.load_dict(specular_box("path", 1)), spp=16))
    assert np.allclose(img.mean(), ref.mean(), rtol=0.05)
    assert np.asarray(pbr.render(pbr.load_dict(specular_box("whitted", 0)), spp=4)).max() == 0.0


@pytest.mark.parametrize("patch, key", [
    ({"integrator": {"type": "whitted", "max_depth": -1}}, "scene.integrator.max_depth"),
    ({"integrator": {"type": "whitted"}, "fog": {"type": "homogeneous", "sigma_t": 1.0}}, "scene.integrator"),
])
def test_whitted_invalid_scenes(patch, key):
    d = pbr.cornell_box(8, 4)
    d.update(patch)
    with pytest.raises(pbr.SceneError, match=key):
        pbr.load_dict(d)
