"""benchmarks/ir_liveness.py (values live across a kernel's ray-tracing calls) and the
path tracer's kernel layout it measures: the shadow ray is traced after the path's next
ray is built, where fewer values are live across the trace (docs/performance.md)."""

import os
import re
import sys

import drjit as dr
import numpy as np
import pytest

import pbr

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import ir_liveness  # noqa: E402

SMALL = """
define void @drjit_0(i64 %start, i64 %end, i32 %thread_id, ptr noalias %params) #0 {
entry:
    %rd1 = load ptr, ptr %params, align 8
    %buffer = alloca i8, i32 64, align 64
    %f8_1 = insertelement <16 x float> undef, float 0x3ff0000000000000, i32 0
    %f8 = shufflevector <16 x float> %f8_1, <16 x float> undef, <16 x i32> zeroinitializer
    br label %l_2_cond

l_2_cond:
    %f2 = phi <16 x float> [ zeroinitializer, %entry ], [ %f6, %l_2_body ]
    %p3 = fcmp olt <16 x float> %f2, zeroinitializer
    %b3 = call i1 @llvm.vector.reduce.or.v16i1(<16 x i1> %p3)
    br i1 %b3, label %l_2_body, label %l_2_done

l_2_body:
    %f4 = fadd <16 x float> %f2, %f2
    %f5 = fmul <16 x float> %f2, %f2

    ; -------- Ray test -------
    %u7_in_0_1 = getelementptr inbounds i8, ptr %buffer, i32 0
    store <16 x float> %f5, ptr %u7_in_0_1, align 64
    call void %rd1(ptr %u7_in_0_1, ptr %rd1, ptr %u7_in_0_1, ptr %u7_in_0_1)
    %f9 = fadd <16 x float> %f4, %f2
    %f6 = fmul <16 x float> %f9, %f8
    br label %l_2_cond

l_2_done:
    ret void
}
"""


def test_liveness_of_a_small_loop():
    """Across the call: %f2 and %f4 (used after it), the broadcast constant %f8 (a uniform
    vector), %rd1 and %buffer (used by the next iteration); not %f5 (last used before it),
    %f6 (defined after it) or the mask %p3."""
    (t,) = ir_liveness.trace_liveness(SMALL)
    assert t.kind == "test" and t.block == "l_2_body"
    assert t.live["float"] == 2 and t.live["mask"] == 0 and t.live["uniform float"] == 1
    assert t.live["scalar"] == 2                       # %rd1 and %buffer
    (c,) = ir_liveness.trace_calls(ir_liveness.parse(SMALL))
    assert (c.kind, c.block, c.inputs) == ("test", "l_2_body", {0: "%f5"})


def test_no_kernel_is_an_error():
    with pytest.raises(ValueError, match="no Dr.Jit kernel"):
        ir_liveness.trace_liveness("define void @f() {\n}\n")


def _kernel_ir(scene, spp=4):
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        img = np.asarray(pbr.render(scene, spp=spp, seed=0, progress=False))
        h = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    jit = [k for k in h if k["type"] == dr.KernelType.JIT and "ir" in k]
    return img, max(jit, key=lambda k: k.get("operation_count", 0))["ir"].getvalue()


@pytest.mark.skipif(pbr.get_backend() != "llvm", reason="reads the LLVM IR of the path kernel")
def test_path_traces_the_shadow_ray_after_the_next_ray():
    """In the path tracer's megakernel the shadow ray (Embree's occlusion call) comes after
    the direction of the path's next ray is computed: the next-iteration values of the
    closest-hit call's direction inputs are defined before the shadow-ray call. With the
    trace where the depth-first schedule puts it (right after the light sample, before
    the BSDF is sampled) this fails, and 6 more per-lane float vectors (and 2 uniform
    ones) are live across it."""
    d = pbr.cornell_box(16, 4)
    d["integrator"] = {"type": "path", "max_depth": 4}
    _, ir = _kernel_ir(pbr.load_dict(d))
    k = ir_liveness.parse(ir)
    pos, defs, start, n = {}, {}, {}, 0
    for name, instrs in k.blocks.items():
        start[name] = n
        for i in instrs:
            if i.defines:
                pos[i.defines], defs[i.defines] = n, i
            n += 1
    calls = ir_liveness.trace_calls(k)
    (trace,) = [c for c in calls if c.kind == "trace"]
    (test,) = [c for c in calls if c.kind == "test"]
    for slot in (5, 6, 7):                              # the ray direction's x, y, z
        phi = defs[trace.inputs[slot]]
        assert phi.incoming, f"the closest-hit call's direction {trace.inputs[slot]} is not a loop variable"
        nxt = [v for v, b in phi.incoming if not b.endswith("_before")][0]
        # the loop keeps finished lanes' values: select(active, new value, old value)
        m = re.match(r"%[\w.]+ = select <16 x i1> %[\w.]+, <16 x float> (%[\w.]+),", defs[nxt].text)
        new = m.group(1) if m else nxt
        assert pos[new] < start[test.block] + test.index, \
            f"the next ray's direction ({new}) is computed after the shadow-ray call"
    live = {t.kind: t.live for t in ir_liveness.trace_liveness(ir)}
    print(f"float vectors live across the closest-hit call {live['trace']['float']}, "
          f"the shadow-ray call {live['test']['float']}")


@pytest.mark.skipif(pbr.get_backend() != "llvm", reason="reads the LLVM IR of the path kernel")
def test_gathered_area_light_ablation():
    """profile_kernels' ``gathered-area-light``: the Cornell box's one light, its tables
    doubled, renders the same image bit for bit, and its 13 values (3 corners, the normal,
    the area: uniform vectors, loaded once before the loop) are no longer live across
    either ray-tracing call; the per-lane float vectors there stay the same."""
    import profile_kernels
    d = pbr.cornell_box(16, 4)
    d["integrator"] = {"type": "path", "max_depth": 4}
    img0, ir0 = _kernel_ir(pbr.load_dict(d))
    img1, ir1 = _kernel_ir(profile_kernels._gathered_area_light(pbr.load_dict(d)))
    assert np.array_equal(img0, img1) and img0.mean() > 0.01
    f0, f1 = ([(t.live["float"], t.live["uniform float"]) for t in ir_liveness.trace_liveness(ir)] for ir in (ir0, ir1))
    print(f"(float, uniform) vectors live across the traces: {f0} -> {f1}")
    assert [(a[0] - b[0], a[1] - b[1]) for a, b in zip(f0, f1)] == [(0, 13), (0, 13)]
    with pytest.raises(ValueError, match="one area light"):
        profile_kernels._gathered_area_light(pbr.load_dict(_no_area_light()))


def _no_area_light():
    return {"type": "scene", "integrator": {"type": "path"},
            "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8}},
            "light": {"type": "point", "position": [0, 0, 2], "intensity": 1.0},
            "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"}}}
