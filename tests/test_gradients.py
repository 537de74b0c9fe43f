"""d(mean image)/d(albedo): PRB reverse mode and forward mode vs central finite differences."""

import numpy as np
import drjit as dr
import mitsuba as mi
import pytest

import pbr

KEY = "red.reflectance.value"


@pytest.fixture(scope="module")
def setup():
    d = pbr.cornell_box(12, 16)
    d["integrator"] = {"type": "path", "max_depth": -1, "rr_depth": 3}
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    return scene, params, mi.Color3f(params[KEY])


def _fd(scene, params, v0, spp, seeds, eps=2e-2):
    out = []
    for s in seeds:
        vals = []
        for sign in (1, -1):
            params[KEY] = v0 + mi.Color3f(sign * eps, 0, 0)
            params.update()
            vals.append(np.asarray(pbr.render(scene, spp=spp, seed=s)).mean(axis=(0, 1)))
        out.append((vals[0] - vals[1]) / (2 * eps))
    params[KEY] = mi.Color3f(v0)
    params.update()
    return np.mean(out, 0), np.std(out, 0) / np.sqrt(len(seeds))


def test_reverse_and_forward_match_finite_differences(setup):
    scene, params, v0 = setup
    spp, seeds = 512, range(3)
    fd, fd_se = _fd(scene, params, v0, spp, seeds)
    rev, fwd = [], []
    for s in seeds:
        params[KEY] = mi.Color3f(v0)
        dr.enable_grad(params[KEY])
        params.update()
        img = pbr.render(scene, params, spp=spp, seed=s, seed_grad=100 + s)
        dr.backward(dr.mean(img[..., 0], axis=None))          # d mean(R) / d (r, g, b)
        rev.append(np.array(dr.grad(params[KEY])).ravel()[0])
        params[KEY] = mi.Color3f(v0)
        dr.enable_grad(params[KEY])
        params.update()
        img = pbr.render(scene, params, spp=spp, seed=s, seed_grad=200 + s)
        dr.set_grad(params[KEY], mi.Color3f(1, 0, 0))
        dr.enqueue(dr.ADMode.Forward, params[KEY])
        dr.traverse(dr.ADMode.Forward)
        fwd.append(np.asarray(dr.grad(img)).mean(axis=(0, 1)))
    params[KEY] = mi.Color3f(v0)
    params.update()
    rev, fwd = np.mean(rev), np.mean(fwd, 0)
    tol = 4 * fd_se[0] + 0.03 * abs(fd[0])
    assert fd[0] > 0.01
    assert abs(rev - fd[0]) < tol, (rev, fd, fd_se)
    assert abs(fwd[0] - fd[0]) < tol, (fwd, fd, fd_se)
    # Green and blue barely depend on the red wall's red albedo.
    assert np.all(np.abs(fwd[1:] - fd[1:]) < 4 * fd_se[1:] + 0.1 * abs(fd[0])), (fwd, fd)


def test_gradient_is_zero_for_unrelated_scale(setup):
    """A gradient test that can fail: a deliberately wrong derivative (x2) is detected."""
    scene, params, v0 = setup
    fd, se = _fd(scene, params, v0, 256, range(2))
    assert abs(2 * fd[0] - fd[0]) > 4 * se[0] + 0.03 * abs(fd[0])
