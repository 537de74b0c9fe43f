"""``benchmarks/ray_counts.py`` (Embree queries per render, pbr vs Mitsuba, through an
``LD_PRELOAD`` shim) on door at 16x16, 4 spp, max_depth 3: both renderers trace the same
closest-hit lanes (camera rays and bounces: the same paths' lengths), and pbr traces far
fewer shadow rays than Mitsuba (it skips light samples whose estimate is zero,
``integrators.base.light_reaches``; measured 0.59x at 64x64). Must fail: with every
sampled lane traced again (``skip_zero=False``), pbr's shadow lanes are 0.93x Mitsuba's
(only the back-of-the-light samples fewer) and the check fails."""

import os
import re
import shutil
import subprocess
import sys

import pytest

import pbr
from scripts import ROOT

pytestmark = [pytest.mark.skipif(shutil.which("cc") is None, reason="needs a C compiler for the shim"),
              pytest.mark.skipif(pbr.get_backend() != "llvm", reason="counts Embree (CPU) queries")]


def _counts(extra_env=None):
    env = dict(os.environ, **(extra_env or {}))
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "ray_counts.py"), "--scenes", "door", "--res", "16",
                        "--spp", "4", "--max-depth", "3"], capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = {}
    for line in r.stdout.splitlines():
        m = re.match(r"door\s+(pbr|mi)\s+([\d,]+)\s+[\d.]+\s+[\d.]+\s+[\d.]+\s+\d+\s+([\d,]+)", line)
        if m:
            rows[m[1]] = (int(m[2].replace(",", "")), int(m[3].replace(",", "")))
    assert set(rows) == {"pbr", "mi"}, r.stdout
    return rows


def test_pbr_traces_fewer_shadow_rays_than_mitsuba_on_door():
    rows = _counts()
    (shadow_p, hit_p), (shadow_m, hit_m) = rows["pbr"], rows["mi"]
    print(f"shadow-ray lanes pbr {shadow_p}, Mitsuba {shadow_m}; closest-hit lanes {hit_p} / {hit_m}")
    assert shadow_m == 16 * 16 * 4 * 2            # Mitsuba: every lane at both NEE vertices
    assert abs(hit_p - hit_m) <= 0.01 * hit_m
    assert shadow_p < 0.75 * shadow_m
