"""The scene's Dr.Jit tables as a whole: one walk over the arrays that pbr's scene
objects hold (texture, BSDF, light and medium tables), for the operations that must see
all of them: aligned memory (:func:`own_table_memory`), forward-mode leaves
(:func:`pbr.scene.params.tables_as_leaves`) and ``pbr.freeze``'s state.
"""

from __future__ import annotations

import drjit as dr
import numpy as np

from ..backend import get_backend
from .params import ParamOwner


def map_tables(root, fn) -> None:
    """Replace every flat Dr.Jit array ``x`` reachable from ``root`` through pbr objects,
    lists, tuples and dicts by ``fn(x)`` (nested arrays are visited per component,
    tensors through their flat array). Values owned by the user (``ParamOwner.params``)
    are not visited."""
    seen = set()

    def visit(x):
        if x is None or isinstance(x, (bool, int, float, str, bytes)):
            return x
        if dr.is_tensor_v(x):
            a = visit(x.array)
            return x if a is x.array else type(x)(a, x.shape)
        if dr.is_array_v(x):
            if dr.depth_v(x) == 1:
                return fn(x)
            for i in range(len(x)):
                c = visit(x[i])
                if c is not x[i]:
                    x[i] = c
            return x
        if id(x) in seen:
            return x
        if isinstance(x, tuple):
            items = [visit(v) for v in x]
            changed = any(a is not b for a, b in zip(items, x))
            return (type(x)(*items) if hasattr(x, "_fields") else tuple(items)) if changed else x
        seen.add(id(x))
        if isinstance(x, list):
            for i, v in enumerate(x):
                x[i] = visit(v)
        elif isinstance(x, dict):
            for k, v in x.items():
                x[k] = visit(v)
        elif type(x).__module__.startswith("pbr") and hasattr(x, "__dict__"):
            user = "params" if isinstance(x, ParamOwner) else None
            for k, v in vars(x).items():
                if k != user:
                    c = visit(v)
                    if c is not v:
                        setattr(x, k, c)
        return x

    visit(root)


def own_table_memory(root) -> None:
    """Give every table reachable from ``root`` memory that is 64-byte aligned.

    On the LLVM backend a Dr.Jit array built from a NumPy array maps NumPy's buffer
    without a copy. NumPy aligns to 16 bytes, Dr.Jit's kernels to 64: a mapped input is
    compiled as an unaligned load, and since the alignment of a fresh NumPy buffer varies,
    rebuilding the tables changed kernel source and forced a recompile of every kernel
    at every optimisation step. A copy into an aligned buffer (a memcpy, no kernel)
    keeps the source stable."""
    if get_backend() != "llvm":
        return

    def realign(x):
        if x.state != dr.VarState.Evaluated or dr.grad_enabled(x):
            return x
        data = np.asarray(x)                     # a view of the array's memory
        if data.ctypes.data % 64 == 0:
            return x
        raw = np.empty(data.nbytes + 64, np.uint8)
        start = -raw.ctypes.data % 64
        aligned = raw[start:start + data.nbytes].view(data.dtype)
        aligned[:] = data
        return type(x)(aligned)                  # mapped in turn; Dr.Jit keeps it alive

    map_tables(root, realign)
