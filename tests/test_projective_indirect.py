"""The indirect boundary term of ``prb_projective`` beyond the first hit: a discontinuity
seen only after two bounces (a shadow seen in a reflection).

Scene: the camera looks down at a floor that reflects a diffuse wall standing behind it;
a small lamp to the side lights the wall at a grazing angle, and a black sphere (the
occluder, key 'obj') between them casts a long shadow on the wall. Neither the wall nor
the occluder is in the camera's view, and the occluder is outside the mirror's too: what
moves when the occluder is translated along x is its shadow, seen via the floor, i.e. from
the camera path's second vertex (on the wall). Gradients are d <ramp, image> / dx over
independent batches, compared by a z-score with both sides' standard errors (the helpers
of test_ad_geometry.py) against central finite differences. Must-fail: the same
gradient with the term limited to the first hit (``indirect_depth`` 1) is rejected.
"""

from __future__ import annotations

import mitsuba as mi
import pytest

import pbr
from test_ad_analytic_silhouettes import BLACK, _pbr
from test_ad_geometry import Z_MAX, _z, ad_batches, fd_batches

T = mi.ScalarTransform4f


def shadow_in_a_reflection(res=16, floor="glossy", **integrator):
    """The scene above; ``floor``: 'glossy' (rough conductor, alpha 0.1) or 'mirror'
    (smooth conductor reflecting 60%: the camera subpath's throughput weighs the term);
    ``integrator``: prb_projective's parameters (max_depth 3: the
    wall's light is direct)."""
    bsdf = {"type": "roughconductor", "alpha": 0.1} if floor == "glossy" else {
        "type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.6]}}
    return {"type": "scene", "integrator": {"type": "prb_projective", "max_depth": 3, **integrator},
            "sensor": {"type": "perspective", "fov": 30, "to_world": T().look_at([0, -2, 1.5], [0, 0, 0], [0, 0, 1]),
                       "film": {"type": "hdrfilm", "width": res, "height": res}},
            "obj": {"type": "sphere", "radius": 0.3, "center": [2.0, 1.6, 2.0], "bsdf": BLACK},
            "wall": {"type": "rectangle", "to_world": T().translate([0, 2, 2]).rotate([1, 0, 0], 90).scale([3, 2, 1]),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}}},
            "floor": {"type": "rectangle", "to_world": T().scale(3), "bsdf": bsdf},
            "lamp": {"type": "rectangle", "to_world": T().look_at([3.5, 1.2, 2.0], [0.5, 2.0, 2.0], [0, 0, 1]).scale(0.1),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [200.0, 200.0, 200.0]}}}}


def test_indirect_depth_parameter():
    """Which vertices the indirect term projects from: up to max_depth - 1, at most
    indirect_depth; direct_projective's is the first hit."""
    def depth(**kw):
        return pbr.load_dict(shadow_in_a_reflection(**kw)).integrator._projection_depth()

    assert depth() == 2 and depth(indirect_depth=1) == 1 and depth(max_depth=6, indirect_depth=3) == 3
    assert depth(max_depth=-1, indirect_depth=4) == 4 and depth(max_depth=-1) > 1000
    assert depth(type="direct_projective", max_depth=5) == 1
    with pytest.raises(pbr.SceneError, match="indirect_depth.*>= 1, got 0"):
        depth(indirect_depth=0)


def test_shadow_in_a_reflection_forward_equals_reverse():
    """Forward and reverse mode on the same samples (the indirect term only, both
    depths)."""
    res = 12
    render, mover = _pbr(shadow_in_a_reflection(res, sppc=0, sppp=0))
    fwd = ad_batches(render, mover, res, 1, 16, "forward")
    rev = ad_batches(render, mover, res, 1, 16, "reverse")
    assert abs(rev) > 0.5 and abs(fwd - rev) < 1e-3 * abs(rev), (fwd, rev)


def test_shadow_seen_in_a_mirror():
    """A smooth conductor floor reflecting 60%: nothing is projected from the mirror (a
    delta lobe), the camera path goes on to the wall and the term projects from there,
    weighted by the mirror's 0.6. Measured (16x16): FD -3.437 +- 0.009 (8x4096, step
    0.04); pbr -3.50 +- 0.08 (8x1024), -3.390 +- 0.043 (32x1024); with the term limited
    to the first hit (indirect_depth 1, the term before this test) exactly 0; with the
    subpath's weight left out -5.8 (must-fail checked)."""
    res = 16
    render, mover = _pbr(shadow_in_a_reflection(res, "mirror"))
    fd = fd_batches(render, mover, res, 8, 4096, h=0.04)
    ad = ad_batches(render, mover, res, 8, 1024)
    first_hit, mover1 = _pbr(shadow_in_a_reflection(res, "mirror", indirect_depth=1))
    no_depth_2 = ad_batches(first_hit, mover1, res, 2, 64)
    print(f"shadow in a mirror: pbr {ad}, FD {fd}, first hit only {no_depth_2}")
    assert abs(fd[0]) > 2.0 and _z(ad, fd) < Z_MAX and abs(ad[0] - fd[0]) < 0.1 * abs(fd[0]), (ad, fd)
    assert _z(no_depth_2, fd) > 3 * Z_MAX, (no_depth_2, fd)


@pytest.mark.slow
def test_shadow_seen_in_a_glossy_floor():
    """A rough conductor floor (alpha 0.1): both vertices have a non-delta lobe. The
    first hit contributes too (the occluder seen at the edge of the floor's glossy lobe:
    +1.13 +- 0.05 with indirect_depth 1, rejected), the shadow on the wall the rest."""
    res = 16
    render, mover = _pbr(shadow_in_a_reflection(res))
    fd = fd_batches(render, mover, res, 4, 2048, h=0.04)
    ad = ad_batches(render, mover, res, 8, 1024, seed0=700)
    first_hit, mover1 = _pbr(shadow_in_a_reflection(res, indirect_depth=1))
    no_depth_2 = ad_batches(first_hit, mover1, res, 4, 256)
    print(f"shadow in a glossy floor: pbr {ad}, FD {fd}, first hit only {no_depth_2}")
    assert _z(ad, fd) < Z_MAX and abs(ad[0] - fd[0]) < 0.2 * abs(fd[0]), (ad, fd)
    assert _z(no_depth_2, fd) > 3 * Z_MAX, (no_depth_2, fd)


def test_finely_tessellated_light_keeps_the_edge_weights_small(tmp_path, monkeypatch):
    """An emissive mesh of many vertices (the Mitsuba tutorials' sphere.obj has 16,258)
    marks its shadow-casting edges from at most LIGHT_VIEWPOINTS of its vertices and its
    centroid: one silhouette test per vertex built a kernel that did not finish tracing in
    6 minutes (object_pose_estimation)."""
    import drjit as dr
    from pbr.integrators import projective
    n = 12                                    # a 12 x 12 vertex grid: 144 vertices
    lines = [f"v {i / (n - 1) * 2 - 1} {j / (n - 1) * 2 - 1} 0" for j in range(n) for i in range(n)]
    lines += [f"f {j * n + i + 1} {j * n + i + 2} {(j + 1) * n + i + 2} {(j + 1) * n + i + 1}"
              for j in range(n - 1) for i in range(n - 1)]
    (tmp_path / "grid.obj").write_text("\n".join(lines) + "\n")
    d = shadow_in_a_reflection(res=4)
    d["lamp"] = {"type": "obj", "filename": str(tmp_path / "grid.obj"), "to_world": d["lamp"]["to_world"],
                 "emitter": d["lamp"]["emitter"]}
    calls, inside = [], []
    silhouette, distribution = projective.silhouette, projective.ProjectivePathIntegrator._edge_distribution

    def counted(*a):
        calls.append(bool(inside))
        return silhouette(*a)

    def edge_distribution(*a):
        inside.append(1)
        try:
            return distribution(*a)
        finally:
            inside.pop()
    monkeypatch.setattr(projective, "silhouette", counted)
    monkeypatch.setattr(projective.ProjectivePathIntegrator, "_edge_distribution", edge_distribution)
    scene = pbr.load_dict(d)
    p = pbr.traverse(scene)
    dr.enable_grad(p["wall.to_world"])
    p.update()
    img = pbr.render(scene, p, spp=1)
    dr.backward(dr.sum(img, axis=None))
    marked = sum(calls)                       # the light's viewpoints: vertices + centroid
    assert 0 < marked <= projective.LIGHT_VIEWPOINTS + 1, marked
