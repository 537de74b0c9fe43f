"""``pbr.convergence`` (error vs time as an API) and the notebook that uses it.

- On a 16x16 Cornell box, path's relMSE against a 4096-spp reference falls from 4 to
  64 spp by more than 4x (expected 16x) and its curve's slope is below -0.5; path with
  max_depth 2 (direct light only) stays far above (a bias: the slope flattens). Must
  fail: with the reference of another scene (the box without its red wall's colour) the
  same check fails (checked by ``test_wrong_reference_is_seen``).
- Samplers are put in the sensor's ``sampler`` entry (an unknown sampler type is the
  scene loader's error naming ``sensor.sampler``); integrators given by name, dict or
  {label: dict} get those labels.
- ``time_to`` / ``spp_to`` interpolate log-log; bad input raises clear errors.
- notebooks/speed_vs_accuracy.ipynb runs (small sizes).
"""

import os

import numpy as np
import pytest

import pbr
from pbr import validate
from pbr.convergence import ConvergenceTable, slope, time_to_reach
from mitsuba_scenes import run_notebook

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def box():
    d = pbr.cornell_box(16)
    ref_scene = pbr.load_dict(d)
    ref = validate.estimate(lambda seed, spp: pbr.render(ref_scene, seed=seed, spp=spp, progress=False),
                            4096, batches=16, seed=3)
    return d, ref


def test_path_converges_and_short_depth_is_biased(box):
    d, ref = box
    t = pbr.convergence(d, integrators={"path": {"type": "path", "max_depth": 8},
                                        "direct only": {"type": "path", "max_depth": 2}},
                        reference=ref, spp=[4, 16, 64], reps=3)
    assert t.labels() == ["path", "direct only"] and len(t) == 6
    path, direct = t.curve("path"), t.curve("direct only")
    assert [r["spp"] for r in path] == [4, 16, 64]
    assert path[-1]["relmse"] < path[0]["relmse"] / 4, t
    assert t.slopes()["path"] < -0.5, t
    assert direct[-1]["relmse"] > 5 * path[-1]["relmse"], t
    assert all(r["time_s"] >= 0 and r["ref_floor"] > 0 for r in t)
    assert t.time_to(1e-9) == {"path": None, "direct only": None}
    ax = t.plot(target=0.01)            # matplotlib is in the test extra
    assert ax is not None and len(ax.get_lines()) == 3


def test_wrong_reference_is_seen(box):
    d, _ = box
    other = dict(d)
    other["red"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}
    s = pbr.load_dict(other)
    wrong = validate.estimate(lambda seed, spp: pbr.render(s, seed=seed, spp=spp, progress=False),
                              1024, batches=16, seed=4)
    t = pbr.convergence(d, integrators="path", reference=wrong, spp=[4, 16, 64], reps=3)
    c = t.curve(t.labels()[0])
    assert not c[-1]["relmse"] < c[0]["relmse"] / 4, t


def test_samplers_go_in_the_sensor_and_labels(box):
    d, ref = box
    t = pbr.convergence(d, integrators=["path"], samplers=[{"type": "independent"}], reference=ref.mean, spp=[4])
    assert t[0]["sampler"] == "independent" and t[0]["ref_floor"] == 0.0
    t2 = pbr.convergence(d, integrators="path", samplers={"A": {"type": "independent"}, "B": "independent"},
                         reference=ref.mean, spp=[4])
    assert t2.labels() == ["path / A", "path / B"]
    with pytest.raises(pbr.SceneError, match="sampler"):
        pbr.convergence(d, samplers=[{"type": "no-such-sampler"}], reference=ref.mean, spp=[4])


def test_budget_bounds_the_curve(box):
    d, ref = box
    t = pbr.convergence(d, reference=ref.mean, budget=0.05, max_spp=1 << 14)
    assert t.curve(t.labels()[0])[-1]["spp"] < 1 << 14


def test_helpers_and_errors(box):
    d, ref = box
    assert time_to_reach([1.0, 4.0], [0.1, 0.025], 0.05) == pytest.approx(2.0)
    assert slope([1, 2, 4], [0.4, 0.2, 0.1]) == pytest.approx(-1.0)
    rows = [{"label": "a", "spp": n, "time_s": n / 10, "relmse": 1 / n} for n in (4, 16)]
    t = ConvergenceTable(rows)
    assert t.spp_to(1 / 8)["a"] == pytest.approx(8.0) and t.time_to(1 / 8)["a"] == pytest.approx(0.8)
    with pytest.raises(TypeError, match="scene dict"):
        pbr.convergence(pbr.load_dict(d))
    with pytest.raises(TypeError, match="integrators"):
        pbr.convergence(d, integrators=[3])
    with pytest.raises(ValueError, match="budget"):
        pbr.convergence(d, budget=-1)
    with pytest.raises(ValueError, match="reference is"):
        pbr.convergence(d, reference=np.zeros((2, 2, 3)), spp=[4])


def test_notebook_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    ns = run_notebook(os.path.join(ROOT, "notebooks", "speed_vs_accuracy.ipynb"),
                      {"RES, BUDGET, MAX_SPP, REF_SPP, REPS = 32, 4.0, 1024, 8192, 3":
                       "RES, BUDGET, MAX_SPP, REF_SPP, REPS = 16, 0.3, 64, 512, 1"})
    assert len(ns["table"]) >= 4 and ns["best"] in ns["integrators"]
    assert ns["info"].spp.max() > ns["info"].spp.min()
