"""Backend set-up: libLLVM discovery, the import-order trap, and that the backend the
tests ask for (``PBR_TEST_BACKEND``) is the one pbr and the Mitsuba references run on."""

import glob
import os
import re
import subprocess
import sys

import mitsuba as mi
import pytest

import pbr
from pbr import backend, validate

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TEST_BACKEND = os.environ.get("PBR_TEST_BACKEND", "llvm")
# libLLVM matters to the CPU backend only (a CUDA run may have none).
llvm_only = pytest.mark.skipif(pbr.get_backend() != "llvm", reason="libLLVM set-up: LLVM backend only")

SCRIPT = """
import os
os.environ.pop("DRJIT_LIBLLVM_PATH", None)
import drjit, mitsuba   # imported before pbr: Dr.Jit chooses a libLLVM on its own
import pbr
from pbr import backend
path = backend.loaded_libllvm()
try:
    pbr.set_backend("llvm")
    print("OK", path)
except pbr.BackendError as e:
    print("ERROR", path, str(e).splitlines()[0])
"""


@llvm_only
def test_usable_llvm_is_found():
    path = backend.find_libllvm()
    assert path is not None and os.path.exists(path)
    v = backend._llvm_version(path)
    assert v is None or v >= backend.MIN_LLVM


@llvm_only
def test_importing_mitsuba_first_gives_a_clear_error_not_a_crash():
    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    words = out.stdout.split()
    status, path = words[0], words[1]
    v = backend._llvm_version(path) if path != "None" else None
    if v is not None and v < backend.MIN_LLVM:
        assert status == "ERROR" and "import pbr first" in out.stdout
    else:
        assert status == "OK"


def test_tests_and_mitsuba_references_run_on_the_requested_backend():
    want = pbr.get_backend() if TEST_BACKEND == "auto" else TEST_BACKEND
    assert pbr.get_backend() == want
    assert validate.mitsuba_variant() == f"{want}_ad_spectral" == mi.variant() == backend.variant()
    assert type(mi.Float(1.0)).__module__.startswith(f"drjit.{want}")


def test_mitsuba_variant_follows_pbrs_backend(monkeypatch):
    """Must-fail for the bug it replaces: mitsuba_variant() called a function pbr does not
    have and fell back to LLVM, so under CUDA every reference was rendered on the CPU. Here
    pbr's backend is made to read 'cuda' (the variant switch itself is recorded, not done)."""
    chosen = []
    monkeypatch.setattr(backend, "_backend", "cuda")
    monkeypatch.setattr(mi, "set_variant", chosen.append)
    assert validate.mitsuba_variant() == "cuda_ad_spectral"
    assert chosen in ([], ["cuda_ad_spectral"])


def _pytest_with_backend(name):
    env = dict(os.environ, PBR_TEST_BACKEND=name)
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           os.path.join(ROOT, "tests", "test_spectrum.py")],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)


@pytest.mark.parametrize("name", ["metal", "cuda"])
def test_an_unusable_test_backend_stops_the_run(name):
    """PBR_TEST_BACKEND naming an unknown or unusable backend is an error before any test
    runs, not a silent run on another backend."""
    if name in backend.available_backends():
        pytest.skip(f"{name} is usable here")
    out = _pytest_with_backend(name)
    text = out.stdout + out.stderr
    assert out.returncode != 0
    assert f"PBR_TEST_BACKEND={name!r}" in text and "passed" not in text, text[-2000:]


def test_a_test_that_switches_the_variant_fails(tmp_path):
    """Must-fail for conftest's guard: a test that switches Mitsuba's variant (as a
    hard-coded ``mi.set_variant("llvm_ad_spectral")`` would under CUDA) is reported."""
    (tmp_path / "test_switch.py").write_text(
        "import mitsuba as mi\n\ndef test_switch():\n    mi.set_variant('scalar_rgb')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.join(ROOT, "tests"), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "conftest",
                          "--rootdir", str(tmp_path), str(tmp_path / "test_switch.py")],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert out.returncode != 0 and "something switched them" in out.stdout, out.stdout[-2000:]


# (\\? : a notebook's JSON escapes the quotes)
HARD_CODED = re.compile(r"""set_variant\(\s*\\?["']|set_backend\(\s*\\?["'](llvm|cuda)\\?["']|drjit\.llvm\b|dr\.llvm\."""
                        r"""|["']--backend["'],\s*["'](llvm|cuda)["']""")


def hard_coded_backends(text: str) -> list[int]:
    """Line numbers of ``text`` that choose a backend or variant by name."""
    return [i + 1 for i, line in enumerate(text.splitlines()) if HARD_CODED.search(line)]


def test_no_test_benchmark_or_example_hard_codes_a_backend():
    """Tests follow PBR_TEST_BACKEND, benchmarks and examples their --backend option,
    notebooks 'auto'. (Not scanned: this file, and test_cli.py, which checks the CLI's own
    --backend parsing with set_backend mocked.)"""
    assert hard_coded_backends('mi.set_variant("llvm_ad_spectral")\nx = 1\n    pbr.set_backend("llvm")') == [1, 3]
    assert hard_coded_backends('"pbr.set_backend(\\"cuda\\")\\n",\n"mi.set_variant(\\"llvm_ad_rgb\\")"') == [1, 2]
    assert hard_coded_backends('main(["render", "-o", o, "--backend", "llvm"])\npbr render s.xml --backend cuda') == [1]
    found = {}
    for sub in ("tests", "benchmarks", "examples", "notebooks"):
        for path in sorted(glob.glob(os.path.join(ROOT, sub, "**", "*.*"), recursive=True)):
            name = os.path.basename(path)
            if not path.endswith((".py", ".ipynb")) or name in ("test_backend.py", "test_cli.py"):
                continue
            with open(path, encoding="utf-8") as f:
                lines = hard_coded_backends(f.read())
            if lines:
                found[os.path.relpath(path, ROOT)] = lines
    assert not found, found
