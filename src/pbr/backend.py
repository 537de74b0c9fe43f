"""Backend selection (LLVM on the CPU, CUDA on the GPU) and locating a usable libLLVM.

Dr.Jit's LLVM backend loads ``libLLVM`` at run time. Dr.Jit 1.5 needs LLVM >= 16:
Debian 12's libLLVM-15 crashes Mitsuba's kernels and libLLVM-14 is rejected. pbr
therefore points ``DRJIT_LIBLLVM_PATH`` at a usable library *before* Dr.Jit
initialises its LLVM backend, trying in order:

1. ``DRJIT_LIBLLVM_PATH`` if the user already set it;
2. the ``karellen-llvm-core`` wheel (a pbr dependency) in this Python environment;
3. a system libLLVM of version >= 16.

All of pbr's array code uses Mitsuba's variant types (``mi.Float``, ``mi.Spectrum``,
...), so the same code runs on both backends: :func:`set_backend` selects the
``{llvm,cuda}_ad_spectral`` variant that provides them (and the geometry).
"""

from __future__ import annotations

import glob
import os
import re
import sys

MIN_LLVM = 16


class BackendError(RuntimeError):
    """No usable Dr.Jit backend (or the requested one is unavailable)."""


def _llvm_version(path: str) -> int | None:
    m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
    if m:
        return int(m.group(1))
    m = re.search(r"llvm-(\d+)", path)
    return int(m.group(1)) if m else None


def find_libllvm() -> str | None:
    """Return the path of a usable libLLVM (>= 16), or None."""
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and os.path.exists(env):
        return env
    # The karellen-llvm-core wheel installs into <prefix>/lib.
    prefixes = {sys.prefix, sys.base_prefix, os.path.dirname(os.path.dirname(sys.executable))}
    candidates = []
    for p in prefixes:
        candidates += sorted(glob.glob(os.path.join(p, "lib", "libLLVM.so.*")))
        candidates += sorted(glob.glob(os.path.join(p, "lib", "libLLVM-*.so")))
    for c in candidates:
        v = _llvm_version(c)
        if v is None or v >= MIN_LLVM:
            return c
    system = glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*") + glob.glob(
        "/usr/lib/*-linux-gnu/libLLVM-*.so*") + glob.glob("/usr/local/lib/libLLVM*.so*")
    usable = [(v, c) for c in system if (v := _llvm_version(c)) is not None and v >= MIN_LLVM]
    if usable:
        return max(usable)[1]
    return None


def _configure_llvm_path() -> None:
    if "DRJIT_LIBLLVM_PATH" in os.environ and os.path.exists(os.environ["DRJIT_LIBLLVM_PATH"]):
        return
    path = find_libllvm()
    if path is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = path


# Must run before Dr.Jit initialises its LLVM backend (i.e. before any LLVM array exists).
_configure_llvm_path()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

_backend: str | None = None

_LLVM_HELP = (
    "pbr's CPU backend needs libLLVM >= 16 (Debian 12's libLLVM-14/15 do not work with "
    "Dr.Jit 1.5). Install it with `pip install karellen-llvm-core` (a pbr dependency), or "
    "`apt-get install libllvm19`, or set DRJIT_LIBLLVM_PATH to a libLLVM.so of version >= 16."
)


def _has(backend: str) -> bool:
    jb = dr.JitBackend.LLVM if backend == "llvm" else dr.JitBackend.CUDA
    try:
        return bool(dr.has_backend(jb))
    except Exception:
        return False


def loaded_libllvm() -> str | None:
    """Path of the libLLVM already mapped into this process (Linux), or None."""
    try:
        with open("/proc/self/maps") as f:
            for line in f:
                if "libLLVM" in line:
                    return line.split()[-1]
    except OSError:
        pass
    return None


def _check_loaded_llvm() -> None:
    """Refuse an LLVM that Dr.Jit loaded before pbr could choose one (importing drjit or
    mitsuba before pbr): Debian 12's libLLVM-15 aborts the process on Mitsuba's kernels."""
    path = loaded_libllvm()
    if path is None:
        return
    v = _llvm_version(path)
    if v is not None and v < MIN_LLVM:
        raise BackendError(
            f"Dr.Jit has already loaded {path} (LLVM {v}), which cannot run pbr's kernels. This happens "
            "when drjit or mitsuba is imported before pbr: import pbr first, or set DRJIT_LIBLLVM_PATH "
            "to a libLLVM >= 16 before starting Python. " + _LLVM_HELP)


def available_backends() -> list[str]:
    """Backends that Dr.Jit can initialise on this machine, preferred first."""
    return [b for b in ("cuda", "llvm") if _has(b)]


def set_backend(name: str = "auto") -> str:
    """Select "llvm", "cuda" or "auto" (CUDA if usable, else LLVM). Returns the choice."""
    global _backend
    if name not in ("llvm", "cuda", "auto"):
        raise BackendError(f"set_backend: unknown backend {name!r}; expected 'llvm', 'cuda' or 'auto'")
    if name == "auto":
        name = "cuda" if _has("cuda") else "llvm"
    if name == "llvm":
        _check_loaded_llvm()
    if not _has(name):
        if name == "llvm":
            path = os.environ.get("DRJIT_LIBLLVM_PATH")
            raise BackendError(f"The LLVM backend is unavailable (DRJIT_LIBLLVM_PATH={path!r}). " + _LLVM_HELP)
        raise BackendError("The CUDA backend is unavailable: no CUDA-capable GPU/driver was found. "
                           "Use pbr.set_backend('llvm') for the CPU.")
    mi.set_variant(f"{name}_ad_spectral")
    _backend = name
    return name


def get_backend() -> str:
    """The active backend, selecting the default ("auto") on first use."""
    if _backend is None:
        set_backend(os.environ.get("PBR_BACKEND", "auto"))
    return _backend


def variant() -> str:
    return f"{get_backend()}_ad_spectral"


def ensure() -> None:
    """Make sure a backend is active (Mitsuba variant set); call before building arrays."""
    if _backend is None or mi.variant() != variant():
        if _backend is None:
            get_backend()
        else:
            mi.set_variant(variant())


class VariantStruct(type):
    """Metaclass for Dr.Jit structs whose field types are Mitsuba variant types:
    ``DRJIT_STRUCT`` is resolved from ``_fields`` (type names) for the active variant, so
    the classes work whichever backend is selected, and can be imported before one is."""

    @property
    def DRJIT_STRUCT(cls):
        return {k: (getattr(mi, v) if isinstance(v, str) else v) for k, v in cls._fields.items()}



class Struct(metaclass=VariantStruct):
    """Base of pbr's Dr.Jit structs. ``_fields`` maps field names (in order) to type
    names; the constructor takes fields positionally in that order or by name, and a
    field left out is ``_defaults.get(name, 0)`` converted to its type."""

    _fields: dict = {}
    _defaults: dict = {}

    def __init__(self, *args, **kwargs):
        names = list(self._fields)
        if len(args) > len(names):
            raise TypeError(f"{type(self).__name__}() takes at most {len(names)} fields, got {len(args)}")
        given = dict(zip(names, args))
        for k, v in kwargs.items():
            if k not in self._fields or k in given:
                raise TypeError(f"{type(self).__name__}(): unexpected or repeated field {k!r}")
            given[k] = v
        for name, tp in type(self).DRJIT_STRUCT.items():
            v = given.get(name)
            setattr(self, name, v if v is not None else tp(self._defaults.get(name, 0)))
