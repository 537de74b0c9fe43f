"""Gradients through the stochastic layered BSDFs (``coateddiffuse``, ``coatedconductor``).

Each query of these BSDFs is a random walk inside the coating. With gradients enabled the
walks sample with detached parameters and their weights carry the derivatives (as a
path replay does), their loops are unrolled (Dr.Jit cannot differentiate them as nested
symbolic loops), and the path replay differentiates the sampled walk's own weight. Here:
forward == reverse for every parameter, and reverse mode against central differences
(same seeds for +-eps) with the projected metric of grad_harness."""

import numpy as np
import pytest

import pbr
from grad_harness import BWD_ERR, backward_error, backward_gradient, fd_image, forward_image, projection

RGB = lambda *v: {"type": "rgb", "value": list(v)}  # noqa: E731
CASES = {
    # A rough coat over a diffuse base, with a scattering medium in the coat.
    "coateddiffuse": {"type": "coateddiffuse", "reflectance": RGB(0.3, 0.5, 0.6), "roughness": 0.1,
                      "thickness": 1.0, "albedo": 0.9, "g": 0.5},
    "coatedconductor": {"type": "coatedconductor", "interface.roughness": 0.05, "conductor.roughness": 0.2,
                        "thickness": 0.5, "albedo": 0.6, "g": -0.3},
    # The same coat without a medium (albedo 0: absorption only).
    "coateddiffuse no medium": {"type": "coateddiffuse", "reflectance": RGB(0.3, 0.5, 0.6), "roughness": 0.1,
                                "thickness": 1.0, "albedo": 0.0},
    # Smooth coat over a mirror: every walk is a chain of delta events.
    "smooth coatedconductor": {"type": "coatedconductor", "interface.roughness": 0.0, "conductor.roughness": 0.0,
                               "thickness": 0.3, "albedo": RGB(0.2, 0.3, 0.4)},
}


def _scene(case, integrator="prb", **extra):
    import grad_scenes as G
    pbr.backend.ensure()
    d = G.metal_floor(max_depth=3)
    d["integrator"]["type"] = integrator
    d["floor"]["bsdf"] = dict(CASES[case], **extra)
    scene = pbr.load_dict(d)
    return scene, pbr.traverse(scene)


@pytest.mark.parametrize("case", ["coateddiffuse", "coatedconductor"])
def test_forward_equals_reverse_for_every_layered_parameter(case):
    # maxdepth 4: the unrolled walks compile in less time; the code is the same.
    scene, params = _scene(case, maxdepth=4)
    keys = [k for k in params.keys() if k.startswith("floor.bsdf.")]
    assert len(keys) >= 5, keys
    w = np.random.default_rng(0).uniform(0.0, 1.0, (16, 16, 3))
    bad = []
    for k in keys:
        t = type(params[k])(1.0)
        fwd = float(np.sum(w * forward_image(scene, params, k, t, 16, seed=3)))
        bwd = backward_gradient(scene, params, k, t, 16, w, seed=3)
        ok = np.isfinite(fwd) and fwd != 0.0 and abs(fwd - bwd) <= 1e-4 * abs(fwd)
        print(f"{'ok ' if ok else 'BAD'} {k}: forward {fwd:.6g}, reverse {bwd:.6g}")
        if not ok:
            bad.append(k)
    assert not bad, bad


def _check_fd(case, key, spp, eps_rel, integrator="prb"):
    scene, params = _scene(case, integrator)
    key = f"floor.bsdf.{key}" + ("" if key.endswith("eta") else ".value")
    v = params[key]
    tan = type(v)(1.0)
    eps = eps_rel * float(np.mean(np.asarray(v)))
    ref = fd_image(scene, params, key, tan, eps, spp, passes=2)
    w = projection(fd_image(scene, params, key, tan, eps, spp, seed=5000))
    g = backward_gradient(scene, params, key, tan, spp, w)
    err = backward_error(g, ref, w)
    print(f"{integrator} {case} {key}: finite differences {np.sum(w * ref):.5g}, reverse mode {g:.5g} (error {err:.4f})")
    assert err < BWD_ERR, (case, key, err)


# Parameters that only scale the walks' weights: robust at modest sample counts.
# Measured errors at these counts (and at 4x): coateddiffuse reflectance 0.023 (0.015),
# albedo 0.010 (0.020); smooth coat thickness 0.008, albedo 0.004 (0.010). Before the
# walks were differentiated with fixed sampling and the replay used the sample's own
# weight (and while Russian roulette's probability carried a derivative), reflectance
# had 0.49 and albedo 0.54 in a similar scene (thickness 0.3, albedo 0.5).
@pytest.mark.parametrize("case,key,spp", [("coateddiffuse", "reflectance", 2048), ("coateddiffuse", "albedo", 2048),
                                          ("smooth coatedconductor", "thickness", 2048),
                                          ("smooth coatedconductor", "albedo", 8192)])
def test_reverse_mode_matches_finite_differences(case, key, spp):
    _check_fd(case, key, spp, 0.1)


def test_prbvolpath_differentiates_the_walks_too():
    # prbvolpath sent the light sample's and the continuation's derivatives in two
    # traversals; the first cleared the BSDF query's graph that both share (the sampled
    # walk's weight), and d/d reflectance came out 0.186 instead of 0.410 (error 0.55).
    _check_fd("coateddiffuse", "reflectance", 2048, 0.1, integrator="prbvolpath")


# Parameters that move the walks' directions (roughness, g) or their flights (thickness
# with a medium): their finite differences need many samples (at 4096 spp two
# independent estimates differ by up to 30% for g). Measured at 16384 spp: coateddiffuse
# roughness 0.011, thickness 0.037, g 0.035; coatedconductor interface roughness 0.022,
# conductor roughness 0.015, thickness 0.017. With attached sampling inside the walks
# (directions moving with the parameters) roughness had 0.82, thickness 0.70.
@pytest.mark.slow
@pytest.mark.parametrize("case,key", [("coateddiffuse", "roughness"), ("coateddiffuse", "thickness"),
                                      ("coateddiffuse", "g"), ("coatedconductor", "interface.roughness"),
                                      ("coatedconductor", "conductor.roughness"), ("coatedconductor", "thickness")])
def test_reverse_mode_matches_finite_differences_slow(case, key):
    _check_fd(case, key, 16384, 0.2 if key in ("g", "thickness") else 0.1)


# The coat's IOR. A rough coat over a conductor agrees (0.025 at 16384 spp). Known
# failures, kept visible: over the diffuse base with a scattering medium d/d eta comes
# out 9% low (0.089 at 4096 and 0.093 at 16384 spp: a bias, not noise). It is GGX's
# refracted lobe, which jumps to 0 at an edge that moves with eta (the same bias as
# roughdielectric's, 2% at eta 1.5), amplified by scatterers near the top that connect
# through grazing directions: without the medium (albedo 0, tested below) the error is
# 0.004, and with Beckmann in the coat instead of GGX 0.003 (docs/layered.md). A smooth coat's
# refracted directions move with eta and that motion is not differentiated (as for the
# smooth dielectric), which here even flips the sign (-2.44 vs +2.04).
@pytest.mark.slow
@pytest.mark.parametrize("case,key", [
    ("coatedconductor", "interface.eta"),
    ("coateddiffuse no medium", "eta"),
    pytest.param("coateddiffuse", "eta",
                 marks=pytest.mark.xfail(strict=True, reason="GGX lobe edge moving with eta, see above")),
    pytest.param("smooth coatedconductor", "interface.eta",
                 marks=pytest.mark.xfail(strict=True, reason="refraction motion not differentiated"))])
def test_coat_ior_against_finite_differences(case, key):
    _check_fd(case, key, 16384, 0.05)
