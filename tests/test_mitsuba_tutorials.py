"""``benchmarks/mitsuba_tutorials.py``: the scenes of Mitsuba's tutorials rendered by pbr
and Mitsuba and compared (pbr.validate). Here on small scenes written by the test (the
runner's size scaling, its polarized-scene rule, a full run), and on the tutorials' own
scenes when their data is there (``PBR_MITSUBA_TUTORIALS``: a copy of the ``scenes/``
folder of ``mitsuba-renderer/mitsuba-tutorials``; skipped otherwise: the data is
Mitsuba's, not pbr's).

Must fail: the run reports a failure when pbr's image is 10% too bright."""

import os

import numpy as np
import pytest

import pbr
from pbr import validate
from scripts import load_script

DATA = os.environ.get("PBR_MITSUBA_TUTORIALS", "")
tutorials = load_script("benchmarks/mitsuba_tutorials.py", register=True)

SIMPLE = """<scene version="3.0.0">
    <default name="resx" value="256"/>
    <default name="resy" value="128"/>
    <integrator type="direct"/>
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, -6, 1" target="0, 0, 0" up="0, 0, 1"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="$resx"/><integer name="height" value="$resy"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.5, 0.2"/></bsdf></shape>
    <emitter type="point"><point name="position" x="2" y="-4" z="3"/><rgb name="intensity" value="40"/></emitter>
</scene>"""

POLARIZED = """<scene version="3.0.0">
    <shape type="sphere"><bsdf type="polarizer"/></shape>
</scene>"""


@pytest.fixture
def data(tmp_path):
    d = tmp_path / "scenes"
    d.mkdir()
    (d / "simple.xml").write_text(SIMPLE)
    (d / "pol.xml").write_text(POLARIZED)
    return str(tmp_path)


def test_film_size_scaled_to_res(data):
    path = os.path.join(data, "scenes", "simple.xml")
    assert tutorials.scene_params(path, 64) == {"resx": "64", "resy": "32"}
    assert np.asarray(pbr.render(pbr.load_file(path, **tutorials.scene_params(path, 16)), spp=1)).shape == (8, 16, 3)


def test_mitsuba_render_fn_reads_files_with_parameters(data):
    path = os.path.join(data, "scenes", "simple.xml")
    assert validate.mitsuba_render_fn(path, resx="12", resy="6")(seed=0, spp=1).shape == (6, 12, 3)
    with pytest.raises(TypeError, match="only apply to an XML file"):
        validate.mitsuba_render_fn({"type": "scene"}, resx="12")


def test_runner_matches_and_reports_polarized_scenes(data):
    rows = {r.scene: r for r in tutorials.main(["--data", data, "--res", "16", "--spp", "128", "--batches", "8"])}
    assert rows["simple.xml"].loads and rows["simple.xml"].verdict.passed, rows["simple.xml"]
    assert not rows["pol.xml"].loads and "out of scope: polarized plugins polarizer" in rows["pol.xml"].error


def test_runner_detects_a_biased_image(data, monkeypatch):
    render = pbr.render
    monkeypatch.setattr(pbr, "render", lambda *a, **k: np.asarray(render(*a, **k)) * 1.1)
    rows = tutorials.main(["--data", data, "--scenes", "simple", "--res", "16", "--spp", "128", "--batches", "8"])
    assert rows[0].loads and not rows[0].verdict.passed


@pytest.mark.slow
@pytest.mark.skipif(not DATA, reason="PBR_MITSUBA_TUTORIALS (the tutorials' scenes/ folder) not set")
@pytest.mark.parametrize("scene", ["cbox.xml", "simple.xml", "shadow_art.xml"])
def test_tutorial_scene_matches_mitsuba(scene):
    root, files = tutorials.find_scenes(DATA, [scene])
    row = tutorials.run_scene(files[0], root, 64, 512, 16)
    assert row.loads and row.verdict.passed, row
