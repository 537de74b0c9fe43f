"""Scenes for gradient tests whose derivatives are well conditioned at 16x16 pixels and a
few thousand samples per pixel, and that pbr and Mitsuba 3 render alike (see
tests/test_ad_vs_mitsuba.py).

* ``glass_backdrop``: a rough glass sphere before an emitting checkerboard. The IOR
  moves and flips the checkerboard seen through the sphere, so d image / d eta is large
  and the backdrop is found both by light sampling and by BSDF sampling (MIS).
  The checkerboard's colours are uniform spectra: Mitsuba multiplies an RGB radiance
  by D65 only where ``rgb`` is the emitter's own radiance, not inside a texture (pbr
  does in both cases), so RGB checkerboards render in different colours.
* ``metal_floor``: a rough metal floor reflecting an emitting checkerboard.
* ``backlit_medium`` / ``backlit_cloud``: a cube of medium (homogeneous, or a voxel
  grid) before an emitting checkerboard: its transmittance carries most of the
  derivative, and the medium is kept away from the light (see ``backlit_medium``).
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

RES = 16


def _sensor(origin, fov, res=RES):
    T = mi.ScalarTransform4f
    return {"type": "perspective", "fov": fov,
            "to_world": T().look_at(origin=origin, target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": 16}}


def _checkerboard_emitter(z, half, freq, hi=1.0, lo=0.15):
    T = mi.ScalarTransform4f
    return {"type": "rectangle", "to_world": T().translate([0, 0, z]).scale(half),
            "emitter": {"type": "area", "radiance": {
                "type": "checkerboard", "color0": {"type": "spectrum", "value": hi},
                "color1": {"type": "spectrum", "value": lo}, "to_uv": T().scale([freq, freq, 1.0])}}}


def glass_backdrop(alpha=0.3, distribution="beckmann", max_depth=4, res=RES) -> dict:
    """A ``roughdielectric`` sphere (``glass``, IOR 1.5) before an emitting checkerboard;
    ``prb``. Beckmann by default: with GGX the transmitted lobe jumps to 0 where the
    generalised half vector becomes horizontal (D_GGX does not vanish there), a
    discontinuity that moves with eta and that detached sampling does not differentiate
    (about 2% of d/d eta here, in pbr and Mitsuba alike)."""
    return {"type": "scene", "integrator": {"type": "prb", "max_depth": max_depth},
            "sensor": _sensor([0, 0, 4.0], 22.0, res),
            "glass": {"type": "sphere", "radius": 0.6,
                      "bsdf": {"type": "roughdielectric", "distribution": distribution, "alpha": alpha,
                               "int_ior": 1.5, "ext_ior": 1.0}},
            "backdrop": _checkerboard_emitter(-1.6, 3.0, 4.0)}


def metal_floor(alpha=0.2, material="Au", max_depth=3, res=RES) -> dict:
    """A ``roughconductor`` floor (``floor``) reflecting an emitting checkerboard that
    stands behind it; ``prb``. Roughness blurs the reflection: with weights that follow
    the image, d <w, image> / d alpha is large and negative."""
    T = mi.ScalarTransform4f
    return {"type": "scene", "integrator": {"type": "prb", "max_depth": max_depth},
            "sensor": _sensor([0, 1.2, 3.0], 35.0, res),
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(2.0),
                      "bsdf": {"type": "roughconductor", "alpha": alpha, "material": material}},
            "backdrop": _checkerboard_emitter(-2.0, 2.0, 3.0) | {"to_world": T().translate([0, 1.0, -2.0]).scale(2.0)}}


def density(n=6) -> np.ndarray:
    """A smooth density blob (1 to 5) on an n^3 grid, (nz, ny, nx)."""
    z, y, x = np.mgrid[0:n, 0:n, 0:n] / (n - 1.0)
    return (1.0 + 4.0 * np.exp(-((x - 0.5) ** 2 + (y - 0.5) ** 2 + (z - 0.5) ** 2) / 0.1)).astype(np.float32)


def backlit_medium(interior: dict, max_depth=4, majorant_factor=2.0, res=RES) -> dict:
    """A medium in a unit cube (``cloud``, null boundary) before an emitting
    checkerboard; ``prbvolpath`` with ``majorant_factor`` (grids only).

    The derivative of a null collision's weight is -d sigma_t / (sigma_maj - sigma_t):
    a loose majorant (factor 2 instead of 1.1) halves the gradient's standard deviation
    here at ~10% more time. The medium is far from the light: Mitsuba 3.9's volumetric
    light sampling was 30x too dark for scattering points 0.15 below a ceiling-mounted
    area light (pbr matched a quadrature there)."""
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "integrator": {"type": "prbvolpath", "max_depth": max_depth, "majorant_factor": majorant_factor},
            "sensor": _sensor([0.3, 0.4, 3.5], 30.0, res),
            "cloud": {"type": "cube", "to_world": T().scale(0.5), "bsdf": {"type": "null"}, "interior": interior},
            "backdrop": _checkerboard_emitter(-1.5, 2.0, 3.0, lo=0.3)}


def backlit_cloud(albedo=0.3, **kw) -> dict:
    """``backlit_medium`` with a ``heterogeneous`` medium: the 6^3 ``density()`` grid."""
    T = mi.ScalarTransform4f
    return backlit_medium({"type": "heterogeneous", "albedo": albedo,
                           "sigma_t": {"type": "gridvolume", "data": mi.TensorXf(density()[..., None]),
                                       "to_world": T().translate([-0.5, -0.5, -0.5])}}, **kw)


def voxel_block(shape, lo=4, hi=6) -> np.ndarray:
    """Tangent selecting the voxels [lo, hi)^3 of a (nz, ny, nx, 1) grid. The default
    block (the cube's front upper corner, density ~1.3) does not hold the grid's maximum:
    Mitsuba's ``heterogeneous`` majorant is that maximum itself (no inflation), so where
    sigma_t reaches it no null collision carries the transmittance derivative (the
    central block [2, 4)^3: Mitsuba -0.349 +- 0.006, pbr -0.402 +- 0.004, central
    differences -0.405 +- 0.010 and -0.412 +- 0.015 in the two renderers)."""
    t = np.zeros(shape, np.float32)
    t[lo:hi, lo:hi, lo:hi, 0] = 1.0
    return t
