"""The layers of docs/architecture.md, checked on the import graph so the layout cannot erode.

Every `import` and `from ... import` in zoo/, lit_models/ and datamodules/ counts, at module
level or inside a function alike (a lazy import is still a dependency). An import may go down
the layers or stay within one; it may not go up, two packages may not import each other, and
modules may not form a cycle.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("zoo", "lit_models", "datamodules")

# top (0) to bottom; a package's layer is the first entry that is a prefix of its module name
LAYERS: tuple[tuple[str, ...], ...] = (
    ("zoo.cli", "zoo.pipeline"),
    ("lit_models", "datamodules"),
    ("zoo.eval", "zoo.rl", "zoo.gym"),
    ("zoo.agents",),
    ("zoo.goals", "zoo.data", "zoo.captions"),
    ("zoo.weights", "zoo.models", "zoo.experts"),
    ("zoo.envs", "zoo.argtypes", "zoo.strict_config", "zoo.files", "zoo.metrics"),
)


def module_name(path: Path) -> str:
    name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
    return name.removesuffix(".__init__")


def package(module: str) -> str:
    """`zoo.<part>` for the library's parts (a module of zoo/'s top counts as its own part)."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "zoo" and len(parts) > 1 else parts[0]


def layer(module: str) -> int:
    if module.rsplit(".", 1)[-1] == "cli":
        return 0  # a part's commands (zoo/<part>/cli.py) wire that part to the rest: top layer
    for depth, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return depth
    raise AssertionError(f"{module} is in no layer of tests/test_layers.py: add it to LAYERS")


def import_graph() -> dict[str, set[str]]:
    """module -> the project modules it imports."""
    files = {module_name(f): f for top in TOPS for f in (ROOT / top).rglob("*.py")}

    def resolve(name: str) -> str | None:
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = defaultdict(set)
    for module, path in files.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                target = resolve(name) if name.split(".")[0] in TOPS else None
                if target and target != module:
                    graph[module].add(target)
        graph.setdefault(module, set())
    return graph


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(
        f"{a} -> {b}" for a, targets in graph.items() for b in targets if layer(b) < layer(a)
    )


def mutual_packages(graph: dict[str, set[str]]) -> list[str]:
    uses: dict[str, set[str]] = defaultdict(set)
    for a, targets in graph.items():
        for b in targets:
            if package(a) != package(b):
                uses[package(a)].add(package(b))
    return sorted(f"{a} <-> {b}" for a in uses for b in uses[a] if a < b and a in uses.get(b, ()))


def module_cycles(graph: dict[str, set[str]]) -> list[str]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(" -> ".join(sorted(component)))
    return sorted(cycles)


GRAPH = import_graph()

# What the layout issue (#32) still has to move; each entry goes when its move lands. The
# tests fail on a new violation and on a listed one that is gone (then delete its line).
KNOWN_UPWARD: set[str] = set()
KNOWN_MUTUAL: set[str] = set()
KNOWN_CYCLES: set[str] = set()


def test_no_import_goes_up_a_layer() -> None:
    assert set(upward_imports(GRAPH)) == KNOWN_UPWARD


def test_no_two_packages_import_each_other() -> None:
    assert set(mutual_packages(GRAPH)) == KNOWN_MUTUAL


def test_no_module_cycles() -> None:
    assert set(module_cycles(GRAPH)) == KNOWN_CYCLES


def test_the_checks_see_a_violation() -> None:
    """The checker itself: an upward import, a mutual pair and a cycle are each reported."""
    graph = {"zoo.envs.a": {"zoo.models.b"}, "zoo.models.b": {"zoo.envs.a"}}
    assert upward_imports(graph) == ["zoo.envs.a -> zoo.models.b"]
    assert mutual_packages(graph) == ["zoo.envs <-> zoo.models"]
    assert module_cycles(graph) == ["zoo.envs.a -> zoo.models.b"]
