"""Boundaries beyond the layers (tests/test_layers.py): ``sim/`` stays below the app,
and the servo vendor's words and modules stay in its driver."""

from __future__ import annotations

import ast
import io
import re
import tokenize
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


# The commands in handrig/cli/ are above the driver too; these are the exceptions.
CLI_VENDOR_COMMANDS = {
    # the emulator's command: it serves emulated Dynamixel servos, and its models and
    # bauds are the emulated ones' (firmware_protocol's codec)
    "handrig/cli/sim_bus.py",
    # times the driver against the vendor's own SDK on the emulator: the vendor is its
    # subject; an installed command (bench/ is not installed), see its docstring
    "handrig/cli/bench_bus.py",
}
CLI_HELP_TEXT = {
    # help text only (strings and comments), never code: what the emulator emulates ...
    "handrig/cli/__init__.py",  # ... in the sim-bus command's one-line help
    "handrig/cli/demo.py",  # ... in the demo's description of its chain
    "handrig/cli/servos.py",  # ... and what factory-new servos answer as, for bring-up
}


def _code_lines(text: str) -> set[int]:
    """Line numbers where a vendor word is in the code (not in a string or comment)."""
    prose = {tokenize.STRING, tokenize.COMMENT}
    prose |= {getattr(tokenize, "FSTRING_MIDDLE", tokenize.STRING)}
    return {tok.start[0] for tok in tokenize.generate_tokens(io.StringIO(text).readline)
            if tok.type not in prose and VENDOR_WORDS.search(tok.string)}


def _vendor_lines(skip: set[str], layers: tuple[str, ...] = ABOVE_THE_DRIVER,
                  help_text: frozenset[str] = frozenset()) -> list[str]:
    found = []
    for layer in layers:
        for path in sorted((ROOT / "handrig" / layer).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in skip:
                continue
            text = path.read_text()
            code = _code_lines(text) if rel in help_text else None
            for n, line in enumerate(text.splitlines(), start=1):
                if VENDOR_WORDS.search(line) and (code is None or n in code):
                    found.append(f"{rel}:{n}: {line.strip()}")
    return found


def test_no_vendor_or_servo_model_is_named_above_the_driver() -> None:
    """A second vendor needs a package under devices/ and one branch in the factory:
    nothing else above ``handrig/devices/servo/`` names the vendor or a servo model."""
    found = _vendor_lines(VENDOR_BRANCH)
    assert not found, "vendor words above the driver:\n" + "\n".join(found)


def test_the_commands_name_no_vendor_type() -> None:
    """``handrig/cli/`` talks to servos through the contracts the factory opens
    (``ServoBus``, ``ZeroingBus``, ``BusBringup``): but for the emulator's and the SDK benchmark's
    commands, a vendor word is at most help text."""
    found = _vendor_lines(CLI_VENDOR_COMMANDS, ("cli",), frozenset(CLI_HELP_TEXT))
    assert not found, "vendor words in the commands:\n" + "\n".join(found)


def test_a_vendor_type_in_a_help_text_command_is_found() -> None:
    """The help-text exception lets strings and comments through, not code."""
    code = "x = 1\nfrom handrig.devices.servo import DynamixelBus  # Dynamixel\n"
    assert _code_lines(code) == {2}
    assert _code_lines('"""Dynamixel X-series"""\nhelp = f"XL330-M288 {n}"\n') == set()


# The driver's own modules: its bring-up, register table, codec and tick arithmetic.
DRIVER_MODULES = re.compile(
    r"^handrig\.devices\.servo\.(dynamixel\w*|registers|codec|positions)(\.|$)")
MODEL_TABLES = "handrig.devices.servo.models"  # its tables (UPPER_CASE names) stay there
DRIVER_DOORS = VENDOR_BRANCH | CLI_VENDOR_COMMANDS  # the factory; the emulator, the SDK bench


def _driver_imports(text: str, filename: str = "<text>") -> list[str]:
    """The imports in ``text`` of the driver's modules, of the model table module whole,
    or of a table (an UPPER_CASE name) from it; lazy imports in functions included."""
    found = []
    for node in ast.walk(ast.parse(text, filename=filename)):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names
                      if DRIVER_MODULES.match(a.name) or a.name == MODEL_TABLES]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for a in node.names:
                full = f"{node.module}.{a.name}"
                if (DRIVER_MODULES.match(full) or full == MODEL_TABLES
                        or (node.module == MODEL_TABLES and a.name.isupper())):
                    found.append(full)
    return found


def test_the_app_and_the_commands_import_no_driver_module_or_model_table() -> None:
    """Above ``handrig/devices/servo/`` the app and the commands reach the servos
    through contracts (``ServoBus``, ``ZeroingBus``, ``BusBringup``) the factory opens:
    no bring-up, register table, codec, ticks or model table of the driver's, but for
    the factory (the one vendor branch) and the emulator's and the SDK bench's
    commands."""
    found = [f"{path.relative_to(ROOT).as_posix()}: {name}"
             for layer in ("app", "cli")
             for path in sorted((ROOT / "handrig" / layer).rglob("*.py"))
             if path.relative_to(ROOT).as_posix() not in DRIVER_DOORS
             for name in _driver_imports(path.read_text(), str(path))]
    assert not found, "driver modules imported above the driver:\n" + "\n".join(found)


def test_a_driver_import_is_found() -> None:
    """The check above sees each way back in, and lets the contracts through."""
    code = """
from handrig.devices.servo import bringup, dynamixel_bringup
from handrig.devices.servo.bringup import BusBringup
from handrig.devices.servo.bus import ServoBus, fault_letters
from handrig.devices.servo.models import BAUD_RATES, temperature_limit_c
import handrig.devices.servo.models
def later():
    from handrig.devices.servo.registers import Reg
    from handrig.devices.servo.dynamixel_bringup import scan
"""
    assert _driver_imports(code) == [
        "handrig.devices.servo.dynamixel_bringup", "handrig.devices.servo.models.BAUD_RATES",
        "handrig.devices.servo.models", "handrig.devices.servo.registers.Reg",
        "handrig.devices.servo.dynamixel_bringup.scan"]
