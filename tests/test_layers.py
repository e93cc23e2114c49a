"""The folders show the layers: imports point one way, and nothing imports itself round.

Read from the source (every ``import``, at module level or inside a function), so
a lazy import cannot hide a dependency. The order is docs/architecture.md's. The
circles are looked for in the whole tree: handrig, sim, firmware_protocol, bench and
the tests; and no file there (a test file included) is over 600 lines.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("handrig", "sim", "firmware_protocol")
TREE = (*PACKAGES, "bench", "tests")  # where circles are looked for
MAX_LINES = 600

# handrig's layers, lowest first; a module may import its own layer or lower ones.
LAYERS = ("core", "config", "pose", "offline", "devices", "outputs", "loop", "app", "cli")
CORE = {"handrig", "handrig.errors", "handrig.clock", "handrig.realtime", "handrig.hand"}
SIM_DOOR = "handrig.app.simulator"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def layer_of(module: str) -> str:
    if module in CORE:
        return "core"
    parts = module.split(".")
    if parts[0] != "handrig" or len(parts) < 2 or parts[1] not in LAYERS:
        raise AssertionError(f"{module} is in no layer of {LAYERS}")
    return parts[1]


def all_modules(packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    return {module_name(p): p for pkg in packages for p in sorted((ROOT / pkg).rglob("*.py"))}


def imports_of(path: Path, name: str, known: set[str]) -> set[str]:
    """The project modules ``path`` imports (a name imported from a package counts as
    its submodule when there is one)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                       for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


MODULES = all_modules()
TREE_MODULES = all_modules(TREE)
TREE_GRAPH = {m: imports_of(p, m, set(TREE_MODULES)) for m, p in TREE_MODULES.items()}
GRAPH = {m: {d for d in TREE_GRAPH[m] if d in MODULES} for m in MODULES}


def test_every_handrig_module_sits_in_a_layer() -> None:
    for m in MODULES:
        if m.startswith("handrig"):
            layer_of(m)


def test_handrig_imports_point_down_the_layers() -> None:
    wrong = []
    for m, deps in GRAPH.items():
        if not m.startswith("handrig"):
            continue
        for d in deps:
            if d.startswith("handrig") and LAYERS.index(layer_of(d)) > LAYERS.index(layer_of(m)):
                wrong.append(f"{m} ({layer_of(m)}) imports {d} ({layer_of(d)})")
    assert not wrong, "imports against the layers:\n" + "\n".join(sorted(wrong))


def test_handrig_reaches_sim_through_one_door() -> None:
    wrong = [f"{m} imports {d}" for m, deps in GRAPH.items() if m.startswith("handrig")
             for d in deps if d.split(".")[0] == "sim" and m != SIM_DOOR]
    assert not wrong, "\n".join(sorted(wrong))


def test_firmware_protocol_imports_neither_handrig_nor_sim() -> None:
    wrong = [f"{m} imports {d}" for m, deps in GRAPH.items() if m.startswith("firmware_protocol")
             for d in deps if not d.startswith("firmware_protocol")]
    assert not wrong, "\n".join(sorted(wrong))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def circles_in(graph: dict[str, set[str]]) -> list[list[str]]:
    # a package's __init__ that imports its own submodules is not a circle of design
    own: dict[str, set[str]] = defaultdict(set)
    for m, deps in graph.items():
        own[m] = {d for d in deps if not m.startswith(d + ".")}
    return cycles(own)


def test_no_import_circle() -> None:
    found = circles_in(TREE_GRAPH)
    assert not found, "import circles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_the_circle_check_finds_a_circle() -> None:
    graph = {"bench.a": {"bench.b"}, "bench.b": {"bench.c"}, "bench.c": {"bench.a"},
             "bench": {"bench.a"}, "bench.d": {"bench.a"}}
    assert circles_in(graph) == [["bench.a", "bench.b", "bench.c"]]


def test_nothing_below_imports_bench_or_the_tests() -> None:
    wrong = [f"{m} imports {d}" for m, deps in TREE_GRAPH.items()
             if m.split(".")[0] in PACKAGES for d in deps
             if d.split(".")[0] in ("bench", "tests")]
    assert not wrong, "\n".join(sorted(wrong))


def test_sim_imports_nothing_from_app_or_cli() -> None:
    wrong = [f"{m} imports {d}" for m, deps in GRAPH.items() if m.split(".")[0] == "sim"
             for d in deps if d.startswith("handrig") and layer_of(d) in ("app", "cli")]
    assert not wrong, "sim/ reaches up into handrig's app or cli:\n" + "\n".join(sorted(wrong))


@pytest.mark.parametrize("pkg", (*PACKAGES, "bench"))
def test_no_module_over_600_lines(pkg: str) -> None:
    big = {m: n for m, p in TREE_MODULES.items() if m.split(".")[0] == pkg
           and (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not big, f"modules over {MAX_LINES} lines: {big}"


def test_no_test_file_over_600_lines() -> None:
    big = {p.relative_to(ROOT).as_posix(): n for p in sorted((ROOT / "tests").rglob("*.py"))
           if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not big, (f"test files over {MAX_LINES} lines (split them by topic): {big}")
