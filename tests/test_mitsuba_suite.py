"""``benchmarks/mitsuba_suite.py``: Mitsuba's render-test criterion (test_renders.py) as
the runner applies it, on synthetic images whose answer is known, and on real scenes of
Mitsuba's suite when its data is there (``PBR_MITSUBA_DATA``: a checkout of
``mitsuba-renderer/mitsuba-data``; skipped otherwise: the data is Mitsuba's, not pbr's).

Must fail: a biased image (20% too bright, or a checkerboard with its squares swapped)
fails the criterion; 0.3% of pixels wrong fails it, 0.2% does not.
"""

import math
import os

import numpy as np
import pytest

import pbr  # noqa: F401  (chooses libLLVM before Dr.Jit loads)
from scripts import load_script

DATA = os.environ.get("PBR_MITSUBA_DATA", "")


def _suite():
    return load_script("benchmarks/mitsuba_suite.py", register=True)


suite = _suite()
H = W = 48
SPP = 2_000_000 // (H * W)


def _synthetic(seed=0):
    """A reference with a checker pattern, its per-sample variance, and an unbiased
    'render' (the reference plus the noise of an SPP-sample mean)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:H, 0:W]
    checker = ((x // 8 + y // 8) % 2).astype(np.float64)
    ref = np.stack([0.2 + 0.6 * checker, 0.3 + 0.2 * checker, 0.5 - 0.3 * checker], -1)
    var = 0.5 * ref + 0.01
    img = ref + rng.standard_normal(ref.shape) * np.sqrt(var / SPP)
    return ref, var, img, checker


def test_judge_accepts_noise_and_rejects_bias():
    ref, var, img, checker = _synthetic()
    v = suite.judge(img, SPP, ref, var)
    assert v.passed and v.fraction > 0.999 and abs(v.mean_ratio - 1) < 1e-3
    # Mitsuba's level: Sidak over the pixels (not the pixel-channels)
    assert v.alpha == pytest.approx(1 - 0.99 ** (1 / (H * W)))
    assert not suite.judge(img * 1.2, SPP, ref, var).passed
    swapped = ref[::-1, :] if checker[0, 0] != checker[-1, 0] else np.roll(ref, 8, axis=1)
    bad = suite.judge(swapped + (img - ref), SPP, ref, var)
    assert not bad.passed and bad.fraction < 0.6 and abs(bad.mean_ratio - 1) < 0.02


@pytest.mark.parametrize("wrong, passes", [(0.002, True), (0.003, False)])
def test_judge_threshold_is_per_pixel(wrong, passes):
    """Pass iff passing pixel-channels / 3 >= 99.75% of the pixels (Mitsuba's count)."""
    ref, var, img, _ = _synthetic(1)
    img = ref.copy()   # noise-free: only the planted pixel-channels fail
    flat = img.reshape(-1)
    n = int(round(wrong * flat.size))
    flat[np.random.default_rng(2).choice(flat.size, n, replace=False)] += 1.0
    assert suite.judge(img, SPP, ref, var).passed == passes


def test_variance_floor_and_nonfinite():
    ref = np.zeros((4, 4, 3))
    var = np.zeros_like(ref)     # floored at 1e-4: z = 0.01 * sqrt(spp / 1e-4)
    img = ref + 0.01
    z = 0.01 * math.sqrt(16 / 1e-4)
    assert suite.judge(img, 16, ref, var).min_p == pytest.approx(math.erfc(z / math.sqrt(2)))
    img[0, 0, 0] = np.nan        # a NaN pixel fails
    assert suite.judge(img, 16, ref, var).fraction < 1


@pytest.mark.skipif(not DATA, reason="PBR_MITSUBA_DATA (a mitsuba-data checkout) not set")
@pytest.mark.parametrize("scene", ["spot_light/test_spot_direct.xml",
                                   "bsdf_spheres/test_textured_roughconductor_path.xml",
                                   "bsdf_spheres/test_texturedprincipled1_path.xml",
                                   "instancing/test_instancing_path.xml",
                                   "orthographic_sensor/test_orthographic_path.xml"])
def test_real_scene(scene):
    """A scene of Mitsuba's suite loads unmodified and passes Mitsuba's criterion; with
    its reference scaled by 1.1 it fails."""
    path = os.path.join(suite.scene_dir(DATA), scene)
    row = suite.run_scene(path)
    assert row.loads and row.verdict is not None, row.error
    assert row.verdict.passed, (row.verdict, row.error)
    ref, var = suite.read_xyz(suite.reference_files(path)[0]), suite.read_xyz(suite.reference_files(path)[1])
    img = suite.render_xyz(pbr.load_file(path, spp=SPP, integrator=suite.integrator_of(path)), SPP)
    assert not suite.judge(img, SPP, ref * 1.1, var).passed
