"""Boundaries beyond the layers (tests/test_layers.py): ``sim/`` stays below the app,
and the servo vendor's words stay in its driver."""

from __future__ import annotations

import ast
import re
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


VENDOR_WORDS = re.compile(r"dynamixel|\bX[LCMH]\d{3}-[A-Z]\d{3}\b|x-series"
                          # what a tick is and the servos' register values: the driver's
                          r"|deg_to_ticks|ticks_to_deg|TICKS_PER_|POSITION_TICKS|OPERATING_MODES\b",
                          re.IGNORECASE)
ABOVE_THE_DRIVER = ("app", "loop", "config", "pose", "outputs")
VENDOR_BRANCH = {
    # the one place a vendor is chosen: servo_bus builds the driver, read_fields_for asks
    # its wire timing what a read may carry
    "handrig/app/factory.py",
}


def _vendor_lines(skip: set[str]) -> list[str]:
    found = []
    for layer in ABOVE_THE_DRIVER:
        for path in sorted((ROOT / "handrig" / layer).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in skip:
                continue
            for n, line in enumerate(path.read_text().splitlines(), start=1):
                if VENDOR_WORDS.search(line):
                    found.append(f"{rel}:{n}: {line.strip()}")
    return found


def test_no_vendor_or_servo_model_is_named_above_the_driver() -> None:
    """A second vendor needs a package under devices/ and one branch in the factory:
    nothing else above ``handrig/devices/servo/`` names the vendor or a servo model."""
    found = _vendor_lines(VENDOR_BRANCH)
    assert not found, "vendor words above the driver:\n" + "\n".join(found)
