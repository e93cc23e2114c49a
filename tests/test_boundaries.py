"""Boundaries beyond the layers (tests/test_layers.py): ``sim/`` stays below the app,
and the servo vendor's words stay in its driver."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _imported(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def test_sim_imports_nothing_from_the_app_or_the_cli() -> None:
    """``handrig`` reaches ``sim/`` through ``app/simulator.py``; an arrow back up from
    ``sim/`` to ``handrig.app`` or ``handrig.cli`` would make a circle of layers."""
    wrong = [f"{p.relative_to(ROOT)} imports {m}" for p in sorted((ROOT / "sim").rglob("*.py"))
             for m in sorted(_imported(p))
             if m.split(".")[:2] in (["handrig", "app"], ["handrig", "cli"])]
    assert not wrong, "\n".join(wrong)
