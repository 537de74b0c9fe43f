"""A seeded fuzzer over pbr's shipped XML scenes (issue 18): each mutant changes one
thing in a scene file (a value made non-finite, negative, huge or malformed; an element's
type or tag swapped; an attribute or element removed or duplicated; an unknown
parameter), is loaded with ``pbr.load_file`` and, when accepted, rendered tiny.

A mutant's outcome is one of

- ``rejected``: loading raised one of pbr's own errors (``SceneError``, ``XMLError``,
  ``FileNotFoundError``) whose message names a place (a key path or ``file:line``);
- ``rendered``: it loaded and rendered a finite image, every sample finite
  (``on_nonfinite="raise"``);
- ``bad``: anything else: a crash, a Python or Dr.Jit exception from inside pbr, an
  error that names no place, or an image with NaN/Inf. Each is a bug.

    python tests/fuzz_scenes.py --count 200 --seed 1       # prints counts and every 'bad' case
"""

from __future__ import annotations

import argparse
import os
import random
import re
import time
import xml.etree.ElementTree as ET

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = [os.path.join(ROOT, "scenes", f) for f in ("cornell_box.xml", "materials_gallery.xml")]
VALUE_TAGS = ("float", "integer", "rgb", "spectrum", "point", "vector", "boolean", "string")
BAD_NUMBERS = ("nan", "inf", "-inf", "-1", "0", "1e30", "-1e30", "1e-30", "abc", "", "1 2", "2.5")
SOME_TYPES = ("diffuse", "conductor", "dielectric", "sphere", "rectangle", "area", "point", "path",
              "perspective", "hdrfilm", "independent", "gaussian", "bitmap", "checkerboard", "homogeneous")


def _elements(root):
    return [e for e in root.iter() if e is not root]


def mutate(text: str, rng: random.Random) -> tuple[str, str]:
    """One mutation of the XML ``text``: (new text, what was done)."""
    root = ET.fromstring(text)
    elems = _elements(root)
    parents = {c: p for p in root.iter() for c in p}
    kind = rng.choice(("value", "value", "value", "type", "tag", "drop_attr", "drop_elem", "dup_elem",
                       "unknown_param", "transform"))
    if kind == "value":
        vals = [e for e in elems if e.tag in VALUE_TAGS and "value" in e.attrib]
        e = rng.choice(vals)
        old = e.get("value")
        if e.tag in ("rgb", "point", "vector") and rng.random() < 0.5:
            parts = re.split(r"[,\s]+", old.strip())
            parts[rng.randrange(len(parts))] = rng.choice(BAD_NUMBERS[:8])
            new = ", ".join(parts)
        else:
            new = rng.choice(BAD_NUMBERS)
        e.set("value", new)
        what = f"<{e.tag} name={e.get('name')!r}> value {old!r} -> {new!r}"
    elif kind == "type":
        e = rng.choice([e for e in elems if "type" in e.attrib])
        old, new = e.get("type"), rng.choice(SOME_TYPES)
        e.set("type", new)
        what = f"<{e.tag}> type {old!r} -> {new!r}"
    elif kind == "tag":
        e = rng.choice([e for e in elems if "type" in e.attrib])
        old, new = e.tag, rng.choice(("shape", "bsdf", "sensor", "emitter", "sampler", "film", "texture",
                                      "medium", "rfilter", "integrator"))
        e.tag = new
        what = f"<{old} type={e.get('type')!r}> -> <{new}>"
    elif kind == "drop_attr":
        e = rng.choice([e for e in elems if e.attrib])
        a = rng.choice(sorted(e.attrib))
        del e.attrib[a]
        what = f"<{e.tag}> without attribute {a!r}"
    elif kind == "drop_elem":
        e = rng.choice(elems)
        parents[e].remove(e)
        what = f"<{e.tag} {dict(e.attrib)}> removed"
    elif kind == "dup_elem":
        e = rng.choice(elems)
        p = parents[e]
        p.insert(list(p).index(e), ET.fromstring(ET.tostring(e)))
        what = f"<{e.tag} {dict(e.attrib)}> duplicated"
    elif kind == "unknown_param":
        e = rng.choice([e for e in elems if "type" in e.attrib])
        ET.SubElement(e, "float", name=rng.choice(("radiance_", "alpha2", "colour", "scael")), value="1")
        what = f"<{e.tag} type={e.get('type')!r}> with an unknown parameter"
    else:
        ts = [e for e in root.iter() if e.tag in ("translate", "rotate", "scale", "lookat", "matrix")]
        e = rng.choice(ts)
        a = rng.choice(sorted(e.attrib))
        old = e.get(a)
        e.set(a, rng.choice(("nan", "0", "0, 0, 0", "inf", "1e30")))
        what = f"<{e.tag}> {a}={old!r} -> {e.get(a)!r}"
    return ET.tostring(root, encoding="unicode"), what


def _names_a_place(msg: str) -> bool:
    """A key path (``scene.x.y``), ``file:line``, or an XML element/parameter name."""
    return bool(re.search(r"(scene\.|\.xml:\d+|:\d+:|line \d+|'[\w.]+'|\"[\w.]+\"|<\w+)", msg))


def run_one(path: str, text: str, tmpdir: str, res: int = 8) -> tuple[str, str]:
    """(outcome, detail) of loading and rendering the scene ``text`` (see the module)."""
    import pbr
    from pbr.plugins.props import SceneError
    from pbr.scene.xml import XMLError
    f = os.path.join(tmpdir, os.path.basename(path))
    with open(f, "w") as fh:
        fh.write(text)
    try:
        defaults = {k: v for k, v in (("res", res), ("width", res), ("height", res), ("spp", 1))
                    if f'<default name="{k}"' in text}
        scene = pbr.load_file(f, **defaults)
    except (SceneError, XMLError, FileNotFoundError) as e:
        msg = str(e)
        return ("rejected", msg) if _names_a_place(msg) else ("bad", f"error names no place: {msg}")
    except Exception as e:   # noqa: BLE001  (every other exception is a finding)
        return "bad", f"load raised {type(e).__name__}: {str(e)[:300]}"
    try:
        img = np.asarray(pbr.render(scene, spp=1, seed=0, progress=False, on_nonfinite="raise"))
    except Exception as e:   # noqa: BLE001
        return "bad", f"render raised {type(e).__name__}: {str(e)[:300]}"
    if not np.all(np.isfinite(img)):
        return "bad", f"image has {int(np.sum(~np.isfinite(img)))} non-finite values"
    return "rendered", ""


def fuzz(count: int, seed: int, tmpdir: str, seconds: float = float("inf")) -> dict:
    """Run up to ``count`` mutants (fewer if ``seconds`` run out): counts per outcome and
    the list of 'bad' cases (scene, mutation, detail)."""
    rng = random.Random(seed)
    texts = {p: open(p).read() for p in SCENES}
    if not os.path.exists(os.path.join(tmpdir, "data")):      # the files the scenes name
        os.symlink(os.path.join(ROOT, "scenes", "data"), os.path.join(tmpdir, "data"))
    counts = {"rejected": 0, "rendered": 0, "bad": 0}
    bad = []
    t0 = time.perf_counter()
    for _ in range(count):
        if time.perf_counter() - t0 > seconds:
            break
        path = rng.choice(SCENES)
        text, what = mutate(texts[path], rng)
        outcome, detail = run_one(path, text, tmpdir)
        counts[outcome] += 1
        if outcome == "bad":
            bad.append((os.path.basename(path), what, detail))
    counts["seconds"] = round(time.perf_counter() - t0, 1)
    return {"counts": counts, "bad": bad}


def main(argv=None):
    import tempfile
    import pbr
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--backend", default="llvm")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    with tempfile.TemporaryDirectory() as d:
        r = fuzz(a.count, a.seed, d)
    print(r["counts"])
    for scene, what, detail in r["bad"]:
        print(f"BAD {scene}: {what}: {detail}")


if __name__ == "__main__":
    main()
