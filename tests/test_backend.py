"""Backend set-up: libLLVM discovery and the import-order trap."""

import os
import subprocess
import sys

import pbr
from pbr import backend

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


def test_usable_llvm_is_found():
    path = backend.find_libllvm()
    assert path is not None and os.path.exists(path)
    v = backend._llvm_version(path)
    assert v is None or v >= backend.MIN_LLVM


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
