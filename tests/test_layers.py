"""The package's layers point down (docs/architecture.md): no import cycles, and no
module imports one of a higher layer, counting imports inside functions too."""

import ast
import os
import re

import pbr

ROOT = os.path.dirname(pbr.__file__)
# Bottom (0) to top; the first pattern that matches a module name (without "pbr.") wins.
LAYERS = [(r"(backend|memory|spectrum|sampling|dispatch|image|plotting|motion)$", 0), (r"plugins(\..*)?$", 1),
          (r"textures(\..*)?$", 2),
          (r"(bsdfs|lights|media)(\..*)?$|(phase|cameras|lens|films|filters|geometry)$|samplers(\..*)?$", 3),
          (r"integrators(\..*)?$", 4), (r"scene(\..*)?$", 5), (r".*", 6)]


def layer(module: str) -> int:
    return next(n for pattern, n in LAYERS if re.match(pattern, module))


def import_graph(root=ROOT) -> dict:
    """Module -> the pbr modules it imports (module names without "pbr.")."""
    modules = {}
    for dirpath, _, files in os.walk(root):
        for f in files:
            if f.endswith(".py"):
                rel = os.path.relpath(os.path.join(dirpath, f), root)[:-3].replace(os.sep, ".")
                modules[rel.removesuffix(".__init__").removesuffix("__init__")] = (
                    os.path.join(dirpath, f), f == "__init__.py")
    graph = {}
    for name, (path, is_pkg) in modules.items():
        parts = name.split(".") if name else []
        package = parts if is_pkg else parts[:-1]
        targets = set()
        for node in ast.walk(ast.parse(open(path).read())):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = package[:len(package) - node.level + 1] + ([node.module] if node.module else [])
                for alias in node.names:
                    sub = ".".join(base + [alias.name])
                    targets.add(sub if sub in modules else ".".join(base))
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pbr"):
                targets.add(node.module[4:])
            elif isinstance(node, ast.Import):
                targets |= {a.name[4:] for a in node.names if a.name.startswith("pbr.")}
        graph[name] = {t for t in targets if t in modules and t != name}
    return graph


def cycles(graph: dict) -> list:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def upward(graph: dict) -> list:
    return sorted(f"{m} -> {t}" for m, ts in graph.items() for t in ts
                  if m and layer(t) > layer(m) and not t.startswith(m + "."))


def test_no_import_cycles():
    assert cycles(import_graph()) == []


def test_imports_point_down_the_layers():
    assert upward(import_graph()) == []


def test_the_checks_find_a_cycle_and_an_upward_import():
    """Must-fail: the old loader's cycle (scene.loader <-> bsdfs through BSDF_LIKE) and an
    integrator reading the loader."""
    graph = import_graph()
    graph["bsdfs.bsdfset"] = graph["bsdfs.bsdfset"] | {"scene.loader"}
    graph["integrators.lightpath"] = graph["integrators.lightpath"] | {"scene.loader"}
    assert any({"bsdfs", "scene.loader"} <= set(c) for c in cycles(graph))
    assert "integrators.lightpath -> scene.loader" in upward(graph)
