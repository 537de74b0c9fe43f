"""pbr vs Mitsuba 3 (llvm_ad_spectral) through the statistical image test of docs/architecture.md.

Both renderers get the same scene dict and independent seeds; a biased pbr render
(albedo x1.02, one bounce fewer) must fail the same test."""

import numpy as np
import mitsuba as mi
import trimesh

import pbr
from pbr import validate
from mitsuba_scenes import gradient_png

RES, SPP, BATCHES = 24, 1024, 16


def small_box(scale=1, max_depth=6, hide_emitters=True):
    """The Cornell box at test size. Directly visible emitters are hidden by default: the
    light's spectral noise would dominate the variance of the image mean (0.72% vs 0.28%
    relative stderr at 256 spp), hiding a 2% bias; one test keeps it visible."""
    d = pbr.cornell_box(RES * scale, 16)
    d["integrator"] = {"type": "path", "max_depth": max_depth, "hide_emitters": hide_emitters}
    return d


def pbr_fn(d):
    scene = pbr.load_dict(d)
    return lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))


def check(d_pbr, d_mi, scale, expect_pass=True, spp=SPP):
    res = validate.compare_renders(pbr_fn(d_pbr), validate.mitsuba_render_fn(d_mi), spp=spp * scale,
                                   batches=BATCHES, seed_a=11, seed_b=12)
    print(res.summary())
    assert bool(res.passed) == expect_pass, res.summary()
    return res


def test_cornell_box_matches_mitsuba(scale):
    d = small_box(scale, hide_emitters=False)
    check(d, d, scale)


def test_cornell_box_indirect_matches_mitsuba(scale):
    d = small_box(scale)
    check(d, d, scale)


def test_checkerboard_and_bitmap_textures_match_mitsuba(tmp_path, scale):
    png = gradient_png(tmp_path)
    d = small_box(scale)
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {
        "type": "checkerboard", "color0": {"type": "rgb", "value": [0.8, 0.7, 0.2]},
        "color1": {"type": "rgb", "value": [0.1, 0.2, 0.6]},
        "to_uv": mi.ScalarTransform4f().scale([4, 4, 1])}}
    d["back"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": png}}
    check(d, d, scale)


def test_spectral_emitter_matches_mitsuba(scale):
    d = small_box(scale)
    d["light"]["emitter"]["radiance"] = {
        "type": "spectrum", "value": [(400.0, 2.0), (500.0, 14.0), (600.0, 25.0), (700.0, 8.0)]}
    check(d, d, scale)


def test_blackbody_emitter_matches_mitsuba(scale):
    d = small_box(scale)
    d["light"]["emitter"]["radiance"] = {"type": "blackbody", "temperature": 3000.0}
    check(d, d, scale)


def test_obj_mesh_matches_mitsuba(tmp_path, scale):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    path = str(tmp_path / "ico.obj")
    mesh.export(path)
    d = small_box(scale)
    del d["small-box"]
    d["ico"] = {"type": "obj", "filename": path,
                "to_world": mi.ScalarTransform4f().translate([0.35, -0.65, 0.3]),
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}}}
    check(d, d, scale)


def test_biased_albedo_fails(scale):
    d = small_box(scale)
    biased = small_box(scale)
    for k in ("white", "red", "green"):
        biased[k]["reflectance"]["value"] = [1.02 * v for v in biased[k]["reflectance"]["value"]]
    res = check(biased, d, scale, expect_pass=False)
    assert res.mean_ratio > 1.0


def test_one_bounce_fewer_fails(scale):
    d = small_box(scale, max_depth=4)
    short = small_box(scale, max_depth=3)
    res = check(short, d, scale, expect_pass=False)
    assert res.mean_ratio < 1.0
