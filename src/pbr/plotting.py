"""Optional plotting: matplotlib is not a dependency of pbr (it is the ``bench`` extra)."""

from __future__ import annotations

import sys
import types


def pyplot():
    """``matplotlib.pyplot`` (Agg backend outside Jupyter), or None when matplotlib is not
    installed. colour-science puts a ``MagicMock`` under ``sys.modules["matplotlib"]``
    when it is missing, so a successful import alone proves nothing."""
    try:
        import matplotlib
        if not isinstance(matplotlib, types.ModuleType):
            return None
        if "ipykernel" not in sys.modules:      # scripts: files only; Jupyter: inline
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        return plt
    except ImportError:
        return None
