"""``ambientocclusion`` against closed forms.

A camera looks straight down (fov 0.5 degrees, so every pixel sees the floor within
0.02 of the axis) at a large floor plane under a disk of radius R at height h whose BSDF
is ``null``: camera rays pass through it (pbrt-v4 skips surfaces without a BSDF), AO
rays are blocked by it. The cosine-weighted fraction of the hemisphere blocked by a
cone of half-angle t is sin^2 t, so on the axis

    AO = 1 - sin^2(min(atan(R / h), acos(h / D)))

with D = ``maxdistance`` (the disk blocks only where it is nearer than D; the cone
cosine > h/D meets the disk plane inside the disk for offsets < R - sqrt(D^2 - h^2)).
Times the unit-luminance D65 illuminant this is AO times D65's linear sRGB (1, 1, 1)
up to the 5 nm tables' rounding (computed below from the same tables). Both
hemisphere samplers must give it; a shadow-ray length 1% too long must fail.
An empty hemisphere (D < h) gives 1, a closed box 0."""

import math

import numpy as np
import pytest
import mitsuba as mi

import pbr
from pbr import spectrum as spec, validate

H, R = 1.0, 1.0


def d65_srgb():
    """Linear sRGB of the unit-luminance D65 spectrum (trapezoidal rule on the 5 nm
    tables, as pbr normalises it)."""
    xyz, d65 = spec.cie_tables_np()
    w = np.full(len(d65), 5.0)
    w[0] = w[-1] = 2.5
    return spec.xyz_to_srgb((xyz * (d65 * w)[:, None]).sum(0) / spec.CIE_Y_INTEGRAL)


def disk_scene(res=16, **integrator):
    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": dict({"type": "ambientocclusion"}, **integrator),
        "sensor": {"type": "perspective", "fov": 0.5,
                   "to_world": T().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "to_world": T().scale(100.0), "bsdf": {"type": "diffuse"}},
        "disk": {"type": "disk", "to_world": T().translate([0, 0, H]).scale(R), "bsdf": {"type": "null"}},
    }


def ao_disk(max_distance=math.inf):
    t = math.atan(R / H)
    if max_distance < math.inf:
        t = min(t, math.acos(min(H / max_distance, 1.0)))
    return 1.0 - math.sin(t) ** 2


def check_constant(d, expected, spp=1024, batches=32, seed=3):
    """pbr's image vs the noiseless image AO = ``expected`` (times D65's sRGB)."""
    s = pbr.load_dict(d)
    e = validate.estimate(lambda seed=0, spp=0: np.asarray(pbr.render(s, seed=seed, spp=spp)), spp, batches, seed)
    ref = np.broadcast_to(expected * d65_srgb(), e.mean.shape)
    res = validate.compare(e.mean, e.var, ref, np.zeros_like(ref), image_mean_var_a=e.image_mean_var,
                           image_mean_var_b=0.0)
    print(expected, res.summary())
    return res


@pytest.mark.parametrize("cossample", [True, False])
@pytest.mark.parametrize("max_distance", [math.inf, 1.2, 0.9])
def test_ao_disk_closed_form(cossample, max_distance):
    kw = {"cossample": cossample}
    if max_distance < math.inf:
        kw["maxdistance"] = max_distance
    assert check_constant(disk_scene(**kw), ao_disk(max_distance))


def test_ao_longer_shadow_rays_fail():
    """maxdistance 1.212 instead of 1.2: AO 0.681 instead of 0.694 (2%)."""
    res = check_constant(disk_scene(maxdistance=1.212), ao_disk(1.2))
    assert not res.passed and res.mean_ratio < 1.0


def test_ao_closed_box_is_black():
    d = pbr.cornell_box(8, 4)
    d["integrator"] = {"type": "ambientocclusion"}
    d["front"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 1]).rotate([0, 1, 0], 180),
                  "bsdf": {"type": "null"}}   # camera rays pass, AO rays are blocked
    assert np.asarray(pbr.render(pbr.load_dict(d), spp=16)).max() == 0.0


def test_ao_invalid_parameters():
    with pytest.raises(pbr.SceneError, match="scene.integrator.maxdistance"):
        pbr.load_dict(disk_scene(maxdistance=-1.0))
    with pytest.raises(pbr.SceneError, match="scene.integrator.max_depth"):
        pbr.load_dict(disk_scene(max_depth=3))
