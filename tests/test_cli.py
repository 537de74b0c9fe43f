"""CLI: argument parsing, outputs, summary line and error handling, with a fake pbr API."""
import os
import subprocess
import sys

import pbr
import numpy as np
import pytest

from pbr import cli
from pbr.image import read_image

H, W = 4, 6


class FakeScene:
    def __init__(self, spp=None):
        if spp is not None:
            self.spp = spp


@pytest.fixture
def fake(monkeypatch, tmp_path):
    """Replace pbr's public API with recorders; run in tmp_path."""
    calls = {}
    img = np.linspace(0, 1, H * W * 3, dtype=np.float32).reshape(H, W, 3)

    def set_backend(name):
        calls["backend"] = name

    def cornell_box():
        return {"type": "scene", "marker": "cornell"}

    def load_dict(d):
        calls["load_dict"] = d
        return FakeScene(spp=32)

    def load_file(path, **kw):
        calls["load_file"] = (path, kw)
        return FakeScene(spp=kw.get("spp"))

    def render(scene, spp=0, seed=0, on_nonfinite="warn"):
        calls["render"] = dict(spp=spp, seed=seed)
        calls["on_nonfinite"] = on_nonfinite
        return img

    for name, f in dict(set_backend=set_backend, cornell_box=cornell_box, load_dict=load_dict,
                        load_file=load_file, render=render).items():
        monkeypatch.setattr(pbr, name, f, raising=False)
    monkeypatch.chdir(tmp_path)
    calls["img"] = img
    return calls


def test_builtin_cornell_defaults(fake, tmp_path, capsys):
    assert cli.main(["render", "--spp", "16", "--seed", "3", "--png", "pics/c.png"]) == 0
    assert fake["backend"] == "auto"
    assert fake["load_dict"]["marker"] == "cornell"
    assert fake["render"] == dict(spp=16, seed=3)
    assert fake["on_nonfinite"] == "warn"
    np.testing.assert_array_equal(read_image(tmp_path / "out" / "cornell.exr"), fake["img"])
    assert (tmp_path / "pics" / "c.png").is_file()
    out = capsys.readouterr().out.strip()
    assert out.startswith(f"rendered cornell: {W}x{H}, 16 spp, ")
    assert out.endswith(f"-> {os.path.join('out', 'cornell.exr')}, pics/c.png")
    assert "Msamples/s" in out and " s, " in out
    assert len(out.splitlines()) == 1


def test_scene_default_spp_from_scene_object(fake, capsys):
    assert cli.main(["render", "--backend", "llvm", "-o", "x.exr"]) == 0
    assert fake["backend"] == "llvm"
    assert fake["render"]["spp"] == 0  # 0 means "scene default"
    assert ", 32 spp, " in capsys.readouterr().out


def test_unknown_spp_prints_question_mark(fake, tmp_path, capsys):
    scene = tmp_path / "box.xml"
    scene.write_text("<scene version='3.0.0'/>")
    assert cli.main(["render", str(scene)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"rendered box: {W}x{H}, ? spp, ") and "? Msamples/s" in out
    assert (tmp_path / "out" / "box.exr").is_file()


def test_defines_reach_load_file_typed(fake, tmp_path, capsys):
    scene = tmp_path / "s.xml"
    scene.write_text("<scene version='3.0.0'/>")
    rc = cli.main(["render", str(scene), "-D", "spp=16", "-D", "scale=0.5",
                   "-D", "name=glass", "-D", "expr=a=b", "-o", "r.exr"])
    assert rc == 0
    path, kw = fake["load_file"]
    assert path == str(scene)
    assert kw == {"spp": 16, "scale": 0.5, "name": "glass", "expr": "a=b"}
    assert type(kw["spp"]) is int and type(kw["scale"]) is float
    assert ", 16 spp, " in capsys.readouterr().out


def test_png_only_output_with_tonemap(fake, tmp_path, capsys):
    assert cli.main(["render", "-o", "img.png", "--tonemap", "reinhard"]) == 0
    assert (tmp_path / "img.png").is_file()
    assert not (tmp_path / "out").exists()
    assert capsys.readouterr().out.strip().endswith("-> img.png")


def test_missing_scene_file(fake, capsys):
    assert cli.main(["render", "no/such/scene.xml"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pbr: error: ") and "no/such/scene.xml" in err
    assert "Traceback" not in err
    assert "render" not in fake and "load_file" not in fake


@pytest.mark.parametrize("exc", [ValueError("scene.shapes.foo: unknown parameter 'bar'"),
                                 FileNotFoundError("mesh.obj not found")])
def test_load_errors_are_reported(fake, monkeypatch, tmp_path, capsys, exc):
    scene = tmp_path / "s.xml"
    scene.write_text("<scene/>")

    def load_file(path, **kw):
        raise exc

    monkeypatch.setattr(pbr, "load_file", load_file, raising=False)
    assert cli.main(["render", str(scene)]) == 2
    err = capsys.readouterr().err
    assert err == f"pbr: error: {exc}\n"


def test_backend_error(fake, monkeypatch, capsys):
    def set_backend(name):
        raise pbr.BackendError(f"backend {name!r} unavailable: no CUDA device")

    monkeypatch.setattr(pbr, "set_backend", set_backend, raising=False)
    assert cli.main(["render", "--backend", "cuda"]) == 2
    err = capsys.readouterr().err
    assert err == "pbr: error: backend 'cuda' unavailable: no CUDA device\n"


def test_bad_output_extension_fails_before_render(fake, capsys):
    assert cli.main(["render", "-o", "out.jpg"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pbr: error: ") and "out.jpg" in err and ".exr" in err
    assert "render" not in fake


def test_nonfinite_image_is_an_error(fake, monkeypatch, capsys):
    bad = np.zeros((2, 2, 3), np.float32)
    bad[0, 0, 0] = np.nan
    monkeypatch.setattr(pbr, "render", lambda scene, spp=0, seed=0, **kw: bad, raising=False)
    assert cli.main(["render"]) == 2
    assert "1 non-finite" in capsys.readouterr().err


def test_render_bugs_keep_their_traceback(fake, monkeypatch):
    def render(scene, spp=0, seed=0, **kw):
        raise ValueError("internal bug")

    monkeypatch.setattr(pbr, "render", render, raising=False)
    with pytest.raises(ValueError, match="internal bug"):
        cli.main(["render"])


def test_usage_errors(fake, capsys):
    assert cli.main([]) == 2
    assert cli.main(["render", "-D", "novalue"]) == 2
    assert "name=value" in capsys.readouterr().err
    assert cli.main(["render", "--backend", "metal"]) == 2
    assert cli.main(["render", "--tonemap", "aces"]) == 2
    assert cli.main(["render", "--spp", "-1"]) == 2
    assert cli.main(["render", "-D", "spp=4"]) == 2  # -D needs a scene file
    assert "-D" in capsys.readouterr().err
    assert cli.main(["render", "--help"]) == 0
    assert "render" not in fake


def test_adaptive_options(tmp_path, monkeypatch, capsys):
    """--target-error / --time-budget render adaptively (a real render) and print the estimate."""
    monkeypatch.chdir(tmp_path)
    assert cli.main(["render", "--backend", pbr.get_backend(), "--res", "12", "--spp", "128",
                     "--target-error", "0.3", "--time-budget", "60"]) == 0
    out = capsys.readouterr().out
    assert "adaptive render: target relative error 0.3" in out and "rendered cornell: 12x12, mean " in out
    assert cli.main(["render", "--target-error", "-1"]) == 2
    assert "--target-error must be > 0" in capsys.readouterr().err


def test_python_dash_m_entry(tmp_path):
    """``python -m pbr`` runs the CLI (a usage error here, so no rendering is needed)."""
    r = subprocess.run([sys.executable, "-m", "pbr", "render", str(tmp_path / "none.xml")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.startswith("pbr: error: scene file not found")
    assert "Traceback" not in r.stderr


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        cli.build_parser().parse_args(["--version"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"pbr {pbr.__version__} (Dr.Jit ") and "Mitsuba 3." in out


@pytest.mark.parametrize("args, size", [(["--res", "20"], (20, 15)), (["--width", "40"], (40, 30)),
                                        (["--height", "12"], (16, 12)), (["--width", "9", "--height", "5"], (9, 5))])
def test_film_size_options_apply_to_any_scene(tmp_path, monkeypatch, args, size):
    """Any scene file: the gallery's film (320 x 240, 4:3) resized by --res/--width/--height."""
    monkeypatch.chdir(tmp_path)
    scene = os.path.join(os.path.dirname(os.path.dirname(__file__)), "scenes", "materials_gallery.xml")
    d = {}
    monkeypatch.setattr(pbr, "render", lambda s, **k: d.setdefault("size", s.sensors[0].film.size) and
                        np.zeros((size[1], size[0], 3), np.float32))
    assert cli.main(["render", scene, "-o", "g.exr", *args]) == 0
    assert tuple(d["size"]) == size


CROPPED = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="200"/><integer name="height" value="100"/>
      <integer name="crop_offset_x" value="100"/><integer name="crop_offset_y" value="20"/>
      <integer name="crop_width" value="80"/><integer name="crop_height" value="60"/></film>
  </sensor>
  <shape type="sphere"/><emitter type="constant"/>
</scene>
"""
CROPPED_PBRT = """LookAt 0 0 4  0 0 0  0 1 0
Camera "perspective" "float fov" 40
Film "rgb" "integer xresolution" 200 "integer yresolution" 100 "integer pixelbounds" [100 180 20 80]
WorldBegin
LightSource "infinite" "rgb L" [1 1 1]
Shape "sphere"
"""


@pytest.mark.parametrize("name, text", [("crop.xml", CROPPED), ("crop.pbrt", CROPPED_PBRT)])
@pytest.mark.parametrize("args, window", [(["--res", "40"], (20, 4, 16, 12)), (["--height", "50"], (50, 10, 40, 30)),
                                          (["--width", "10", "--height", "10"], (5, 2, 4, 6))])
def test_film_size_options_scale_a_crop_window(tmp_path, monkeypatch, name, text, args, window):
    """A film with a crop window in pixels (Mitsuba's crop_*, pbrt-v4's pixelbounds) keeps
    the same part of the view: the window scales with the film (before, --res 40 on a
    200 x 100 film cropped at x 100..180 was refused: 'exceeds the film's 40 pixels')."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / name).write_text(text)
    got = {}

    def render(s, **k):
        film = s.sensors[0].film
        got["window"] = (*film.crop_offset, *film.crop_size)
        return np.zeros((film.crop_size[1], film.crop_size[0], 3), np.float32)

    monkeypatch.setattr(pbr, "render", render)
    assert cli.main(["render", name, "-o", "c.exr", *args]) == 0
    assert got["window"] == window


@pytest.mark.parametrize("args, message", [(["--res", "16", "--width", "3"], "give either --res or --width/--height"),
                                           (["--height", "0"], "--height must be a positive integer, got 0")])
def test_bad_film_size_options(fake, capsys, args, message):
    assert cli.main(["render", *args]) == 2
    assert f"pbr: error: {message}" in capsys.readouterr().err


@pytest.mark.parametrize("out", ["/proc/no/such.exr", "/proc/such.exr", "/proc/such.png"])
def test_write_failure_is_an_error_line(fake, capsys, out):
    """A folder that cannot be made (OSError) or a file the writer cannot open (OpenEXR's
    and Mitsuba's RuntimeError)."""
    assert cli.main(["render", "-o", out]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pbr: error: cannot write {out}") and "Traceback" not in err


def test_write_under_a_file_names_it(fake, capsys):
    """A file where the output's folder should be: said so (os.makedirs' own message was
    'File exists')."""
    open("plain", "w").close()
    assert cli.main(["render", "-o", "plain/x.exr"]) == 2
    assert capsys.readouterr().err == "pbr: error: cannot write plain/x.exr: plain is not a folder\n"
