"""Renders that cannot fit are refused before launch with a clear error (pbr.memory):
Dr.Jit's 2^32-entry array limit and the memory available (issue 18: a 30000^2 film under
a 6 GB address-space limit ended in a segmentation fault inside Dr.Jit)."""

import subprocess
import sys
import textwrap

import pytest

import pbr
from pbr import memory


def test_arrays_over_dr_jit_limit_are_refused():
    scene = pbr.load_dict(pbr.cornell_box(50000, 1))
    with pytest.raises(ValueError, match=r"sensor 0: a 50000 x 50000 film needs 10,000,000,000 film entries.*"
                                         r"2\^32 - 1"):
        pbr.render(scene)


def test_film_over_available_memory_is_refused(monkeypatch):
    monkeypatch.setattr(memory, "available_bytes", lambda: 1 << 30)
    with pytest.raises(MemoryError, match=r"sensor 0: a 9000 x 9000 film with 4 channels needs [\d.]+ GiB, and "
                                          r"1.0 GiB are available"):
        pbr.render(pbr.load_dict(pbr.cornell_box(9000, 1)))
    pbr.render(pbr.load_dict(pbr.cornell_box(16, 1)))          # a small one still renders
    monkeypatch.setattr(memory, "available_bytes", lambda: None)   # unknown: only the entry limit
    memory.check_render(9000, 9000, 1, 4, "sensor 0")


@pytest.mark.parametrize("integrator", ["bdpt", "sppm", "mlt"])
def test_path_state_is_counted(monkeypatch, integrator):
    """Integrators that keep per-path state between kernels (bytes_per_lane) are checked
    with it: a 2048^2 film alone (176 MiB) is too small to be checked, but with bdpt's
    subpaths (2.4 GiB more), sppm's visible points (1.6 GiB) or mlt's float64 splat film
    (0.4 GiB) it does not fit in 512 MiB (before, these renders started; see the
    address-space test for the crash that followed)."""
    monkeypatch.setattr(memory, "available_bytes", lambda: 1 << 29)
    d = pbr.cornell_box(2048, 1)
    d["integrator"] = {"type": integrator}
    with pytest.raises(MemoryError, match=r"sensor 0: a 2048 x 2048 film with 4 channels and 4,194,304 paths "
                                          r"needs [\d.]+ GiB, and 0.5 GiB are available"):
        pbr.render(pbr.load_dict(d), spp=1)


def test_film_bytes_follow_dr_jit_allocations():
    # 11000^2 rendered under a 6 GiB address-space limit (5.6 GiB left), 12000^2 crashed.
    assert memory.film_bytes(11000, 11000, 4) < 5.6 * 2**30 < memory.film_bytes(12000, 12000, 4)


@pytest.mark.skipif(pbr.get_backend() != "llvm", reason="an address-space limit bounds host memory only")
@pytest.mark.parametrize("integrator, res", [("path", 30000), ("bdpt", 3200), ("sppm", 4000), ("mlt", 30000)])
def test_no_segfault_under_an_address_space_limit(integrator, res):
    """Each of these ended in a segmentation fault under a 6 GiB limit (bdpt 3200^2 and
    sppm 4000^2 after the film check alone had let them start; mlt was not checked)."""
    code = textwrap.dedent(f"""
        import resource, pbr
        pbr.set_backend({pbr.get_backend()!r})
        resource.setrlimit(resource.RLIMIT_AS, (6 << 30, resource.RLIM_INFINITY))
        d = pbr.cornell_box({res}, 1)
        d["integrator"] = {{"type": {integrator!r}}}
        try:
            pbr.render(pbr.load_dict(d), spp=1)
        except MemoryError as e:
            print("refused:", e)
    """)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    assert f"refused: sensor 0: a {res} x {res} film" in p.stdout
