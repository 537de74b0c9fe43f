"""Values live across each ray-tracing call of a Dr.Jit LLVM kernel.

A megakernel keeps every value that is computed before a trace and used after it alive
across the trace. On the CPU those are spilled around the call into Embree (all vector
registers are caller-saved); on the GPU OptiX keeps them on its stack while the trace
runs. Fewer values there is a cheaper trace, the same for both renderers, so the count
compares pbr's kernel with Mitsuba's where timings alone cannot say why one trace costs
more (docs/performance.md, "door").

The analysis is SSA liveness on the kernel's main function (``define void @drjit_...``):
a value is live after a call if a later instruction of its block, a successor block, or
a ``phi`` on the edge to a successor uses it. Dr.Jit marks its calls into Embree with a
``; -------- Ray trace -------`` (closest hit) or ``Ray test`` (shadow ray) comment.
Values are counted by kind: float vectors, masks and integer vectors, each split into
those that vary per lane and the uniform ones (a scalar broadcast to every lane: a literal
or a one-element array such as a light's corner, which the compiler may reload instead of
preserving), and scalars.

    python benchmarks/ir_liveness.py out/ir/door_pbr_0.ll out/ir/door_mitsuba_0.ll

(``profile_kernels.py --ir-dir`` writes those files and prints the same figures.)
"""

from __future__ import annotations

import re
import sys
from collections import Counter
from dataclasses import dataclass

_NAME = re.compile(r"%[A-Za-z0-9_.]+")
_DEF = re.compile(r"^(%[A-Za-z0-9_.]+) = (.*)$")
_LABEL = re.compile(r"^([A-Za-z0-9_.]+):")
_VEC = re.compile(r"<(\d+) x (\w+)>")
_SPLAT = re.compile(r"shufflevector <\d+ x \w+> %[\w.]+, <\d+ x \w+> undef, <\d+ x i32> zeroinitializer$")


@dataclass
class Instr:
    text: str
    defines: str | None
    uses: list[str]                         # not for phis: see ``incoming``
    incoming: list[tuple[str, str]]         # phi: (value, predecessor block)
    comment: str                            # the comment line just before it, if any


@dataclass
class Kernel:
    blocks: dict[str, list[Instr]]          # in textual order
    types: dict[str, str]                   # value -> 'float', 'mask', 'int', 'scalar', or
                                            # 'uniform float' ('uniform mask', ...)

    def successors(self, block: str) -> list[str]:
        return re.findall(r"label %([A-Za-z0-9_.]+)", self.blocks[block][-1].text)


@dataclass
class TraceLiveness:
    kind: str                               # 'trace' (closest hit) or 'test' (shadow ray)
    block: str
    index: int                              # position of the call in its block
    live: Counter                           # kind of value -> count

    def __str__(self):
        c = self.live
        return (f"{self.kind:5s} {sum(c.values()):4d} live: "
                + ", ".join(f"{c[k]} (+{c['uniform ' + k]} uniform) {name}" for k, name in
                            (("float", "float vectors"), ("mask", "masks"), ("int", "integer vectors")))
                + f", {c['scalar']} scalars")


def _kind(rhs: str) -> str:
    m = _VEC.search(rhs)
    if not m:
        return "scalar"
    t = m.group(2)
    kind = "float" if t in ("float", "double", "half") else "mask" if t == "i1" else "int"
    return "uniform " + kind if _SPLAT.match(rhs) else kind    # Dr.Jit's broadcast of a scalar


def parse(ir: str) -> Kernel:
    """The main function of a Dr.Jit LLVM kernel."""
    m = re.search(r"^define void @drjit_\w+\(.*?\{\n(.*?)^\}", ir, re.S | re.M)
    if not m:
        raise ValueError("no Dr.Jit kernel function (define void @drjit_...) in this IR")
    blocks: dict[str, list[Instr]] = {}
    cur, comment = "entry", ""
    for line in m.group(1).split("\n"):
        s = line.strip()
        if not s:
            continue
        if s.startswith(";"):
            comment = s
            continue
        lm = _LABEL.match(s)
        if lm:
            cur = lm.group(1)
            blocks.setdefault(cur, [])
            continue
        dm = _DEF.match(s)
        d, rhs = (dm.group(1), dm.group(2)) if dm else (None, s)
        if rhs.startswith("phi "):
            inc = [(v.strip(), b) for v, b in re.findall(r"\[\s*([^,\]]+),\s*%([A-Za-z0-9_.]+)\s*\]", rhs)]
            ins = Instr(s, d, [], inc, comment)
        else:
            ins = Instr(s, d, _NAME.findall(rhs), [], comment)
        blocks.setdefault(cur, []).append(ins)
        comment = ""
    k = Kernel(blocks, {})
    for b in blocks.values():
        for i in b:
            if i.defines:
                k.types[i.defines] = _kind(i.text.split("=", 1)[1].strip())
    return k


def _live_before(k: Kernel, instrs: list[Instr], live_out: set[str]) -> set[str]:
    live = set(live_out)
    for i in reversed(instrs):
        if i.defines:
            live.discard(i.defines)
        live.update(u for u in i.uses if u[1:] not in k.blocks)
    return live


def _live_out(k: Kernel) -> dict[str, set[str]]:
    """Values live at the end of each block (fixed point of the usual dataflow)."""
    phi_uses: dict[str, set[str]] = {b: set() for b in k.blocks}
    for b in k.blocks.values():
        for i in b:
            for v, pred in i.incoming:
                if v.startswith("%") and pred in phi_uses:
                    phi_uses[pred].add(v)
    live_in = {b: set() for b in k.blocks}
    live_out = {b: set() for b in k.blocks}
    changed = True
    while changed:
        changed = False
        for b in reversed(list(k.blocks)):
            out = set(phi_uses[b])
            for s in k.successors(b):
                out |= live_in.get(s, set())
            live_out[b] = out
            new_in = _live_before(k, k.blocks[b], out)
            if new_in != live_in[b]:
                live_in[b], changed = new_in, True
    return live_out


@dataclass
class TraceCall:
    kind: str                               # 'trace' (closest hit), 'test' (shadow ray) or 'call'
    block: str
    index: int                              # position of the call in its block
    inputs: dict[int, str]                  # input slot -> the value stored there for the call


def trace_calls(k: Kernel) -> list[TraceCall]:
    """The kernel's Embree calls, in textual order, with the values stored as their
    inputs (slots 1-3: the ray's origin, 5-7: its direction)."""
    out = []
    for name, instrs in k.blocks.items():
        for n, i in enumerate(instrs):
            if not re.match(r"^call void %rd\d+\(", i.text):
                continue
            # Dr.Jit's comment sits before the first store of the call's inputs
            inputs, comment = {}, ""
            for j in reversed(instrs[:n]):
                m = re.match(r"store <\d+ x \w+> (%[\w.]+), ptr %u\d+_in_(\d+)_1", j.text)
                if m:
                    inputs.setdefault(int(m.group(2)), m.group(1))
                if j.comment:
                    comment = j.comment
                    break
            kind = "test" if "Ray test" in comment else "trace" if "Ray trace" in comment else "call"
            out.append(TraceCall(kind, name, n, inputs))
    return out


def trace_liveness(ir: str) -> list[TraceLiveness]:
    """For each Embree call of the kernel, in textual order, the values live across it."""
    k = parse(ir)
    live_out = _live_out(k)
    result = []
    for c in trace_calls(k):
        live = _live_before(k, k.blocks[c.block][c.index + 1:], live_out[c.block])
        result.append(TraceLiveness(c.kind, c.block, c.index, Counter(k.types.get(v, "scalar") for v in live)))
    return result


def main(argv=None):
    for path in (argv if argv is not None else sys.argv[1:]):
        with open(path) as f:
            print(path)
            for t in trace_liveness(f.read()):
                print("  " + str(t))


if __name__ == "__main__":
    main()
