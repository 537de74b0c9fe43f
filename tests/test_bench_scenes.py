"""``benchmarks/bench_scenes.py``'s memory figures: :func:`kept_by` sees what a render
leaves allocated (Mitsuba's film block stays between renders, so a later render does
not add it), :func:`memory_of` the peak a call adds. Must fail: an array kept alive is
counted (1 MiB), a temporary one is not (its peak is)."""

import sys

import drjit as dr
import mitsuba as mi
import pytest

from scripts import ROOT, load_script


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    return load_script("benchmarks/bench_scenes.py")


def test_memory_kept_between_renders_and_peak_added(bench):
    n = 1 << 18                                     # 1 MiB of float32
    kept = []

    def keeps():
        a = dr.arange(mi.Float, n)
        dr.eval(a)
        kept.append(a)

    def temporary():
        a = dr.arange(mi.Float, n) + 2.0
        dr.eval(a)
        return float(a[0])

    assert bench.kept_by(keeps) == pytest.approx(1.0, abs=0.02)
    assert bench.kept_by(temporary) == pytest.approx(0.0, abs=0.02)
    rss, jit = bench.memory_of(temporary)
    assert jit == pytest.approx(1.0, abs=0.1), jit
    kept.clear()
