"""The shipped scene file and notebook keep working."""

import os

import numpy as np

import pbr
from mitsuba_scenes import run_notebook

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_scene_file_equals_builtin_cornell_box():
    a = np.asarray(pbr.render(pbr.load_file(os.path.join(ROOT, "scenes", "cornell_box.xml"), spp=4, res=16), seed=2))
    b = np.asarray(pbr.render(pbr.load_dict(pbr.cornell_box(16, 4)), seed=2))
    assert np.allclose(a, b, atol=1e-5)


def test_quickstart_notebook_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    ns = run_notebook(os.path.join(ROOT, "notebooks", "quickstart.ipynb"))
    assert os.path.exists(tmp_path / "out" / "notebook_cornell.png")
    red_wall = np.asarray(ns["img"])[64, 5]
    blue_wall = np.asarray(ns["img2"])[64, 5]
    assert red_wall[0] > red_wall[2] and blue_wall[2] > blue_wall[0]
