"""The repository's scripts (benchmarks/, scenes/data/) imported as modules by the tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def load_script(relpath: str, register: bool = False):
    """The script at ``ROOT / relpath`` as a module named after its file; ``register``
    puts it in ``sys.modules`` first (dataclasses defined there look their module up)."""
    path = ROOT / relpath
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    if register:
        sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod
