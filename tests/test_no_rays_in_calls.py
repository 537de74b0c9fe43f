"""No ray is traced inside a symbolic call (``dr.switch`` over BSDF/light families).

On CUDA, Dr.Jit compiles a symbolic call over several functions into OptiX *direct
callables*, and OptiX forbids ``optixTrace`` in those (its programming guide; it may
appear to work, but is unsanctioned). The LLVM backend shows the same structure: a
symbolic call becomes LLVM functions (``@func_...``), and Mitsuba's ray queries are
marked in the IR (``-------- Ray trace``/``Ray test``). Every integrator renders a scene
whose lights include a ``directionalarea`` (its ``sample_Li`` traces a ray) beside
other light families, and the kernels' IR must have no ray query inside a function.
Must fail: with the light dispatch tracing inside the switch again, the check finds it.
"""

import re

import drjit as dr
import mitsuba as mi
import pytest

import pbr
from pbr.lights.directionalarea import DirectionalAreaLight

INTEGRATORS = ["path", "prb", "direct", "whitted", "volpath", "volpathmis", "prbvolpath", "simplevolpath",
               "ptracer", "lightpath", "bdpt", "sppm", "randomwalk", "simplepath", "ambientocclusion", "aov"]


def _scene(integrator):
    T = mi.ScalarTransform4f
    d = pbr.cornell_box(8, 1)
    d["integrator"] = {"type": integrator}
    if integrator == "aov":
        d["integrator"]["aovs"] = "d:depth"
    d["point"] = {"type": "point", "position": [0.2, 0.7, 0.6], "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    d["panel"] = {"type": "rectangle", "to_world": T().translate([0, 0.9, 0]).rotate([1, 0, 0], 90).scale(0.1),
                  "emitter": {"type": "directionalarea", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}
    return d


def ray_queries_in_calls(ir: str) -> tuple[int, int]:
    """(ray queries inside functions of symbolic calls, all ray queries) in LLVM IR."""
    inside = total = 0
    in_call = False
    for line in ir.splitlines():
        if line.startswith("define "):
            in_call = re.search(r"@func_", line) is not None
        elif line.startswith("}"):
            in_call = False
        elif re.search(r"-------- Ray (trace|test)", line):
            total += 1
            inside += in_call
    return inside, total


def _ir_of_render(d, capfd):
    scene = pbr.load_dict(d)
    capfd.readouterr()
    with dr.scoped_set_flag(dr.JitFlag.PrintIR, True):
        dr.eval(pbr.render(scene, spp=1, seed=0))
        dr.sync_thread()
    out = capfd.readouterr()
    return out.out + out.err


pytestmark = pytest.mark.skipif(pbr.get_backend() != "llvm", reason="reads the LLVM backend's IR")


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_no_ray_query_inside_a_symbolic_call(integrator, capfd):
    inside, total = ray_queries_in_calls(_ir_of_render(_scene(integrator), capfd))
    assert total > 0, "no kernel IR captured"
    assert inside == 0, f"{inside} of {total} ray queries inside a symbolic call"


def test_must_fail_a_ray_query_in_the_light_switch_is_found(monkeypatch, capfd):
    monkeypatch.setattr(DirectionalAreaLight, "traces_rays_in", ())
    inside, total = ray_queries_in_calls(_ir_of_render(_scene("path"), capfd))
    assert inside >= 1 and total > inside
