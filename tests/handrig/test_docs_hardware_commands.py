"""The hardware commands of docs/hardware.md and the README, run as a newcomer would,
against the emulator: each block between ``<!-- newcomer: NAME -->`` markers, line by
line as written, so the docs cannot drift from the commands again (issue 37).

The newcomer's servo adapter is a symlink the test points at an emulated bus; where
the docs write the adapter's by-id name (``/dev/serial/by-id/usb-FTDI_...``) the
test puts that symlink, as the reader puts their own. ``handrig setup`` gets the
newcomer's answers (unplug, plug back in, ``s`` for servos already set up) and the
port list before and after; ``calibrate servos`` gets ``q`` at its first question.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from collections.abc import Iterator
from pathlib import Path

import pytest

from handrig.cli import build_parser, main
from handrig.cli.setup import run as run_setup
from handrig.config.paths import installed_config, user_config
from handrig.config.rig import load_rig_config
from sim.dxl_bus import SimBus
from sim.dxl_servo import EmulatedServo

ROOT = Path(__file__).resolve().parents[2]
PLACEHOLDER = "/dev/serial/by-id/usb-FTDI_..."


def blocks(path: Path) -> dict[str, list[str]]:
    """Each marked block's ``handrig`` lines, comments cut off."""
    text = path.read_text(encoding="utf-8")
    found = re.findall(r"<!-- newcomer: ([\w ]+) -->\n```sh\n(.*?)```\n<!-- /newcomer -->",
                       text, flags=re.S)
    out = {}
    for name, body in found:
        lines = [line.split("  #")[0].strip() for line in body.splitlines()]
        out[name] = [line for line in lines if line]
        assert all(line.startswith("handrig ") for line in out[name]), out[name]
    return out


class Adapter:
    """The newcomer's adapter: a symlink to whichever emulated bus is plugged in."""

    def __init__(self, path: Path, stack: contextlib.ExitStack) -> None:
        self.path, self.stack, self.plugged_in = path, stack, True

    def plug(self, servos: list[EmulatedServo] | None = None) -> None:
        spec = servos if servos is not None else load_rig_config(installed_config("rig.toml"))
        bus = self.stack.enter_context(SimBus(spec, check_baud=True, realtime=False))
        self.path.unlink(missing_ok=True)
        self.path.symlink_to(bus.port_path)

    def ports(self) -> list[str]:
        return [str(self.path)] if self.plugged_in else []


@pytest.fixture
def adapter(tmp_path: Path) -> Iterator[Adapter]:
    with contextlib.ExitStack() as stack:
        yield Adapter(tmp_path / "usb-FTDI_adapter", stack)


def argv(line: str, adapter: Adapter) -> list[str]:
    return shlex.split(line.replace(PLACEHOLDER, str(adapter.path)))[1:]


def setup_as_a_newcomer(line: str, adapter: Adapter) -> tuple[int, str]:
    """``handrig setup`` with the newcomer's answers: unplug, plug back in, then every
    servo skipped (the emulated bus already holds the rig's servos, set up)."""
    lines: list[str] = []

    def ask(prompt: str) -> str:
        lines.append(prompt)
        if "unplug the servo adapter" in prompt:
            adapter.plugged_in = False
        elif "plug it back in" in prompt:
            adapter.plugged_in = True
        elif "plug in the servo for ID" in prompt:
            return "s"
        else:
            raise AssertionError(f"an unexpected question: {prompt!r}")
        return ""

    args = build_parser().parse_args(argv(line, adapter))
    status = run_setup(args, ask=ask, say=lines.append, list_ports=adapter.ports)
    return status, "\n".join(lines)


def test_the_hardware_guide_and_the_readme_bring_up_run_as_written(
        adapter: Adapter, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/hardware.md's blocks in order, then the README's: its ``handrig setup`` and
    ``handrig servos check`` are the guide's own lines (run once, for both), then its
    calibration."""
    guide = blocks(ROOT / "docs" / "hardware.md")
    assert list(guide) == ["setup", "one servo", "chained"]
    (readme_setup, readme_check, readme_calibrate) = blocks(ROOT / "README.md")["readme"]
    # one newcomer's setup and check serve both: the README's lines must be the guide's,
    # as written (run once, in the guide's order)
    assert argv(readme_setup, adapter) == argv(guide["setup"][0], adapter), readme_setup
    assert argv(readme_check, adapter) == argv(guide["chained"][0], adapter), readme_check
    mine = user_config("rig.toml")
    assert not mine.exists()  # a newcomer: the shipped rig, which names no port
    # before setup: a hardware command stops and names --port
    assert main(argv(guide["chained"][0], adapter)) == 2
    assert "--port PORT" in capsys.readouterr().err

    adapter.plug()  # the whole rig, chained
    (line,) = guide["setup"]
    status, said = setup_as_a_newcomer(line, adapter)
    assert status == 0, said
    assert load_rig_config(mine).bus.port == str(adapter.path)
    assert "the bus matches the rig file" in said

    adapter.plug([EmulatedServo(1, baud=57600)])  # one factory-new servo alone
    for line in guide["one servo"]:
        assert main(argv(line, adapter)) == 0, line
    out = capsys.readouterr().out
    assert re.search(r"^ +1  XL330-M288 .* 57600 ", out, re.M), out
    assert "is now ID 7 at 57600 bps" in out and "now runs at 1000000 bps" in out

    adapter.plug()  # all of them chained
    for line in guide["chained"]:
        assert main(argv(line, adapter)) == 0, line
    out = capsys.readouterr().out
    assert "20 servo(s) answered on" in out and "SIMULATED" not in out
    assert "the bus matches the rig file" in out

    # then the README's calibration on the same chained rig, from the port setup wrote
    monkeypatch.setattr("sys.stdin", io.StringIO("q\n"))  # leaves at the first question
    assert main(argv(readme_calibrate, adapter)) == 0
    out = capsys.readouterr().out
    assert "calibration stopped: nothing was written" in out and "SIMULATED" not in out
