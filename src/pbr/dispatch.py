"""Calling one of several families (BSDF, light) per lane, and loops within one call.

Normally a ``dr.switch``: one symbolic call, each lane runs its family's code. Forward-
mode differentiation is the exception: Dr.Jit 1.5 cannot forward-propagate through two
symbolic calls that share an implicit differentiable input (a parameter table) within
one traversal ("tried to forward-propagate derivatives across edge ... outside of the
current dr.isolate_grad() scope"), and a PRB forward pass has several such calls per
path vertex. Inside :func:`by_lane` every family is therefore evaluated on its own lanes
and the results are selected, which is plain differentiable arithmetic (and costs one
evaluation per family instead of one in all).
"""

from __future__ import annotations

import contextlib

import drjit as dr

_by_lane = False
_whole_packets = False


@contextlib.contextmanager
def by_lane():
    """Within the block, :func:`switch` evaluates every family and selects per lane."""
    global _by_lane
    prev, _by_lane = _by_lane, True
    try:
        yield
    finally:
        _by_lane = prev


@contextlib.contextmanager
def whole_packets():
    """Within the block, :func:`when_any` runs its function on every packet (no symbolic
    conditional): for adjoint passes, which Dr.Jit 1.5 aborted (a fatal error, not an
    exception) with these conditionals in the path loop (the gallery's parameters in
    ``tests/test_ad_every_parameter.py``)."""
    global _whole_packets
    prev, _whole_packets = _whole_packets, True
    try:
        yield
    finally:
        _whole_packets = prev


def branching() -> bool:
    """Whether code may use symbolic conditionals to skip work (not within
    :func:`by_lane`, where every branch is plain arithmetic for the same reason)."""
    return not _by_lane


def switch(index, fns, *args, outside=()):
    """``fns[index](*args)`` per lane; the last of ``args`` is the ``active`` mask.

    ``outside``: indices of functions that trace rays. They are called on their own lanes
    outside the symbolic call: on CUDA, Dr.Jit compiles a symbolic call over several
    functions into OptiX *direct callables*, in which OptiX does not allow ray tracing."""
    if outside and not _by_lane:
        return _switch_outside(index, fns, args, outside)
    if not _by_lane:
        return dr.switch(index, fns, *args)
    *rest, active = args
    out = None
    for k, fn in enumerate(fns):
        mine = active & (index == k)
        r = fn(*rest, mine)
        out = r if out is None else _select(mine, r, out)
    return _select(active, out, None)


def when_any(mask, fn, *args, otherwise=None, label="when any"):
    """``fn(*args)`` where some lane of ``mask`` is set, zeros elsewhere: a symbolic
    conditional, so that a vector packet with no such lane skips ``fn``'s code (Dr.Jit's
    LLVM backend branches on whether any lane of a packet takes a branch), as a
    symbolic call skips a callee that no lane of a packet calls. ``fn``'s result on
    lanes outside ``mask`` must not matter; ``otherwise``: the result of skipped packets
    (zeros shaped like ``fn``'s result if None). Within :func:`by_lane` and
    :func:`whole_packets` it is plain ``fn(*args)``."""
    if _by_lane or _whole_packets:
        return fn(*args)
    shape = []

    def on(*a):
        r = fn(*a)
        shape.append(r)
        return r

    def off(*a):
        if otherwise is not None:
            return otherwise
        # (a literal False mask: Dr.Jit traces this branch only; fn's code is unused)
        return _zeros(shape[0] if shape else fn(*a))

    return dr.if_stmt((), mask, lambda: on(*args), lambda: off(*args), label=label)


def _zeros(v):
    """Zeros shaped like the result tree ``v``."""
    return _tree_map(lambda x, _: dr.zeros(type(x), dr.width(x)), v, None)


def _switch_outside(index, fns, args, outside):
    *rest, active = args
    inside = [k for k in range(len(fns)) if k not in outside]
    out = None
    if inside:
        on = active
        for k in outside:
            on = on & (index != k)
        remap = type(index)([inside.index(k) if k in inside else 0 for k in range(len(fns))])
        out = dr.switch(dr.gather(type(index), remap, index, on), [fns[k] for k in inside], *rest, on)
    for k in outside:
        mine = active & (index == k)
        out = _select(mine, fns[k](*rest, mine), out)
    return out


def _tree_map(fn, a, b):
    """``fn(leaf of a, leaf of b or None)`` over a result tree (tuples, Dr.Jit structs,
    arrays), rebuilt with ``a``'s structure; ``b`` is None or shaped like ``a``."""
    if isinstance(a, tuple):
        others = b if b is not None else (None,) * len(a)
        return type(a)(_tree_map(fn, x, y) for x, y in zip(a, others))
    fields = getattr(type(a), "DRJIT_STRUCT", None)
    if fields:
        out = type(a).__new__(type(a))
        for k in fields:
            setattr(out, k, _tree_map(fn, getattr(a, k), None if b is None else getattr(b, k)))
        return out
    return fn(a, b)


def _select(mask, a, b):
    """``dr.select`` over a result tree (tuples, Dr.Jit structs, arrays); ``b = None``
    selects zeros (what ``dr.switch`` gives inactive lanes)."""
    return _tree_map(lambda x, y: dr.select(mask, x, type(x)(0) if y is None else y), a, b)


def loop(state, cond, body, unroll: int, label: str):
    """``dr.while_loop(state, cond, body)``; with ``unroll`` > 0 the same loop as that
    many masked copies of its body (a bound on its trip count), for a loop nested in the
    path loop that carries gradients. Dr.Jit 1.5 reverse-differentiates a symbolic loop
    only with a trajectory bound (``max_iterations``), and with one generated invalid
    LLVM IR for such loops; and its forward mode does not carry derivatives from outside
    a nested symbolic loop into it (they came out 0). Also for a loop with a short
    known trip count, where straight-line code is cheaper than a loop (a shallow light
    BVH's descent)."""
    if not unroll:
        return dr.while_loop(state, cond, body, label=label)
    state = tuple(state)
    for _ in range(unroll):
        on = cond(*state)
        state = tuple(dr.select(on, a, b) for a, b in zip(body(*state), state))
    return state
