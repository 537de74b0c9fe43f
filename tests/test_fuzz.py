"""The scene fuzzer (tests/fuzz_scenes.py): seeded mutants of the shipped XML scenes are
either rejected with an error naming the place or render a finite image; nothing else
(a crash, an exception from inside pbr or Dr.Jit, an error naming no place, NaN/Inf)."""

import numpy as np
import pytest

import pbr
import fuzz_scenes as F


def _report(r):
    return "\n".join(f"{s}: {what}: {detail}" for s, what, detail in r["bad"])


def test_mutants_are_rejected_clearly_or_render_finite(tmp_path):
    r = F.fuzz(count=40, seed=7, tmpdir=str(tmp_path), seconds=60)
    c = r["counts"]
    assert c["rejected"] + c["rendered"] >= 20, c          # it ran, and both outcomes occur
    assert c["rejected"] > 0 and c["rendered"] > 0, c
    assert not r["bad"], _report(r)


@pytest.mark.slow
def test_many_mutants(tmp_path):
    r = F.fuzz(count=600, seed=11, tmpdir=str(tmp_path))
    assert not r["bad"], _report(r)


def test_findings_are_recognised(tmp_path, monkeypatch):
    """Must-fail: an internal exception, an error naming no place and a NaN image are 'bad'."""
    text = open(F.SCENES[0]).read()
    monkeypatch.setattr(pbr, "load_file", lambda *a, **k: {}["missing"])
    assert F.run_one(F.SCENES[0], text, str(tmp_path))[0] == "bad"
    from pbr.plugins.props import SceneError

    def vague(*a, **k):
        raise SceneError("something is wrong")
    monkeypatch.setattr(pbr, "load_file", vague)
    assert F.run_one(F.SCENES[0], text, str(tmp_path))[0] == "bad"
    monkeypatch.undo()
    monkeypatch.setattr(pbr, "render", lambda *a, **k: np.full((2, 2, 3), np.nan, np.float32))
    assert F.run_one(F.SCENES[0], text, str(tmp_path)) == ("bad", "image has 12 non-finite values")
