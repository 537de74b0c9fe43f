"""Shape identification of ray hits (``pbr.geometry.Geometry``), on both ray tracers.

A hit must be mapped to pbr's own shape (its BSDF, emitter and media). Measured on an
H100: OptiX leaves ``PreliminaryIntersection.shape_index`` at a literal 0, so a map
through it made every hit shape 0 (the Cornell box 95x too bright). The shape pointer is
filled in on both backends and holds the shape's Dr.Jit registry id; those ids follow
the order in which Mitsuba objects were created, not the scene's shape order. The scene
here makes the two orders differ on the CPU (meshes and curves read from files exist
before the scene's other shapes), and ``optix_like`` gives the LLVM backend OptiX's
empty ``shape_index``, so these tests fail on the CPU for a map that would fail on CUDA.
"""

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr
from pbr.geometry import Geometry

SPACING = 2.0
# pbr's shapes along x, in the scene dict's order: (id, type).
SHAPES = [("panel", "rectangle"), ("quad", "obj"), ("ball", "sphere"), ("box", "cube"),
          ("lamp", "disk"), ("fibre", "bsplinecurve"), ("tile", "obj")]


def _scene_dict(tmp_path, spp=4):
    T = mi.ScalarTransform4f
    quad = tmp_path / "quad.obj"
    quad.write_text("v -0.4 -0.4 0\nv 0.4 -0.4 0\nv 0.4 0.4 0\nv -0.4 0.4 0\nf 1 2 3\nf 1 3 4\n")
    fibre = tmp_path / "fibre.txt"
    fibre.write_text("".join(f"0 {y:.3f} 0 0.15\n" for y in np.linspace(-0.6, 0.6, 6)))
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 50, "fov_axis": "x",      # the row of shapes
                   "to_world": T().look_at(origin=[6, -2, 14], target=[6, 0, 0], up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": spp},
                   "film": {"type": "hdrfilm", "width": 48, "height": 10}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}},
    }
    for i, (name, kind) in enumerate(SHAPES):
        at = T().translate([i * SPACING, 0, 0])
        s = {"type": kind, "bsdf": {"type": "diffuse",
                                    "reflectance": {"type": "rgb", "value": [0.1 + 0.1 * i, 0.5, 0.9 - 0.1 * i]}}}
        if kind == "obj":
            s.update(filename=str(quad), to_world=at)
        elif kind == "bsplinecurve":
            s.update(filename=str(fibre), to_world=at)
        else:
            s["to_world"] = at @ T().scale(0.4)
        if name in ("panel", "ball", "lamp", "tile"):   # (ball and lamp: sampled through Mitsuba)
            s["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [1.0 + i, 2.0, 3.0]}}
        d[name] = s
    return d


@pytest.fixture
def scene(tmp_path):
    return pbr.load_dict(_scene_dict(tmp_path))


class OptixLikeScene:
    """A Mitsuba scene whose preliminary intersections leave ``shape_index`` as OptiX
    does (a width-1 literal 0); everything else is the wrapped scene's."""

    def __init__(self, mi_scene):
        self._scene = mi_scene

    def ray_intersect_preliminary(self, ray, coherent=False, active=True):
        pi = self._scene.ray_intersect_preliminary(ray, coherent, active)
        pi.shape_index = mi.UInt32(0)
        return pi

    def __getattr__(self, name):
        return getattr(self._scene, name)


def optix_like(monkeypatch, scene):
    monkeypatch.setattr(scene.geometry, "mi_scene", OptixLikeScene(scene.geometry.mi_scene))


def _old_intersect(self, ray, active, attached=False, ray_ad=None, coherent=False):
    """The route pbr took before: ``shape_index`` (filled in by Embree only); the
    derivative and coherence arguments of ``Geometry.intersect`` are accepted and unused."""
    pi = self.mi_scene.ray_intersect_preliminary(ray, False, active)
    return pi.compute_surface_interaction(ray, mi.RayFlags.All, active), pi.shape_index


def wrong_hits(scene, n=16):
    """Rays aimed straight down at each shape's middle (jittered); returns (hits, hits
    attributed to another shape than the one aimed at). The expected shape comes from
    the scene description, not from ``Geometry``."""
    rng = np.random.default_rng(1)
    k = len(SHAPES)
    target = np.repeat(np.arange(k), n)
    x = target * SPACING + rng.uniform(-0.1, 0.1, k * n)
    y = rng.uniform(-0.1, 0.1, k * n)
    ray = mi.Ray3f(mi.Point3f(mi.Float(x), mi.Float(y), 5.0), mi.Vector3f(0, 0, -1))
    si, shape = scene.geometry.intersect(ray, mi.Bool(True))
    valid = np.array(si.is_valid())
    shape = np.broadcast_to(np.array(shape), valid.shape)
    expected = np.array([scene.shape_ids.index(SHAPES[t][0]) for t in target])
    return int(valid.sum()), int((valid & (shape != expected)).sum())


def test_registry_ids_are_not_in_shape_order(scene):
    """The premise of the other tests: mapping by position (shape_index) or by registry
    id - 1 would both be wrong here."""
    reg = np.array(dr.reinterpret_array(mi.UInt32, scene.mi_scene.shapes_dr()))
    assert len(reg) == len(SHAPES)
    assert not np.array_equal(reg, np.sort(reg)), reg
    assert not np.array_equal(np.argsort(reg), np.arange(len(reg)))


def test_every_hit_maps_to_its_shape(scene):
    hits, wrong = wrong_hits(scene)
    assert hits == 16 * len(SHAPES) and wrong == 0


def test_every_hit_maps_to_its_shape_when_shape_index_is_empty(scene, monkeypatch):
    optix_like(monkeypatch, scene)
    hits, wrong = wrong_hits(scene)
    assert hits == 16 * len(SHAPES) and wrong == 0


def test_must_fail_wrong_maps_are_caught(scene, monkeypatch):
    """The check catches the old shape_index route under OptiX's behaviour, a permuted
    table and a map by registry id - 1."""
    with monkeypatch.context() as m:
        optix_like(m, scene)
        m.setattr(Geometry, "intersect", _old_intersect)
        assert wrong_hits(scene)[1] == (len(SHAPES) - 1) * 16    # all but shape 0's hits
    table = np.array(scene.geometry.shape_of_id)
    reg = np.array(dr.reinterpret_array(mi.UInt32, scene.mi_scene.shapes_dr()))
    swapped = table.copy()
    swapped[reg[[2, 5]]] = table[reg[[5, 2]]]
    with monkeypatch.context() as m:
        m.setattr(scene.geometry, "shape_of_id", mi.UInt32(swapped))
        assert wrong_hits(scene)[1] == 2 * 16
    with monkeypatch.context() as m:
        m.setattr(Geometry, "shape_of",
                  lambda self, ptr, active: dr.reinterpret_array(mi.UInt32, ptr) - 1)
        assert wrong_hits(scene)[1] > 0


def test_render_is_the_same_when_shape_index_is_empty(tmp_path, monkeypatch):
    """A path-traced image (emitters, BSDFs, NEE shadow rays on every shape type) does
    not change when the ray tracer leaves shape_index empty; with the old route it does."""
    scene = pbr.load_dict(_scene_dict(tmp_path))
    ref = np.asarray(pbr.render(scene, seed=3, spp=32))
    assert ref.mean() > 0
    optix_like(monkeypatch, scene)
    assert np.array_equal(np.asarray(pbr.render(scene, seed=3, spp=32)), ref)
    monkeypatch.setattr(Geometry, "intersect", _old_intersect)
    old = np.asarray(pbr.render(scene, seed=3, spp=32))
    on_shapes = np.abs(ref - ref[0, 0]).max(axis=2) > 0.15      # pixels that show a shape
    assert on_shapes.mean() > 0.1
    assert (np.abs(old - ref)[on_shapes] > 0.1 * ref[on_shapes]).mean() > 0.3   # measured: 0.44
