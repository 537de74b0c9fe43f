"""Gradient checks against finite differences, with Mitsuba's metric (its AD integrator
tests): forward mode per pixel ``|a - r| / max(|r|, 2e-2)`` averaged over the image, and
reverse mode ``|g - r| / max(|r|, 1e-3)`` for the gradient of a scalar loss (the image
projected on the normalised reference derivative image); both must
stay below 0.05. The finite-difference reference uses the same seed for +eps and -eps
(correlated samples), and many samples."""

import numpy as np
import drjit as dr
import mitsuba as mi

import pbr

FWD_MEAN_ERR = 0.05
BWD_ERR = 0.05


def _perturb(params, key, v0, tangent, eps):
    params[key] = type(v0)(v0 + tangent * eps) if eps else type(v0)(v0)
    params.update()


def fd_image(scene, params, key, tangent, eps, spp, seed=0, passes=1, side=0):
    """Finite difference of the image along ``tangent`` (same seeds at both ends):
    central (``side`` 0), or one-sided from the current value forward (+1) or backward
    (-1), for parameters on a bound of their range."""
    v0 = type(params[key])(params[key])
    steps = {0: (1.0, -1.0), 1: (1.0, 0.0), -1: (0.0, -1.0)}[side]
    acc = 0.0
    for p in range(passes):
        imgs = []
        for sign in steps:
            _perturb(params, key, v0, tangent, sign * eps)
            imgs.append(np.asarray(pbr.render(scene, spp=spp, seed=seed + 7919 * p), np.float64))
        acc = acc + (imgs[0] - imgs[1]) / ((steps[0] - steps[1]) * eps)
    _perturb(params, key, v0, tangent, 0.0)
    return acc / passes


def forward_image(scene, params, key, tangent, spp, seed=1):
    """Forward-mode derivative image along ``tangent``."""
    v0 = type(params[key])(params[key])
    dr.enable_grad(params[key])
    params.update()
    img = pbr.render(scene, params, spp=spp, seed=seed, seed_grad=seed + 1000)
    dr.set_grad(params[key], tangent)
    dr.enqueue(dr.ADMode.Forward, params[key])
    dr.traverse(dr.ADMode.Forward)
    g = np.asarray(dr.grad(img), np.float64)
    params[key] = v0
    params.update()
    return g


def backward_gradient(scene, params, key, tangent, spp, weights, seed=2):
    """d sum(weights * image) / d(parameter) along ``tangent``, by reverse mode."""
    v0 = type(params[key])(params[key])
    dr.enable_grad(params[key])
    params.update()
    img = pbr.render(scene, params, spp=spp, seed=seed, seed_grad=seed + 1000)
    dr.backward(dr.sum(img * mi.TensorXf(np.asarray(weights, np.float32)), axis=None))
    g = dr.grad(params[key])
    val = float(np.sum(np.asarray(g, np.float64).ravel() * np.asarray(tangent, np.float64).ravel()))
    params[key] = v0
    params.update()
    return val


def forward_error(a, r):
    return float(np.mean(np.abs(a - r) / np.maximum(np.abs(r), 2e-2)))


def projection(r_img):
    """Weights of the scalar loss for reverse mode: a normalised derivative image (the
    mean of the image can be insensitive, e.g. to roughness, which mostly moves light
    around). Take it from a finite-difference run *independent* of the reference, or
    the reference's own noise biases the projected value upward."""
    return r_img / max(float(np.sqrt(np.sum(r_img ** 2))), 1e-30)


def backward_error(g, r_img, weights):
    r = float(np.sum(weights * r_img))
    return abs(g - r) / max(abs(r), 1e-3)
