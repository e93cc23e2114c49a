"""The LeRobot plugins stay thin and point one way: plugins/ imports handrig only through
handrig.app.lerobot, and handrig imports nothing of LeRobot or of the plugins (so its
own layers, tests/test_layers.py, hold with or without LeRobot installed)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[4]
PLUGINS = sorted((ROOT / "plugins").glob("lerobot_*/lerobot_*/*.py"))


def imported(path: Path) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out.add(node.module)
    return out


def test_the_plugins_reach_handrig_only_through_its_lerobot_package() -> None:
    assert len(PLUGINS) == 6
    for path in PLUGINS:
        for name in imported(path):
            if name.split(".")[0] == "handrig":
                assert name.startswith("handrig.app.lerobot."), (path.name, name)


def test_handrig_imports_neither_lerobot_nor_the_plugins() -> None:
    for path in sorted((ROOT / "handrig").rglob("*.py")):
        for name in imported(path):
            assert name.split(".")[0] not in (
                "lerobot", "lerobot_robot_handrig", "lerobot_teleoperator_handrig"), (
                path.relative_to(ROOT).as_posix(), name)
