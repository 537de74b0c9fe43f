"""Family dispatch (pbr.dispatch): one family without a switch, several with
``dr.switch``, and the per-lane form used by forward-mode derivatives."""

import numpy as np

import pbr
from pbr import dispatch
from mitsuba_scenes import lit_box


def _scene(all_conductor: bool):
    d = lit_box({"type": "roughconductor", "alpha": 0.25, "material": "Au"},
                {"type": "roughplastic", "alpha": 0.2}, lighting="point")
    if all_conductor:
        d["large-box"]["bsdf"] = {"type": "roughconductor", "alpha": 0.1, "material": "Ag"}
        for k in ("white", "green", "red"):
            d[k] = {"type": "roughconductor", "alpha": 0.5, "material": "Al"}
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 16
    return pbr.load_dict(d)


def test_scene_with_one_bsdf_family_renders():
    """A single family is called directly; its results must still have the shared
    types (a conductor's spectral weight is an Array4f, the path's throughput a
    Spectrum: the masked update used to raise a TypeError)."""
    scene = _scene(all_conductor=True)
    assert scene.bsdfs.order == ["roughconductor"]
    img = np.asarray(pbr.render(scene, spp=16, seed=1))
    assert np.all(np.isfinite(img)) and img.mean() > 1e-3


def test_per_lane_dispatch_renders_the_same_image_as_the_switch():
    scene = _scene(all_conductor=False)
    assert len(scene.bsdfs.order) >= 3
    a = np.asarray(pbr.render(scene, spp=16, seed=3))
    with dispatch.by_lane():
        b = np.asarray(pbr.render(scene, spp=16, seed=3))
    assert a.mean() > 1e-3
    assert np.allclose(a, b, rtol=1e-4, atol=1e-6), np.abs(a - b).max()


def test_light_family_that_traces_rays_is_called_outside_the_switch():
    """``directionalarea`` traces a ray in ``sample_Li``, so the light switch calls it on
    its own lanes (OptiX forbids tracing inside the callables of a switch; see
    test_no_rays_in_calls.py). The image equals the per-lane dispatch's, and the light
    contributes."""
    import mitsuba as mi
    T = mi.ScalarTransform4f
    d = pbr.cornell_box(16, 16)
    d["point"] = {"type": "point", "position": [0.2, 0.7, 0.6], "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}

    def with_panel(radiance):
        d["panel"] = {"type": "rectangle", "to_world": T().translate([0, 0.9, 0]).rotate([1, 0, 0], 90).scale(0.3),
                      "emitter": {"type": "directionalarea", "radiance": {"type": "rgb", "value": [radiance] * 3}}}
        return pbr.load_dict(d)
    without = np.asarray(pbr.render(with_panel(0.0), spp=16, seed=3))
    scene = with_panel(20.0)
    assert sorted(scene.lights.order) == ["area", "directionalarea", "point"]
    a = np.asarray(pbr.render(scene, spp=16, seed=3))
    with dispatch.by_lane():
        b = np.asarray(pbr.render(scene, spp=16, seed=3))
    assert np.allclose(a, b, rtol=1e-4, atol=1e-6), np.abs(a - b).max()
    assert a.mean() > 1.2 * without.mean()


def _when_any_result(mask_from):
    import drjit as dr
    import mitsuba as mi
    x = dr.arange(mi.Float, 64)
    mask = x >= mask_from
    return x, mask, dispatch.when_any(mask, lambda: (x * 2.0, mi.UInt32(x) + 1), otherwise=(mi.Float(-1.0), mi.UInt32(7)))


def test_when_any_skips_packets_without_a_lane():
    """Lanes of ``mask`` get the function's value; a vector packet with none of them
    (the first 8 lanes: packets are 8 or 16 wide on the CPU) gets ``otherwise``, which
    shows that the code was skipped there, not computed and discarded."""
    x, mask, (a, b) = _when_any_result(40.0)
    x, mask, a, b = (np.asarray(v) for v in (x, mask, a, b))
    assert np.array_equal(a[mask], 2 * x[mask]) and np.array_equal(b[mask], x[mask].astype(np.uint32) + 1)
    assert np.all(a[:8] == -1.0) and np.all(b[:8] == 7)
    with dispatch.whole_packets():
        _, _, (a2, _) = _when_any_result(40.0)
    assert np.array_equal(np.asarray(a2), 2 * x)      # computed on every packet


def test_when_any_with_a_literal_mask():
    """A literal False mask (a path tracer without next-event estimation) traces only
    the skipped branch; zeros shaped like the function's result when ``otherwise`` is
    None."""
    import drjit as dr
    import mitsuba as mi
    x = dr.arange(mi.Float, 16)
    r = dispatch.when_any(mi.Bool(False), lambda: (x + 1.0, mi.Vector3f(x, x, x)))
    assert np.all(np.asarray(r[0]) == 0) and np.all(np.asarray(r[1]) == 0)
    r = dispatch.when_any(mi.Bool(True), lambda: x + 1.0)
    assert np.array_equal(np.asarray(r), np.arange(16) + 1.0)
