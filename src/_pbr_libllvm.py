"""Point Dr.Jit at a usable libLLVM before anything imports it (standard library only).

Dr.Jit's LLVM backend loads ``libLLVM`` when it starts, which ``import mitsuba`` already
does. Dr.Jit 1.5 needs LLVM >= 16: Debian 12's libLLVM-15 crashes Mitsuba's kernels and
libLLVM-14 is rejected. Once a library is loaded it cannot be replaced, so the choice
must happen before the first ``import drjit`` / ``import mitsuba`` of the process.

pbr's installation puts ``pbr-libllvm.pth`` in site-packages; Python runs its one line
(``import _pbr_libllvm``) at start-up, so ``DRJIT_LIBLLVM_PATH`` is set in every
interpreter of that environment, whatever the user imports first. ``pbr.backend`` calls
:func:`configure` again (for interpreters started without site-packages processing).

The search order: ``DRJIT_LIBLLVM_PATH`` if the user set it to an existing file; the
``karellen-llvm-core`` wheel (a pbr dependency, installed into ``<prefix>/lib``); a
system libLLVM of version >= 16. Nothing is set when none is found.
"""

from __future__ import annotations

import glob
import os
import re
import sys

MIN_LLVM = 16


def llvm_version(path: str) -> int | None:
    """The major LLVM version in a library's file name or directory, or None."""
    m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
    if m:
        return int(m.group(1))
    m = re.search(r"llvm-(\d+)", path)
    return int(m.group(1)) if m else None


def find_libllvm() -> str | None:
    """The path of a usable libLLVM (>= 16), or None."""
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and os.path.exists(env):
        return env
    prefixes = dict.fromkeys((sys.prefix, sys.base_prefix, os.path.dirname(os.path.dirname(sys.executable))))
    candidates = []
    for p in prefixes:
        candidates += sorted(glob.glob(os.path.join(p, "lib", "libLLVM.so.*")))
        candidates += sorted(glob.glob(os.path.join(p, "lib", "libLLVM-*.so")))
    for c in candidates:
        v = llvm_version(c)
        if v is None or v >= MIN_LLVM:
            return c
    system = glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*") + glob.glob(
        "/usr/lib/*-linux-gnu/libLLVM-*.so*") + glob.glob("/usr/local/lib/libLLVM*.so*")
    usable = [(v, c) for c in system if (v := llvm_version(c)) is not None and v >= MIN_LLVM]
    return max(usable)[1] if usable else None


def configure() -> None:
    """Set ``DRJIT_LIBLLVM_PATH`` to :func:`find_libllvm`'s answer unless it already
    names an existing file. Never raises: it runs at interpreter start-up."""
    try:
        current = os.environ.get("DRJIT_LIBLLVM_PATH")
        if current and os.path.exists(current):
            return
        path = find_libllvm()
        if path is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = path
    except Exception:   # a start-up hook must not break the interpreter
        pass


configure()
