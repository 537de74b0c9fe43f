"""Forward-mode derivatives (``dr.forward``) of ``prb``/``prbvolpath`` images for every
parameter kind of tests/test_ad_integrators.py: against finite differences, and against
reverse mode on the same samples (the two modes must give the same number)."""

import numpy as np
import drjit as dr
import pytest

from grad_harness import (BWD_ERR, FWD_MEAN_ERR, backward_error, backward_gradient, fd_image, forward_error,
                          forward_image, projection)
from test_ad_integrators import CASES, _setup

# Roughness and IOR move light around (a highlight, a refracted image): their per-pixel
# derivatives are small against the Monte Carlo noise of both estimates at test sample
# counts (two independent forward images of the roughness scene differ by 0.36 in the
# per-pixel metric; the IOR scene's forward image gives 0.23 against finite differences
# with image means -0.1281 vs -0.1279), so their forward images are checked through the
# projected (scalar) metric that reverse mode uses. Even that scalar varies by 10%
# (standard deviation) between seeds at 2048 spp for roughness, so this check runs at 8x
# the samples, among the slow tests; forward == reverse below covers the default run.
NOISY_PER_PIXEL = {"roughness", "ior"}


@pytest.mark.parametrize("name", sorted(set(CASES) - NOISY_PER_PIXEL))
def test_forward_image_matches_finite_differences(name):
    scene, params, key, tan, ref, spp, _ = _setup(name)
    fwd = forward_image(scene, params, key, tan, spp)
    err = forward_error(fwd, ref)
    print(f"{name}: forward image mean {fwd.mean():.5g} vs {ref.mean():.5g}, per-pixel error {err:.4f}")
    assert err < FWD_MEAN_ERR, (name, err)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(NOISY_PER_PIXEL))
def test_forward_projection_matches_finite_differences(name):
    scene, params, key, tan, ref, spp, (make, eps, spp_fd) = _setup(name)
    ref = (ref + fd_image(scene, params, key, tan, eps, spp_fd, seed=9000)) / 2
    w = projection(fd_image(scene, params, key, tan, eps, spp_fd // 2, seed=5000))
    fwd = forward_image(scene, params, key, tan, 8 * spp)
    g = float(np.sum(w * fwd))
    err = backward_error(g, ref, w)
    print(f"{name}: projected derivative: finite differences {np.sum(w * ref):.5g}, forward mode {g:.5g} "
          f"(error {err:.4f})")
    assert err < BWD_ERR, (name, err)


@pytest.mark.parametrize("name", sorted(CASES))
def test_forward_equals_reverse_on_the_same_samples(name):
    """<w, J t> by forward mode equals <J^T w, t> by reverse mode with the same seeds:
    the two adjoint passes replay the same paths, so only rounding may differ."""
    import pbr
    make, key, tangent, *_ = CASES[name]
    scene = pbr.load_dict(make())
    params = pbr.traverse(scene)
    tan = tangent(params, key)
    w = np.random.default_rng(7).uniform(0.0, 1.0, (16, 16, 3))
    fwd = float(np.sum(w * forward_image(scene, params, key, tan, 64, seed=11)))
    bwd = backward_gradient(scene, params, key, tan, 64, w, seed=11)
    print(f"{name}: forward {fwd:.7g}, reverse {bwd:.7g}")
    assert abs(fwd) > 1e-6 and abs(fwd - bwd) <= 1e-3 * abs(fwd), (name, fwd, bwd)


def test_bitmap_texels_forward_equals_reverse():
    """A bitmap texture's texels (the albedo-texture example's scene): reverse mode goes
    through the texture lookup's symbolic conditional, forward mode through its per-lane
    form (pbr.dispatch.by_lane); both give the same derivative."""
    import os
    import sys
    import mitsuba as mi
    import pbr
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples"))
    import optimize_albedo_texture as ex
    scene = pbr.load_dict(ex.scene_dict(8, 16, 16))
    params = pbr.traverse(scene)
    tan = mi.TensorXf(np.random.default_rng(1).uniform(0, 1, params[ex.KEY].shape).astype(np.float32))
    w = np.random.default_rng(7).uniform(0.0, 1.0, (16, 16, 3))
    fwd = float(np.sum(w * forward_image(scene, params, ex.KEY, tan, 64, seed=11)))
    bwd = backward_gradient(scene, params, ex.KEY, tan, 64, w, seed=11)
    print(f"bitmap texels: forward {fwd:.7g}, reverse {bwd:.7g}")
    assert abs(fwd) > 1e-3 and abs(fwd - bwd) <= 1e-4 * abs(fwd), (fwd, bwd)
