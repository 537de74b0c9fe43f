"""The scenes of Mitsuba 3's tutorials, rendered by pbr and by Mitsuba and compared.

The public ``mitsuba-renderer/mitsuba-tutorials`` repository ships its scenes under
``scenes/`` (``cbox.xml``, ``simple.xml``, ``shadow_art.xml``, ``cbox_pol.xml``,
``polarizers.xml``, ``lego/scene.xml``, with their meshes and textures). They have no
reference images, so each scene is loaded unmodified by ``pbr.load_file`` and by
Mitsuba's ``mi.load_file`` (variant ``llvm_ad_spectral``), both rendered at a small size
in ``--batches`` independent batches, and the two estimates are compared with
:func:`pbr.validate.compare` (per pixel-channel z-test at a Sidak-corrected level, at
least 99.75% passing, and the image mean ratio within 3 standard errors).

The size: every ``<default>`` named ``res``, ``resx``, ``resy``, ``width`` or ``height``
is scaled by one factor so that the largest becomes ``--res`` (aspect ratio kept).
Scenes that need Mitsuba's polarized variants (the ``stokes`` integrator, the
``polarizer``/``retarder``/``circular``/``pplastic`` BSDFs) are reported as out of scope:
pbr transports unpolarized radiance. The table's columns are those of
``mitsuba_suite.py`` (pass-frac: fraction of pixel-channels passing; mean-ratio: pbr /
Mitsuba). Keep the data outside pbr's repository (it is Mitsuba's):

    python benchmarks/mitsuba_tutorials.py --data /path/to/mitsuba-tutorials [--scenes cbox,lego]
        [--res 64] [--spp 512] [--batches 16] [--out DIR]

``--data`` is the repository's root or its ``scenes`` folder.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import time
import xml.etree.ElementTree as ET

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mitsuba_suite as suite  # noqa: E402  (the table, the rows and the error messages)

SIZE_PARAMS = ("res", "resx", "resy", "width", "height")
POLARIZED = frozenset({"stokes", "polarizer", "retarder", "circular", "pplastic", "measured_polarized"})


def find_scenes(data: str, select: list[str] | None = None) -> tuple[str, list[str]]:
    """(scenes folder, its XML scene files, sorted); with ``select``, those whose path
    below the folder contains one of its strings."""
    for root in (os.path.join(data, "scenes"), data):
        files = sorted(glob.glob(os.path.join(root, "*.xml")) + glob.glob(os.path.join(root, "*", "*.xml")))
        if files:
            break
    else:
        raise SystemExit(f"mitsuba_tutorials: no scenes under {data!r} (expected scenes/*.xml)")
    if select:
        files = [f for f in files if any(s in os.path.relpath(f, root) for s in select)]
    return root, files


def scene_params(path: str, res: int) -> dict:
    """Parameters shrinking the scene's film: its size ``<default>`` values scaled so that
    the largest is ``res``."""
    defaults = {e.get("name"): e.get("value") for e in ET.parse(path).getroot().iter("default")}
    sizes = {k: int(v) for k, v in defaults.items() if k in SIZE_PARAMS}
    if not sizes:
        return {}
    f = res / max(sizes.values())
    return {k: str(max(1, round(v * f))) for k, v in sizes.items()}


def polarized_plugins(path: str) -> list[str]:
    """The polarized-only plugin types the scene uses."""
    return sorted({e.get("type") for e in ET.parse(path).getroot().iter() if e.get("type") in POLARIZED})


def run_scene(path: str, root: str, res: int, spp: int, batches: int, out: str | None = None) -> suite.Row:
    """Load the scene with pbr and Mitsuba, render both in batches, compare."""
    import pbr
    from pbr import validate
    name = os.path.relpath(path, root)
    pol = polarized_plugins(path)
    if pol:
        return suite.Row(name, False, None, 0.0, f"out of scope: polarized plugins {', '.join(pol)}")
    params = scene_params(path, res)
    try:
        scene = pbr.load_file(path, **params)
    except Exception as e:
        return suite.Row(name, False, None, 0.0, suite._message(e))
    try:
        fb = validate.mitsuba_render_fn(path, **params)
    except Exception as e:
        return suite.Row(name, True, None, 0.0, "Mitsuba: " + suite._message(e))
    fa = lambda seed=0, spp=0: np.asarray(pbr.render(scene, seed=seed, spp=spp))  # noqa: E731
    t0 = time.perf_counter()
    try:
        ea = validate.estimate(fa, spp, batches, seed=1)
        eb = validate.estimate(fb, spp, batches, seed=2)
        r = validate.compare(ea.mean, ea.var, eb.mean, eb.var, image_mean_var_a=ea.image_mean_var,
                             image_mean_var_b=eb.image_mean_var)
    except Exception as e:
        return suite.Row(name, True, None, time.perf_counter() - t0, "render: " + suite._message(e))
    seconds = time.perf_counter() - t0
    if out and not r.passed:
        os.makedirs(out, exist_ok=True)
        stem = os.path.join(out, name.replace(os.sep, "__").removesuffix(".xml"))
        pbr.write_image(stem + "_pbr.exr", ea.mean.astype(np.float32))
        pbr.write_image(stem + "_mitsuba.exr", eb.mean.astype(np.float32))
        pbr.write_image(stem + "_fail.exr", (r.p_values < r.alpha_sidak).astype(np.float32))
    verdict = suite.Verdict(r.passed, r.pass_fraction, r.mean_ratio, float(np.nanmin(r.p_values)), r.alpha_sidak)
    note = "" if r.ratio_ok else f"mean ratio {r.mean_ratio:.4f} +- {r.mean_ratio_stderr:.4f}"
    return suite.Row(name, True, verdict, seconds, note)


def main(argv=None) -> list[suite.Row]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="mitsuba-tutorials root (or its scenes folder)")
    ap.add_argument("--scenes", default="", help="comma-separated substrings of scene paths to run")
    ap.add_argument("--res", type=int, default=64, help="largest film side (default 64)")
    ap.add_argument("--spp", type=int, default=512, help="samples per pixel over all batches (default 512)")
    ap.add_argument("--batches", type=int, default=16, help="independent batches per renderer (default 16)")
    ap.add_argument("--backend", default="llvm", help="pbr backend: llvm, cuda or auto")
    ap.add_argument("--out", default="", help="folder for the images of failing scenes")
    ap.add_argument("--traceback", action="store_true", help="print tracebacks of errors")
    args = ap.parse_args(argv)
    import pbr
    pbr.set_backend(args.backend)
    root, files = find_scenes(args.data, [s for s in args.scenes.split(",") if s])
    return suite.run_all(files, lambda f: run_scene(f, root, args.res, args.spp, args.batches, args.out or None),
                         lambda f: os.path.relpath(f, root), args.traceback, width=30)


if __name__ == "__main__":
    main()
