"""Backend selection (LLVM on the CPU, CUDA on the GPU), a usable libLLVM, and the
Mitsuba variant pbr runs on.

Dr.Jit's LLVM backend loads ``libLLVM`` when it starts (``import mitsuba`` starts it).
Dr.Jit 1.5 needs LLVM >= 16: Debian 12's libLLVM-15 crashes Mitsuba's kernels and
libLLVM-14 is rejected. :mod:`_pbr_libllvm` points ``DRJIT_LIBLLVM_PATH`` at a usable
library: pbr's installation runs it at interpreter start-up (``pbr-libllvm.pth``), so
importing ``mitsuba`` or ``drjit`` before ``pbr`` works; importing pbr runs it again for
interpreters started without site-packages (``python -S``, ``PYTHONPATH`` checkouts).

All of pbr's array code uses Mitsuba's variant types (``mi.Float``, ``mi.Spectrum``,
...), so the same code runs on both backends: :func:`set_backend` selects the
``{llvm,cuda}_ad_spectral`` variant that provides them (and the geometry).

**The user's variant.** :func:`set_backend` makes pbr's variant Mitsuba's active one (it
is a request for it). Every other pbr call (loading, rendering, traversal, updates)
switches to pbr's variant while it runs and back to the variant it found afterwards
(:func:`pbr_variant`), so a script that uses Mitsuba beside pbr (say ``llvm_ad_rgb``
references) keeps its variant. pbr's backend follows the user's variant when one is set
before pbr's first call (``llvm_*`` -> LLVM, ``cuda_*`` -> CUDA).
"""

from __future__ import annotations

import contextlib
import functools
import os
import warnings

from _pbr_libllvm import MIN_LLVM, configure as _configure_llvm_path, find_libllvm  # noqa: F401
from _pbr_libllvm import llvm_version as _llvm_version

# Must run before Dr.Jit initialises its LLVM backend (a no-op when pbr-libllvm.pth did it).
_configure_llvm_path()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402


class BackendError(RuntimeError):
    """No usable Dr.Jit backend (or the requested one is unavailable)."""


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
    """Refuse an LLVM that Dr.Jit loaded before pbr could choose one: without pbr's
    start-up hook (``pbr-libllvm.pth``: missing from this environment, or ``python -S``),
    importing drjit or mitsuba before pbr lets Dr.Jit pick Debian 12's libLLVM-15, which
    aborts the process on Mitsuba's kernels."""
    path = loaded_libllvm()
    if path is None:
        return
    v = _llvm_version(path)
    if v is not None and v < MIN_LLVM:
        raise BackendError(
            f"Dr.Jit has already loaded {path} (LLVM {v}), which cannot run pbr's kernels. This happens "
            "when drjit or mitsuba is imported before pbr in an environment where pbr's start-up hook "
            "(pbr-libllvm.pth, installed with pbr) did not run: reinstall pbr (`pip install -e .` or "
            "`make test`), import pbr first, or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16 before "
            "starting Python. " + _LLVM_HELP)


def available_backends() -> list[str]:
    """Backends that Dr.Jit can initialise on this machine, preferred first."""
    return [b for b in ("cuda", "llvm") if _has(b)]


def _select(name: str) -> str:
    """Check that backend ``name`` ("llvm", "cuda" or "auto") is usable and make it
    pbr's backend; Mitsuba's active variant is left alone. Returns the choice."""
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
    _backend = name
    return name


def set_backend(name: str = "auto") -> str:
    """Select "llvm", "cuda" or "auto" (CUDA if usable, else LLVM), and make its
    ``{name}_ad_spectral`` variant Mitsuba's active one (pbr's arrays are its types; a
    Mitsuba reference render to compare with wants it too). Returns the choice."""
    name = _select(name)
    if mi.variant() != f"{name}_ad_spectral":
        mi.set_variant(f"{name}_ad_spectral")
    return name


def _default_backend() -> str:
    """``PBR_BACKEND``; else the backend of the variant the user made active (``llvm_*``,
    ``cuda_*``), so that pbr's arrays live where the user's do; else "auto"."""
    if os.environ.get("PBR_BACKEND"):
        return os.environ["PBR_BACKEND"]
    user = mi.variant() or ""
    prefix = user.split("_", 1)[0]
    return prefix if prefix in ("llvm", "cuda") else "auto"


def get_backend() -> str:
    """The active backend, selecting the default on first use (see :func:`_default_backend`);
    Mitsuba's variant is not changed here."""
    if _backend is None:
        _select(_default_backend())
    return _backend


def variant() -> str:
    return f"{get_backend()}_ad_spectral"


def ensure() -> None:
    """Make pbr's variant Mitsuba's active one (selecting the default backend on first
    use); call before building arrays. Public entry points use :func:`pbr_variant`,
    which also switches back."""
    v = variant()
    if mi.variant() != v:
        mi.set_variant(v)


def ensure_any() -> None:
    """Make sure some Mitsuba variant is active (pbr's when none is): Mitsuba's scalar
    types (``mi.ScalarTransform4f``...) need one, and are the same in every variant."""
    if mi.variant() is None:
        ensure()


class VariantWarning(RuntimeWarning):
    """pbr switched Mitsuba's variant (and back) around a call; see :func:`pbr_variant`."""


_depth = 0            # nesting of pbr_variant blocks
_warned = False


@contextlib.contextmanager
def pbr_variant():
    """Within the block Mitsuba's active variant is pbr's; at the end of the outermost
    block the variant that was active before is restored (when there was one).

    Mitsuba's ``set_variant`` costs about 0.2 s (it reloads Mitsuba's Python integrators;
    measured with Mitsuba 3.9.1), so a call made while another variant is active costs
    about 0.4 s more; pbr says so once per process (:class:`VariantWarning`)."""
    global _depth, _warned
    outer = _depth == 0
    before = mi.variant() if outer else None
    _depth += 1
    try:
        if outer and before != variant():
            ensure()
            if before is not None and not _warned:
                _warned = True
                warnings.warn(
                    f"pbr runs on Mitsuba's {variant()!r} variant (its arrays are that variant's types); "
                    f"the active variant is {before!r}, so each pbr call switches to {variant()!r} and back "
                    "(about 0.4 s per call, Mitsuba reloads its Python integrators on every switch). "
                    "Call pbr.set_backend() to keep pbr's variant active.", VariantWarning, stacklevel=4)
        yield
    finally:
        _depth -= 1
        if outer and before is not None and mi.variant() != before:
            mi.set_variant(before)


def uses_pbr_variant(fn):
    """Decorator: ``fn`` runs inside :func:`pbr_variant`."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with pbr_variant():
            return fn(*args, **kwargs)
    return wrapper


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
