"""Dispersion: a wavelength-dependent IOR refracts by the first wavelength and terminates
the others (pbrt-v4's TerminateSecondary)."""

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import validate
from pbr.spectrum import SampledWavelengths, sellmeier_ior
from mitsuba_scenes import material_box


def test_bk7_sellmeier_matches_catalogue():
    # Schott N-BK7: n_F (486.1 nm) 1.52238, n_d (587.6 nm) 1.51680, n_C (656.3 nm) 1.51432.
    n = sellmeier_ior("glass-bk7", np.array([486.1, 587.6, 656.3]))
    assert np.allclose(n, [1.52238, 1.51680, 1.51432], atol=2e-5)


def test_terminate_secondary_divides_the_survivors_density():
    wl = SampledWavelengths(mi.Spectrum(400, 500, 600, 700), mi.Spectrum(0.002, 0.003, 0.004, 0.001))
    t = wl.terminate_secondary()
    assert np.allclose(np.array(t.pdf).ravel(), [0.0005, 0, 0, 0])
    assert np.allclose(np.array(t.terminate_secondary().pdf).ravel(), [0.0005, 0, 0, 0])


def _fn(d):
    scene = pbr.load_dict(d)
    return lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))


def test_constant_spectral_ior_equals_float_ior():
    """The dispersive code path (termination, N-fold weight) is unbiased: an IOR given as a
    flat spectrum renders like the same float IOR."""
    flat = {"type": "spectrum", "value": [(360.0, 1.5), (830.0, 1.5)]}
    d_spec = material_box({"type": "dielectric", "int_ior": flat},
                          {"type": "roughdielectric", "alpha": 0.3, "int_ior": flat})
    d_float = material_box({"type": "dielectric", "int_ior": 1.5},
                           {"type": "roughdielectric", "alpha": 0.3, "int_ior": 1.5})
    res = validate.compare_renders(_fn(d_spec), _fn(d_float), spp=1024, batches=16, seed_a=3, seed_b=4)
    print(res.summary())
    assert res.passed, res.summary()


def test_dispersion_without_termination_would_be_detected(monkeypatch):
    """Disabling the N-fold weight of the surviving wavelength must fail the same test."""
    from pbr.integrators import path
    monkeypatch.setattr(path, "first_only", lambda s: mi.Spectrum(s[0], 0.0, 0.0, 0.0))
    flat = {"type": "spectrum", "value": [(360.0, 1.5), (830.0, 1.5)]}
    d_spec = material_box({"type": "dielectric", "int_ior": flat}, {"type": "dielectric", "int_ior": flat})
    d_float = material_box({"type": "dielectric", "int_ior": 1.5}, {"type": "dielectric", "int_ior": 1.5})
    res = validate.compare_renders(_fn(d_spec), _fn(d_float), spp=512, batches=16, seed_a=3, seed_b=4)
    assert not res.passed


def test_named_glass_renders_and_gradients_are_refused():
    d = material_box({"type": "dielectric", "int_ior": "glass-BK7"})
    scene = pbr.load_dict(d)
    img = np.asarray(pbr.render(scene, spp=16))
    assert np.all(np.isfinite(img)) and img.mean() > 0.01
    params = pbr.traverse(scene)
    import drjit as dr
    key = "red.reflectance.value"
    dr.enable_grad(params[key])
    params.update()
    with pytest.raises(NotImplementedError, match="dispersive"):
        pbr.render(scene, params, spp=4)
