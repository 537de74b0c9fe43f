"""Validation runner over pbrt-v4's scene collection (mmp/pbrt-v4-scenes): which scenes
pbr reads, which it renders, and what stops the rest.

For every scene file (a ``.pbrt`` file with ``WorldBegin``) under ``--root``:

0. parse: the file and the files it includes that are present read as pbrt-v4 syntax;
1. strict load (``pbr.scene.pbrt.convert``, missing files skipped): the first feature
   pbr lacks is reported as the scene's blocker;
2. approximate load (``approximate=True, skip_missing=True``): what is substituted or
   left out (the notes), and the conversion time;
3. render at ``--res`` pixels wide and ``--spp`` samples per pixel with pbr (time), if
   the approximate dict loads and ``--no-render`` is not given;
4. with ``--compare``: scenes that load strictly and whose features Mitsuba 3 has are
   converted for Mitsuba 3 (``mitsuba=True``), rendered by pbr and Mitsuba 3 and compared
   statistically (``pbr.validate``; box filter).

Prints one row per scene, a summary, and the scenes grouped by what stops their strict
conversion and their render. The collection is 1.5 GB (geometry, textures);
where only its scene files are present (``/work/data/pbrt-v4-scenes`` holds the text
of a few, read one by one), missing geometry shows as "missing file".

    python benchmarks/pbrt_scenes.py [--root /work/data/pbrt-v4-scenes] [--res 64] [--spp 4]
                                     [--compare] [--no-render] [--csv rows.csv]
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import time

import numpy as np

import pbr
from pbr import validate
from pbr.scene.pbrt import convert
from pbr.scene.pbrt_tokens import read_directives, resolve
from pbr.scene.xml import XMLError


def scene_files(root: str) -> list[str]:
    out = []
    for d, _, files in os.walk(root):
        for f in files:
            if f.endswith(".pbrt"):
                p = os.path.join(d, f)
                with open(p, errors="replace") as fh:
                    if "WorldBegin" in fh.read():
                        out.append(p)
    return sorted(out)


def blocker(msg: str) -> str:
    """The short reason of a strict-load error."""
    m = msg.split(": ", 1)[1] if ": " in msg else msg
    return m.split(" (not supported", 1)[0].split(" is not supported", 1)[0][:90]


def parses(path: str, base: str, seen=None) -> str:
    """'ok', or the first syntax error of ``path`` and of the files it includes (those
    present; paths relative to the main file's directory ``base``, as pbrt-v4 resolves them)."""
    seen = set() if seen is None else seen
    if path in seen:
        return "ok"
    seen.add(path)
    try:
        for d in read_directives(path):
            if d.name in ("Include", "Import") and d.args and isinstance(d.args[0], str):
                full = resolve(d.args[0], base)
                if os.path.exists(full):
                    r = parses(full, base, seen)
                    if r != "ok":
                        return r
    except XMLError as e:
        return str(e).replace(base + "/", "")[:120]
    return "ok"


def run(path: str, args) -> dict:
    row = {"scene": os.path.relpath(path, args.root), "parse": parses(path, os.path.dirname(path))}
    try:
        convert(path, res=args.res, spp=args.spp, mesh_dir=args.mesh_dir, skip_missing=True)
        row["strict"] = "ok"
    except XMLError as e:
        row["strict"] = blocker(str(e))
    t0 = time.perf_counter()
    try:
        d, notes, _ = convert(path, approximate=True, skip_missing=True, res=args.res, spp=args.spp,
                              mesh_dir=args.mesh_dir)
    except XMLError as e:
        row.update(load="FAIL", why=blocker(str(e)))
        return row
    row["convert_s"] = time.perf_counter() - t0
    row["missing"] = sum("file not found" in n for n in notes)
    row["first_missing"] = next((n.split("file not found: ", 1)[1].split(" (looked", 1)[0] for n in notes
                                 if "file not found" in n), "")
    row["approx"] = sum("not found" not in n and ("not supported" in n or ": " in n) and "is used" in n
                        or "approximat" in n for n in notes)
    row["notes"] = notes
    t0 = time.perf_counter()
    try:
        scene = pbr.load_dict(d, base_dir=os.path.dirname(path))
    except Exception as e:
        row.update(load="FAIL", why=str(e).splitlines()[0][:90])
        return row
    row["load"] = "ok"
    row["load_s"] = time.perf_counter() - t0
    if args.no_render:
        return row
    t0 = time.perf_counter()
    try:
        img = np.asarray(pbr.render(scene, seed=0, on_nonfinite="ignore"))
        row["render_s"] = time.perf_counter() - t0
        row["mean"] = float(img.mean())
    except Exception as e:
        row["render"] = f"FAIL {str(e).splitlines()[0][:80]}"
        return row
    if args.compare and row["strict"] == "ok":
        # The dict for Mitsuba 3 (mitsuba=True: hdrfilm, Mitsuba's filters and textures);
        # both render it with a box filter (pbr samples filters, Mitsuba splats them).
        try:
            d, _, _ = convert(path, skip_missing=True, res=args.res, spp=args.spp, mesh_dir=args.mesh_dir,
                              mitsuba=True)
        except XMLError as e:
            row["mitsuba"] = f"no Mitsuba dict: {blocker(str(e))}"
            return row
        d["sensor"]["film"]["rfilter"] = {"type": "box"}
        s = pbr.load_dict(d, base_dir=os.path.dirname(path))
        try:
            r = validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(s, seed=seed, spp=spp)),
                                         validate.mitsuba_render_fn(d), spp=args.spp * 16, batches=16,
                                         seed_a=5, seed_b=6)
            row["mitsuba"] = f"{'PASS' if r else 'FAIL'} ratio {float(np.mean(r.mean_ratio)):.3f}"
            row["compare"] = r.summary()
        except Exception as e:
            row["mitsuba"] = "Mitsuba cannot load it (pbr-only plugins)"
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default="/work/data/pbrt-v4-scenes")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--compare", action="store_true")
    ap.add_argument("--no-render", action="store_true")
    ap.add_argument("--notes", action="store_true", help="print every note")
    ap.add_argument("--mesh-dir", default=None)
    ap.add_argument("--csv", default=None, help="write one row per scene to this CSV file")
    args = ap.parse_args(argv)
    pbr.set_backend("auto")
    files = scene_files(args.root)
    if not files:
        print(f"no scene files under {args.root}", file=sys.stderr)
        return 1
    rows = [run(p, args) for p in files]
    print(f"{'scene':44s} {'strict load: first unsupported feature':50s} {'conv s':>6s} {'miss':>4s} "
          f"{'load':>4s} {'render s':>8s}  mitsuba")
    for r in rows:
        conv = f"{r['convert_s']:.2f}" if "convert_s" in r else "-"
        rend = f"{r['render_s']:.2f}" if "render_s" in r else r.get("render", "-")
        print(f"{r['scene']:44s} {r['strict'][:50]:50s} {conv:>6s} {r.get('missing', '-')!s:>4s} "
              f"{r.get('load', '-'):>4s} {rend:>8s}  {r.get('mitsuba', '')}{r.get('why', '')}")
        if args.notes and r.get("compare"):
            print("      " + r["compare"].replace("\n", "\n      "))
        if args.notes:
            for n in r.get("notes", []):
                print("      " + n.replace(args.root + "/", ""))
    if args.csv:
        keys = ["scene", "parse", "strict", "missing", "first_missing", "approx_notes", "load", "why", "convert_s", "load_s",
                "render_s", "render", "mean", "mitsuba"]
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, keys, extrasaction="ignore")
            w.writeheader()
            for r in rows:
                w.writerow({**r, "approx_notes": len(r.get("notes", []))})
    n = len(rows)
    strict = sum(r["strict"] == "ok" for r in rows)
    loaded = sum(r.get("load") == "ok" for r in rows)
    rendered = sum("render_s" in r for r in rows)
    complete = sum(r.get("load") == "ok" and r.get("missing") == 0 for r in rows)
    parsed = sum(r["parse"] == "ok" for r in rows)
    print(f"\n{n} scenes: {parsed} parse, {strict} convert without approximations, {loaded} load approximately "
          f"({complete} with all their files), {rendered} render at {args.res} px, {args.spp} spp")
    for title, key in (("what stops a strict conversion (missing files skipped)", lambda r: r["strict"]),
                       ("what stops a render (approximate=True, skip_missing=True)",
                        lambda r: "ok" if "render_s" in r else (r.get("why") or r.get("render") or "not rendered"))):
        groups: dict[str, list] = {}
        for r in rows:
            k = key(r)
            if k != "ok":
                groups.setdefault(k, []).append(r["scene"])
        print(f"\n{title}:")
        for k, v in sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0])):
            print(f"  {len(v):3d}  {k}\n         {', '.join(v)}")
    for r in rows:
        if r["parse"] != "ok":
            print(f"parse error: {r['parse']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
