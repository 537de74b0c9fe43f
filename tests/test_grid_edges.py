"""Grid media where a ray inside the medium misses the grid's unit cube (the majorant
walk's empty segment): the grid smaller than the shape that bounds the medium, and a
scattering point that lands exactly on the cube's face.

Before the fix, ``majorant.start`` set up the DDA at a point outside the cube, so the
first step went *back* to a cell boundary: a negative distance and T_maj > 1 (pbr 0.7%
darker than Mitsuba over the image, 44 pixel-channels failing, z up to 26), and NaN when
the ray escaped (t_max = inf), which turned a whole voxel block's gradient into NaN."""

import mitsuba as mi
import numpy as np
import drjit as dr

import pbr
from pbr import validate
from grad_scenes import backlit_cloud, backlit_medium, density


def _small_grid(integrator, half=0.25):
    """The backlit cube of medium with its grid filling only [-half, half]^3."""
    T = mi.ScalarTransform4f
    d = backlit_medium({"type": "heterogeneous", "albedo": 0.5,
                        "sigma_t": {"type": "gridvolume", "data": mi.TensorXf(2.0 * density()[..., None]),
                                    "to_world": T().translate([-half] * 3).scale(2 * half)}})
    d["integrator"] = {"type": integrator, "max_depth": 4}
    return d


def test_grid_smaller_than_its_shape_matches_mitsuba():
    for integrator in ("volpath", "prbvolpath"):
        d = _small_grid(integrator)
        scene = pbr.load_dict(d)
        res = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp)),
                                       validate.mitsuba_render_fn(d), spp=1024, batches=16, seed_a=1, seed_b=2)
        print(integrator, res)
        assert res.passed, (integrator, str(res))


def test_voxel_gradient_finite_when_a_scattering_point_is_on_the_face():
    """Seed 45 / seed_grad 1045 at 2048 spp puts one scattering point exactly on the
    cube's face x = -0.5, and the next ray leaves the medium (found by
    tests/test_ad_vs_mitsuba.py's slow variant)."""
    scene = pbr.load_dict(backlit_cloud())
    params = pbr.traverse(scene)
    key = "cloud.interior_medium.sigma_t.data"
    v = mi.TensorXf(params[key])
    dr.enable_grad(v)
    params[key] = v
    params.update()
    img = pbr.render(scene, params, spp=2048, seed=45, seed_grad=1045)
    assert np.all(np.isfinite(np.asarray(img)))
    dr.backward(dr.sum(img, axis=None))
    g = np.asarray(dr.grad(v))
    assert np.all(np.isfinite(g)), np.argwhere(~np.isfinite(g[..., 0])).tolist()
