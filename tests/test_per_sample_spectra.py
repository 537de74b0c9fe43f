"""Spectra that depend on a camera sample's wavelengths only (D65, constant emitter
spectra) are computed once per sample, before the integrator's loop, and give the same
images as their lookups at every path vertex (docs/performance.md)."""

import os
import tempfile

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr import spectrum as S
from pbr.textures.textureset import TextureSet


def test_d65_of_the_sampled_wavelengths_is_the_one_computed_at_sampling():
    wl = S.SampledWavelengths.sample_visible(dr.linspace(mi.Float, 0.0, 0.999, 64))
    fixed = S.d65(wl.lambda_)
    assert fixed is S.d65(mi.Spectrum(wl.lambda_))      # by variable, not by Python object
    other = mi.Spectrum(wl.lambda_) + 0.0
    other = mi.Spectrum(dr.select(other > 0, other, 1.0))     # same values, other variables
    fresh = S.d65(other)
    assert fresh is not fixed
    assert np.array_equal(np.asarray(fresh), np.asarray(fixed))
    lam = np.asarray(wl.lambda_, np.float64)
    _, d65 = S.cie_tables_np()
    grid = S.LAMBDA_MIN + 5.0 * np.arange(len(d65))
    assert np.allclose(np.asarray(fixed), np.interp(lam, grid, d65), rtol=1e-5)


def _lights_scene():
    """The Cornell box (a constant area light) with a point light added."""
    d = pbr.cornell_box(24, 8)
    d["point"] = {"type": "point", "position": [0.3, 0.6, 0.2], "intensity": {"type": "rgb", "value": [2.0, 1.5, 1.0]}}
    return d


def _counting(monkeypatch):
    hits = []
    orig = TextureSet._fixed_value

    def counted(self, *a):
        v = orig(self, *a)
        hits.append(v is not None)
        return v

    monkeypatch.setattr(TextureSet, "_fixed_value", counted)
    return hits


def test_emitter_spectra_fixed_per_sample_give_the_per_vertex_image(monkeypatch):
    hits = _counting(monkeypatch)
    scene = pbr.load_dict(_lights_scene())
    fixed = np.asarray(pbr.render(scene, spp=8, seed=3))
    # emission found, the area light's and the point light's next-event samples
    assert sum(hits) >= 3, hits
    hits.clear()
    monkeypatch.setattr(TextureSet, "MAX_FIXED", 0)
    per_vertex = np.asarray(pbr.render(scene, spp=8, seed=3))
    assert not any(hits)
    assert fixed.mean() > 0.01
    assert np.array_equal(fixed, per_vertex)


def test_emitter_spectra_with_derivatives_are_not_fixed(monkeypatch):
    """A derivative pass evaluates the emitter's spectrum attached, inside the loop: a
    fixed (detached) value would lose its derivative (forward and reverse derivatives of
    the gallery's light radiance differed when it did)."""
    hits = _counting(monkeypatch)
    d = _lights_scene()
    d["integrator"] = {"type": "prb", "max_depth": 4}
    scene = pbr.load_dict(d)
    p = pbr.traverse(scene)
    key = next(k for k in p.keys() if k.endswith("emitter.radiance.value"))
    dr.enable_grad(p[key])
    p.update()
    img = pbr.render(scene, p, spp=4, seed=1)
    dr.forward(p[key])
    assert np.abs(np.asarray(dr.grad(img))).max() > 0
    assert not any(hits)


def stage(**emitters):
    """A grey sphere on a checkerboard floor, lit by ``emitters``."""
    T = mi.ScalarTransform4f
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 4},
         "sensor": {"type": "perspective", "fov": 40.0,
                    "to_world": T().look_at(origin=[0, 1.6, 3.2], target=[0, 0, 0], up=[0, 1, 0]),
                    "sampler": {"type": "independent", "sample_count": 4},
                    "film": {"type": "hdrfilm", "width": 16, "height": 16}},
         "floor": {"type": "rectangle", "to_world": T().translate([0, -0.5, 0]).rotate([1, 0, 0], -90).scale(3),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": 0.7,
                                                               "color1": 0.2}}},
         "sphere": {"type": "sphere", "radius": 0.5,
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.4]}}}}
    d.update(emitters)
    return d


def _sky() -> str:
    path = os.path.join(tempfile.gettempdir(), "pbr_test_per_sample_sky.exr")
    if not os.path.exists(path):
        sky = np.ones((8, 16, 3), np.float32) * np.array([0.4, 0.5, 0.9], np.float32)
        mi.Bitmap(sky).write(path)
    return path


T = mi.ScalarTransform4f
POINT = {"type": "point", "position": [1.0, 2.0, 1.0], "intensity": {"type": "rgb", "value": [8.0, 7.0, 6.0]}}
POINT2 = {"type": "point", "position": [-1.0, 1.5, 0.5], "intensity": {"type": "rgb", "value": [1.0, 3.0, 6.0]}}
SPOT = {"type": "spot", "cutoff_angle": 40.0, "intensity": {"type": "blackbody", "temperature": 3200.0},
        "to_world": T().look_at(origin=[1.5, 2.5, 1.5], target=[0, -0.3, 0], up=[0, 1, 0])}
DIRECTIONAL = {"type": "directional", "direction": [-0.4, -1.0, -0.3],
               "irradiance": {"type": "rgb", "value": [3.0, 2.8, 2.5]}}
CONSTANT = {"type": "constant", "radiance": {"type": "rgb", "value": [0.5, 0.45, 0.4]}}
AREA = {"type": "rectangle", "to_world": T().translate([0.5, 2.5, 1.0]).rotate([1, 0, 0], 90).scale(0.6),
        "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 5.5, 5.0]}}}
# sample_Li traces rays: called outside the lights' dr.switch
PANEL = {"type": "rectangle", "to_world": T().translate([0, 2.0, 0]).rotate([1, 0, 0], 90),
         "emitter": {"type": "directionalarea", "radiance": {"type": "rgb", "value": [2.0, 2.0, 1.5]}}}
PROJECTOR = {"type": "projector", "fov": 50.0, "irradiance": {"type": "rgb", "value": [8.0, 6.0, 4.0]},
             "to_world": T().look_at(origin=[1.5, 2.5, 1.5], target=[0, -0.3, 0], up=[0, 1, 0])}
ENVMAP = {"type": "envmap", "filename": "SKY"}
BITMAP_AREA = {**AREA, "emitter": {"type": "area", "radiance": {"type": "bitmap", "filename": "SKY"}}}


def _with_sky(v):
    if isinstance(v, dict):
        return {k: (_sky() if k == "filename" and x == "SKY" else _with_sky(x)) for k, x in v.items()}
    return v


@pytest.mark.parametrize("emitters, fixed", [
    ({"e": POINT}, True), ({"e": SPOT}, True), ({"e": DIRECTIONAL}, True), ({"e": CONSTANT}, True),
    ({"e": PROJECTOR}, True), ({"light": AREA}, True), ({"a": POINT, "b": POINT2}, True),
    ({"a": POINT, "light": AREA, "c": CONSTANT}, True), ({"e": ENVMAP, "a": POINT}, True),
    ({"a": POINT, "s": SPOT, "d": DIRECTIONAL, "light": AREA}, True), ({"a": POINT, "panel": PANEL}, True),
    ({"e": ENVMAP}, False), ({"light": BITMAP_AREA}, False),
], ids=["point", "spot-blackbody", "directional", "constant", "projector", "area", "two-points", "mixed",
        "envmap-point", "four-families", "directionalarea-point", "envmap", "bitmap-area"])
def test_every_emitter_kind_renders_as_with_per_vertex_lookups(monkeypatch, emitters, fixed):
    """Alone and mixed (through the lights' dr.switch, and the families it calls outside
    because they trace rays): bit-identical to the lookups at every vertex, D65 included;
    spatially varying spectra (environment map, emitting bitmap) are not fixed."""
    hits = _counting(monkeypatch)
    scene = pbr.load_dict(stage(**{k: _with_sky(v) for k, v in emitters.items()}))
    new = np.asarray(pbr.render(scene, spp=4, seed=2))
    assert any(hits) == fixed
    monkeypatch.setattr(TextureSet, "MAX_FIXED", 0)
    monkeypatch.setattr(S, "fixed_for", lambda lam: None)
    old = np.asarray(pbr.render(scene, spp=4, seed=2))
    assert np.all(np.isfinite(new)) and new.mean() > 0
    assert np.array_equal(new, old)


def test_d65_reaches_the_lights_switch(monkeypatch):
    """With an environment map and a point light (two families: a symbolic call), the
    environment's D65 factor inside the call is the one fixed per sample."""
    seen, keys = [], set()
    orig = S.fixed_for

    def counted(lam):
        v = orig(lam)
        seen.append(v is not None and S.D65 in v)
        if seen[-1]:
            keys.add(S.wavelength_key(lam))
        return v

    monkeypatch.setattr(S, "fixed_for", counted)
    scene = pbr.load_dict(stage(e=_with_sky(ENVMAP), a=POINT))
    pbr.render(scene, spp=4, seed=2)
    # the switch forwards it (one check there) and the envmap's lookups inside find it
    assert sum(seen) >= 3, seen
    # found at the sample's wavelengths and at the call's own (forwarded) variables
    assert len(keys) >= 2, keys
