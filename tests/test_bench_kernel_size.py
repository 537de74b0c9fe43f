"""``benchmarks/bench_kernel_size.py`` (issue 20, item 5: a kernel models only the
families a scene has) at 8 x 8, 1 spp: the Cornell box with three more BSDF/texture
families on unreachable tiny spheres renders the same image (same seed: equal means)
with a strictly larger kernel (LLVM IR and operations), and ``--quick`` prints its table.

Must fail: with the spheres placed inside the box (``FAR`` = 0, radius 0.1) the image check
fails; with ``with_all_bsdfs`` adding nothing the kernel-size check fails (both tried).
"""

import sys
from pathlib import Path

import pbr  # first: it chooses libLLVM before Dr.Jit loads
from scripts import load_script

ROOT = Path(__file__).resolve().parent.parent


def _bench():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    return load_script("benchmarks/bench_kernel_size.py")


def test_unreachable_families_grow_the_kernel_not_the_image():
    B = _bench()
    d = pbr.cornell_box(8, 1)
    d["integrator"] = {"type": "path", "max_depth": 4}
    base = B.first_render(pbr.load_dict(d), 1)
    more = B.first_render(pbr.load_dict(B.with_all_bsdfs(d, B.QUICK_MATERIALS)), 1)
    assert abs(more["mean"] / base["mean"] - 1.0) < 1e-4, (base["mean"], more["mean"])
    assert more["ir"] > 1.1 * base["ir"], (base["ir"], more["ir"])
    assert more["ops"] > base["ops"], (base["ops"], more["ops"])


def test_quick_table(capsys):
    B = _bench()
    res = B.main(["--quick", "--res", "8", "--backend", pbr.get_backend()])
    out = capsys.readouterr().out
    assert "+bsdfs+lights" in out and "aov+path" in out
    rows = {r["variant"]: r for r in res["cornell"]}
    assert rows["+bsdfs"]["ir_ratio"] > 1.1 and rows["+bsdfs+lights"]["ir_ratio"] > 1.0
    aov = {r["variant"]: r for r in res["aov (cornell)"]}
    assert aov["aov+path"]["ir"] > aov["path"]["ir"]
