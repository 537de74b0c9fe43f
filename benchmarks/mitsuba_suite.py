"""Mitsuba 3's own render-test suite, rendered by pbr and judged as Mitsuba judges it.

The suite is the 41 scenes under ``tests/scenes`` of the public ``mitsuba-renderer/mitsuba-data``
repository (with ``common/``, the meshes and textures they share; ``various_shapes`` also
reads ``tests/obj``, ``tests/ply``, ``tests/serialized`` and ``docs/scenes/sdfgrid``), each with a spectral
reference image ``refs/<name>_ref_spectral.exr`` and the per-sample variance of that
reference, ``refs/<name>_ref_spectral_var.exr`` (both linear sRGB). Mitsuba's
``src/render/tests/test_renders.py`` judges a render as follows, and so does this runner:

1. the scene file is loaded unmodified, with the parameters ``spp`` (a budget of 2e6
   samples over the image: ``2000000 // (width * height)`` per pixel) and ``integrator``
   (the suffix of the file name: ``test_spot_direct.xml`` -> ``direct``);
2. it is rendered with seed 0; the image is taken in CIE XYZ (the first moment of a
   ``moment`` integrator when the scene has one, else the RGB image converted to XYZ);
3. the reference and its variance are converted from RGB to XYZ (Mitsuba's
   ``Bitmap.convert``), the variance is clamped below at 1e-4;
4. per pixel and channel a two-sided z-test ``z = |img - ref| sqrt(spp / var)``,
   p = erfc(z / sqrt 2), passes when p > alpha, with the Sidak-corrected level
   alpha = 1 - (1 - 0.01)^(1 / number of pixels);
5. the scene passes when at least 99.75% of the pixels' worth of pixel-channels pass
   (passing pixel-channels / 3 >= 0.9975 * pixels).

The table also shows the image mean ratio (pbr / reference over all pixel-channels), which
tells a global energy difference from a pattern difference. Keep the data outside pbr's
repository (it is Mitsuba's):

    python benchmarks/mitsuba_suite.py --data /path/to/mitsuba-data [--scenes spot,test_bumpmap] [--spp N]
        [--backend llvm] [--out DIR]

``--data`` is the repository's root (holding ``tests/scenes`` and ``common``) or its
``tests/scenes`` folder. ``--scenes`` selects scenes whose file name or folder contains
one of the given strings. ``--out`` writes, for each failing scene, pbr's image, the
reference and the map of failing pixel-channels as EXR files.
"""

from __future__ import annotations

import argparse
import glob
import math
import os
import sys
import time
import traceback
from dataclasses import dataclass

import numpy as np

SIGNIFICANCE = 0.01      # Mitsuba's significance_level
MIN_PASS = 0.9975        # fraction of pixels' worth of pixel-channels that must pass
SAMPLE_BUDGET = 2_000_000
VAR_FLOOR = 1e-4         # Mitsuba sanitises the reference variance with this floor

_erfc = np.vectorize(math.erfc, otypes=[np.float64])


@dataclass
class Verdict:
    """Outcome of :func:`judge`."""
    passed: bool
    fraction: float      # pixel-channels that pass / all pixel-channels
    mean_ratio: float    # mean(img) / mean(ref)
    min_p: float
    alpha: float


def judge(img, spp: int, ref, ref_var, significance: float = SIGNIFICANCE, min_pass: float = MIN_PASS) -> Verdict:
    """Mitsuba's test_renders criterion for an image ``img`` rendered with ``spp`` samples
    per pixel, against ``ref`` and the per-sample variance ``ref_var`` of the reference
    renderer (all (H, W, C) in the same colour space; Mitsuba uses XYZ)."""
    img, ref = np.asarray(img, np.float64), np.asarray(ref, np.float64)
    var = np.maximum(np.asarray(ref_var, np.float64), VAR_FLOOR)
    if img.shape != ref.shape or ref.shape != var.shape:
        raise ValueError(f"judge: shapes differ: image {img.shape}, reference {ref.shape}, variance {var.shape}")
    pixels = img.shape[0] * img.shape[1]
    channels = img.shape[2] if img.ndim == 3 else 1
    with np.errstate(invalid="ignore"):
        z = np.abs(img - ref) * np.sqrt(spp / var)
    p = np.where(np.isfinite(z), _erfc(np.where(np.isfinite(z), z, 0.0) / math.sqrt(2.0)), 0.0)
    alpha = 1.0 - (1.0 - significance) ** (1.0 / pixels)
    ok = p > alpha
    passed = bool(np.count_nonzero(ok) / channels >= min_pass * pixels)
    mean_ref = float(np.mean(ref))
    ratio = float(np.mean(img)) / mean_ref if mean_ref != 0 else float("nan")
    return Verdict(passed, float(np.count_nonzero(ok)) / ok.size, ratio, float(np.min(p)), alpha)


# ------------------------------------------------------------------------ the suite

def scene_dir(data: str) -> str:
    """The folder holding the scene folders (``<data>/tests/scenes`` or ``data``)."""
    for d in (os.path.join(data, "tests", "scenes"), data):
        if glob.glob(os.path.join(d, "*", "*.xml")):
            return d
    raise SystemExit(f"mitsuba_suite: no scenes under {data!r} (expected tests/scenes/<folder>/*.xml)")


def find_scenes(data: str, select: list[str] | None = None) -> list[str]:
    """The suite's scene files (``<folder>/<name>_<integrator>.xml``), sorted; with
    ``select``, those whose folder or file name contains one of its strings."""
    files = sorted(glob.glob(os.path.join(scene_dir(data), "*", "*.xml")))
    if select:
        files = [f for f in files if any(s in os.path.relpath(f, os.path.dirname(os.path.dirname(f)))
                                         for s in select)]
    return files


def integrator_of(scene_file: str) -> str:
    """The integrator a suite scene is tested with: its file name's last ``_`` part."""
    return os.path.splitext(os.path.basename(scene_file))[0].rsplit("_", 1)[-1]


def reference_files(scene_file: str) -> tuple[str, str]:
    """(reference, variance) EXR files of a scene (spectral variant)."""
    stem = os.path.splitext(os.path.basename(scene_file))[0].rsplit("_", 1)[0]
    ref = os.path.join(os.path.dirname(scene_file), "refs", f"{stem}_ref_spectral.exr")
    return ref, ref.replace(".exr", "_var.exr")


def read_xyz(path: str) -> np.ndarray:
    """An RGB EXR converted to XYZ by Mitsuba's Bitmap (as test_renders reads references)."""
    import mitsuba as mi
    bmp = mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.XYZ, mi.Struct.Type.Float32, False)
    return np.array(bmp, dtype=np.float64)


def rgb_to_xyz(rgb: np.ndarray) -> np.ndarray:
    """Linear sRGB -> XYZ with Mitsuba's Bitmap conversion."""
    import mitsuba as mi
    bmp = mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32), mi.Bitmap.PixelFormat.RGB)
    return np.array(bmp.convert(mi.Bitmap.PixelFormat.XYZ, mi.Struct.Type.Float32, False), dtype=np.float64)


def xyz_to_rgb(xyz: np.ndarray) -> np.ndarray:
    import mitsuba as mi
    bmp = mi.Bitmap(np.ascontiguousarray(xyz, dtype=np.float32), mi.Bitmap.PixelFormat.XYZ)
    return np.array(bmp.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False))


def render_xyz(scene, spp: int, seed: int = 0) -> np.ndarray:
    """pbr's image of ``scene`` in XYZ: the first nested integrator's first moment when
    the scene's integrator is ``moment``, else its RGB image converted."""
    import pbr
    img = np.asarray(pbr.render(scene, spp=spp, seed=seed), dtype=np.float64)
    if getattr(scene.integrator, "name", None) == "moment":
        return img[..., 3:6]
    return rgb_to_xyz(img[..., :3])


@dataclass
class Row:
    scene: str
    loads: bool
    verdict: Verdict | None
    seconds: float
    error: str


def run_scene(path: str, spp: int | None = None, out: str | None = None, budget: int = SAMPLE_BUDGET) -> Row:
    """Load, render and judge one suite scene."""
    import pbr
    name = os.path.relpath(path, os.path.dirname(os.path.dirname(path)))
    ref_file, var_file = reference_files(path)
    if not (os.path.exists(ref_file) and os.path.exists(var_file)):
        return Row(name, False, None, 0.0, f"missing reference {os.path.basename(ref_file)}")
    ref, ref_var = read_xyz(ref_file), read_xyz(var_file)
    spp = spp or budget // (ref.shape[0] * ref.shape[1])
    try:
        scene = pbr.load_file(path, spp=spp, integrator=integrator_of(path))
    except Exception as e:
        return Row(name, False, None, 0.0, _message(e))
    t0 = time.perf_counter()
    try:
        img = render_xyz(scene, spp)
        if img.shape != ref.shape:
            raise ValueError(f"image shape {img.shape} differs from the reference's {ref.shape}")
        verdict = judge(img, spp, ref, ref_var)
    except Exception as e:
        return Row(name, True, None, time.perf_counter() - t0, "render: " + _message(e))
    seconds = time.perf_counter() - t0
    if out and not verdict.passed:
        _write_failure(out, name, img, ref, ref_var, spp)
    return Row(name, True, verdict, seconds, "")


def _message(e: Exception) -> str:
    """The first line of the innermost cause (Dr.Jit's loops wrap errors: "see above")."""
    while e.__cause__ is not None:
        e = e.__cause__
    lines = str(e).strip().splitlines() or [type(e).__name__]
    return f"{type(e).__name__}: {lines[0]}"


def _write_failure(out: str, name: str, img, ref, ref_var, spp: int) -> None:
    import pbr
    os.makedirs(out, exist_ok=True)
    stem = os.path.join(out, name.replace(os.sep, "__").removesuffix(".xml"))
    pbr.write_image(stem + "_img.exr", xyz_to_rgb(img))
    pbr.write_image(stem + "_ref.exr", xyz_to_rgb(ref))
    z = np.abs(img - ref) * np.sqrt(spp / np.maximum(ref_var, VAR_FLOOR))
    alpha = 1.0 - (1.0 - SIGNIFICANCE) ** (1.0 / (img.shape[0] * img.shape[1]))
    fail = (_erfc(z / math.sqrt(2.0)) <= alpha).astype(np.float32)
    pbr.write_image(stem + "_fail.exr", fail)


def format_row(r: Row, w: int) -> str:
    v = r.verdict
    frac = f"{v.fraction:9.4f}" if v else " " * 9
    ratio = f"{v.mean_ratio:10.4f}" if v else " " * 10
    result = ("pass" if v.passed else "FAIL") if v else "-"
    return f"{r.scene:<{w}}  {'yes' if r.loads else 'no':<5}  {frac}  {ratio}  {result:<6}  {r.seconds:7.1f}  {r.error}"


def print_table(rows: list[Row], file=sys.stdout) -> None:
    w = max([len(r.scene) for r in rows] + [5])
    print(f"{'scene':<{w}}  loads  pass-frac  mean-ratio  result  time(s)  error", file=file)
    for r in rows:
        print(format_row(r, w), file=file, flush=True)
    loads = sum(r.loads for r in rows)
    passed = sum(bool(r.verdict and r.verdict.passed) for r in rows)
    print(f"\n{len(rows)} scenes: {loads} load, {passed} pass", file=file)


def run_all(files: list[str], run, name, show_traceback: bool = False, width: int = 60) -> list[Row]:
    """``run(f)`` (a Row) for each scene file, progress on stderr, then the table; an
    exception of the runner itself becomes a row (``name(f)``: its scene name)."""
    rows = []
    for f in files:
        try:
            rows.append(run(f))
        except Exception as e:   # a bug in the runner itself: report, go on
            if show_traceback:
                traceback.print_exc()
            rows.append(Row(name(f), False, None, 0.0, "runner: " + _message(e)))
        print(format_row(rows[-1], width), file=sys.stderr, flush=True)
    print_table(rows)
    return rows


def main(argv=None) -> list[Row]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="mitsuba-data root (or its tests/scenes folder)")
    ap.add_argument("--scenes", default="", help="comma-separated substrings of scene paths to run")
    ap.add_argument("--spp", type=int, default=0, help="samples per pixel (default: 2e6 / pixels, as Mitsuba)")
    ap.add_argument("--backend", default="llvm", help="pbr backend: llvm, cuda or auto")
    ap.add_argument("--out", default="", help="folder for the images of failing scenes")
    ap.add_argument("--traceback", action="store_true", help="print tracebacks of errors")
    args = ap.parse_args(argv)
    import pbr
    pbr.set_backend(args.backend)
    files = find_scenes(args.data, [s for s in args.scenes.split(",") if s])
    return run_all(files, lambda f: run_scene(f, args.spp or None, args.out or None), os.path.basename,
                   args.traceback)


if __name__ == "__main__":
    main()
