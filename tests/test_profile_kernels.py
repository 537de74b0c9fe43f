"""``benchmarks/profile_kernels.py``'s register read-out of OptiX kernels (``ptxas_info``):
a PTX entry that calls an OptiX intrinsic (unresolved outside OptiX, so compiled with
``-c``) and carries Dr.Jit's ``.pragma "enable_smem_spilling"``, which ptxas refuses in
that mode ("not allowed for per-function compilation modes": what the H200 session got
for every OptiX kernel). Must fail: the same file given to ptxas unchanged gives that
error (checked here too)."""

import shutil
import subprocess
import sys

import pytest

from scripts import ROOT, load_script

PTX = """.version 8.7
.target sm_90
.address_size 64

.extern .func (.param .b32 r) _optix_trace_0 (.param .b64 a, .param .b32 b);

.entry __raygen__test()
{
    .reg .b32 %r<4>;
    .reg .b64 %rd<2>;
    .pragma "enable_smem_spilling";
    mov.u32 %r1, 1;
    mov.u64 %rd1, 0;
    {
    .param .b64 p0;
    .param .b32 p1;
    .param .b32 ret;
    st.param.b64 [p0], %rd1;
    st.param.b32 [p1], %r1;
    call.uni (ret), _optix_trace_0, (p0, p1);
    ld.param.b32 %r2, [ret];
    }
    ret;
}
"""

pytestmark = pytest.mark.skipif(shutil.which("ptxas") is None, reason="needs CUDA's ptxas")


def test_optix_ptx_with_smem_spilling_gives_registers(tmp_path):
    path = tmp_path / "k.ptx"
    path.write_text(PTX)
    raw = subprocess.run(["ptxas", "-arch=sm_90", "-v", "-c", str(path), "-o", "/dev/null"],
                         capture_output=True, text=True)
    assert raw.returncode != 0 and "enable_smem_spilling" in raw.stderr, raw.stderr
    sys.path.insert(0, str(ROOT / "benchmarks"))      # it imports bench_scenes
    info = load_script("benchmarks/profile_kernels.py").ptxas_info(str(path))
    print(info)
    assert info.startswith("registers max ") and "without enable_smem_spilling" in info, info
