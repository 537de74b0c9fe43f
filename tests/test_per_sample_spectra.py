"""Spectra that depend on a camera sample's wavelengths only (D65, constant emitter
spectra) are computed once per sample, before the integrator's loop, and give the same
images as their lookups at every path vertex (docs/performance.md)."""

import drjit as dr
import mitsuba as mi
import numpy as np

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
