"""Command line interface: ``pbr render [SCENE] -o OUT ...`` (also ``python -m pbr``).

Uses only pbr's public API (set_backend, cornell_box, load_dict, load_file, render) and
:func:`pbr.image.write_image`. Loading and output errors print ``pbr: error: <message>``
on stderr and exit with status 2, without a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

import pbr

from .cameras import SENSORS
from .films import FILMS
from .image import TONEMAPS, WRITE_EXTENSIONS, write_image
from .scene.loader import load_xml_file

EXIT_ERROR = 2


def _parse_value(text: str):
    """A -D value: int if it parses as one, else float, else the string itself."""
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text


def _define(text: str):
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected name=value, got {text!r}")
    return name, _parse_value(value)


def _version() -> str:
    import drjit
    import mitsuba
    return f"pbr {pbr.__version__} (Dr.Jit {drjit.__version__}, Mitsuba {mitsuba.__version__})"


def _film_size(args):
    """A function that sets every sensor film's size of a scene dict from --res/--width/
    --height (None when none is given). Mitsuba's default film is 768 x 576."""
    if args.res is None and args.width is None and args.height is None:
        return None
    if args.res is not None and (args.width is not None or args.height is not None):
        raise UsageError("give either --res or --width/--height")
    for name in ("res", "width", "height"):
        v = getattr(args, name)
        if v is not None and v <= 0:
            raise UsageError(f"--{name} must be a positive integer, got {v}")

    def edit(d):
        for sensor in (v for v in d.values() if isinstance(v, dict) and v.get("type") in SENSORS):
            films = [f for f in sensor.values() if isinstance(f, dict) and f.get("type") in FILMS]
            if not films:
                films = [sensor.setdefault("film", {"type": "hdrfilm"})]
            for film in films:
                kw, kh, dw, dh = FILMS[film["type"]].size_keys     # pbrt-v4's films: xresolution, ...
                w, h = int(film.get(kw, dw)), int(film.get(kh, dh))
                width = args.res if args.res is not None else args.width
                if width is not None and args.height is not None:
                    film[kw], film[kh] = width, args.height
                elif width is not None:
                    film[kw], film[kh] = width, max(1, round(width * h / w))
                else:
                    film[kw], film[kh] = max(1, round(args.height * w / h)), args.height
                _scale_crop(film, (w, h), (film[kw], film[kh]))
    return edit


def _scaled_span(offset: int, size: int, old: int, new: int) -> tuple[int, int]:
    """A pixel span [offset, offset + size) of an ``old``-pixel axis mapped onto ``new``
    pixels: the same part of the view, at least one pixel, inside the axis."""
    a = min(new - 1, round(offset * new / old))
    b = min(new, max(a + 1, round((offset + size) * new / old)))
    return a, b - a


def _scale_crop(film: dict, old: tuple[int, int], new: tuple[int, int]) -> None:
    """Resize a film's crop window in pixels with the film (Mitsuba's ``crop_*``, pbrt-v4's
    ``pixelbounds``), so that --res renders the same part of the view; pbrt-v4's
    ``cropwindow`` is in fractions and stays."""
    if any(k in film for k in ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height")):
        for axis, (ko, kc) in enumerate((("crop_offset_x", "crop_width"), ("crop_offset_y", "crop_height"))):
            o = int(film.get(ko, 0))
            film[ko], film[kc] = _scaled_span(o, int(film.get(kc, old[axis] - o)), old[axis], new[axis])
    if "pixelbounds" in film:
        pb = [int(v) for v in np.asarray(film["pixelbounds"], np.float64).ravel()]
        if len(pb) == 4:
            (x0, nx), (y0, ny) = (_scaled_span(pb[2 * i], pb[2 * i + 1] - pb[2 * i], old[i], new[i]) for i in (0, 1))
            film["pixelbounds"] = [x0, x0 + nx, y0, y0 + ny]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pbr", description="pbr: a spectral, differentiable renderer on Dr.Jit.")
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    r = sub.add_parser("render", help="render a scene to an image",
                       description="Render SCENE (Mitsuba XML or pbrt-v4 .pbrt), or the built-in Cornell box.")
    r.add_argument("scene", nargs="?", metavar="SCENE",
                   help="scene file; omitted: the built-in Cornell box")
    r.add_argument("-o", "--output", metavar="OUT",
                   help="output image (.exr or .png); default out/<scene-stem>.exr")
    r.add_argument("--png", metavar="PNGPATH", help="also write a tone-mapped sRGB PNG here")
    r.add_argument("--spp", type=int, default=0,
                   help="samples per pixel (0: the scene's own sample count)")
    r.add_argument("--res", type=int, metavar="N",
                   help="image width N, the height following the film's aspect ratio (any scene; a crop "
                        "window scales with the film)")
    r.add_argument("--width", type=int, help="image width (with --height: both exactly; alone: aspect kept)")
    r.add_argument("--height", type=int, help="image height (alone: aspect kept)")
    r.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    r.add_argument("--backend", choices=("auto", "llvm", "cuda"), default="auto",
                   help="Dr.Jit backend (default auto: CUDA if usable, else LLVM)")
    r.add_argument("--tonemap", choices=TONEMAPS, default="clamp",
                   help="tone mapping for PNG output (default clamp)")
    r.add_argument("--on-nonfinite", choices=("warn", "raise", "ignore"), default="warn",
                   help="samples that are NaN or infinite count as 0: warn with their number "
                        "(default), fail (exit status 2) or ignore them")
    r.add_argument("--target-error", type=float, metavar="E",
                   help="adaptive sampling: each pixel gets the samples it needs for a relative standard "
                        "error E (e.g. 0.05), --spp being the most any pixel gets (docs/speed_vs_accuracy.md)")
    r.add_argument("--time-budget", type=float, metavar="S", help="stop rendering after S seconds")
    r.add_argument("-D", dest="defines", action="append", type=_define, default=[],
                   metavar="NAME=VALUE",
                   help="scene parameter override passed to load_file (repeatable); "
                        "numbers become int/float")
    return parser


def _scene_spp(scene):
    spp = getattr(scene, "spp", None)
    if callable(spp):
        spp = spp()
    try:
        return int(spp) if spp is not None else None
    except (TypeError, ValueError):
        return None


class UsageError(Exception):
    """A user-facing error: printed as ``pbr: error: <message>``, exit status 2."""


def _load(args):
    """Select the backend and load the scene; user errors become :class:`UsageError`."""
    if args.scene is None and args.defines:
        raise UsageError("-D overrides apply to scene files; none given "
                         "(the built-in Cornell box takes no parameters)")
    if args.scene is not None and not os.path.isfile(args.scene):
        raise UsageError(f"scene file not found: {args.scene}")
    edit = _film_size(args)
    try:
        pbr.set_backend(args.backend)
        if args.scene is None:
            d = pbr.cornell_box()
            if edit:
                edit(d)
            return pbr.load_dict(d)
        if edit is None:
            return pbr.load_file(args.scene, **dict(args.defines))
        return load_xml_file(args.scene, edit, **dict(args.defines))
    except (ValueError, FileNotFoundError, pbr.BackendError) as e:
        raise UsageError(str(e)) from e


def _render(args) -> int:
    if args.scene is None:
        name = "cornell"
    else:
        name = os.path.splitext(os.path.basename(args.scene))[0] or "scene"
    out = args.output or os.path.join("out", f"{name}.exr")
    if args.spp < 0:
        raise UsageError(f"--spp must be >= 0, got {args.spp}")
    adaptive = {}
    for opt, key, v in (("--target-error", "target_relative_error", args.target_error),
                        ("--time-budget", "time_budget", args.time_budget)):
        if v is not None:
            if not v > 0:
                raise UsageError(f"{opt} must be > 0, got {v}")
            adaptive[key] = v
    targets = [out] + ([args.png] if args.png else [])
    for path in targets:  # fail before a long render, not after
        ext = os.path.splitext(path)[1].lower()
        if ext not in WRITE_EXTENSIONS:
            raise UsageError(f"cannot write {path!r}: unsupported extension "
                             f"{ext or '(none)'!r}; supported: {', '.join(WRITE_EXTENSIONS)}")

    scene = _load(args)
    # Errors from here on are pbr bugs, not user errors: they keep their traceback.
    t0 = time.perf_counter()
    # np.asarray forces evaluation of Dr.Jit's lazy result, so the time includes
    # kernel compilation and execution.
    info = None
    try:
        if adaptive:
            img, info = pbr.render(scene, spp=args.spp, seed=args.seed, on_nonfinite=args.on_nonfinite,
                                   return_info=True, **adaptive)
        else:
            img = pbr.render(scene, spp=args.spp, seed=args.seed, on_nonfinite=args.on_nonfinite)
        img = np.asarray(img, dtype=np.float32)
    except FloatingPointError as e:     # --on-nonfinite raise
        raise UsageError(str(e)) from e
    elapsed = time.perf_counter() - t0

    written = []
    for path in targets:
        try:
            write_image(path, img, tonemap=args.tonemap)
        except ValueError as e:  # unsupported extension, NaN/Inf pixels
            raise UsageError(str(e)) from e
        except OSError as e:
            raise UsageError(str(e) if e.strerror is None else f"cannot write {path}: {e.strerror}") from e
        written.append(path)

    h, w = img.shape[:2]
    if info is not None:
        print(info.summary())
    spp = info.mean_spp if info is not None else args.spp if args.spp > 0 else _scene_spp(scene)
    if spp is not None and elapsed > 0:
        rate = f"{w * h * spp / elapsed / 1e6:.2f} Msamples/s"
    else:
        rate = "? Msamples/s"
    spp_text = "?" if spp is None else f"mean {spp:.1f}" if info is not None else spp
    print(f"rendered {name}: {w}x{h}, {spp_text} spp, "
          f"{elapsed:.2f} s, {rate} -> {', '.join(written)}")
    return 0


def main(argv=None) -> int:
    """Run the CLI with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2, message already printed)
        return e.code if isinstance(e.code, int) else EXIT_ERROR
    try:
        return _render(args)  # "render" is the only command
    except UsageError as e:
        print(f"pbr: error: {e}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
