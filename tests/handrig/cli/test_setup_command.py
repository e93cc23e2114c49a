"""``handrig setup`` against the byte-level emulator, through the real SDK: the port found
by unplugging, the rig file written, a box of servos at other IDs and bauds given
theirs one at a time (one beside a stray servo, one missing when Enter is pressed),
then ``servos check``; and ``set-id`` finding a factory-new servo at 57600 without
``--baud``. (``setup --port sim`` refused: tests/handrig/cli/test_first_hour_messages.py.)

The servo adapter is a symlink the test points at an emulated bus (a pty): plugging
servos in and out is the test pointing it at another bus, as a /dev/serial/by-id/
name points at whichever ttyUSB the adapter got. The person is a script of answers.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import tomlkit

from handrig.cli import build_parser, main
from handrig.cli.setup import run as run_setup
from handrig.config.paths import installed_config
from handrig.config.rig import load_rig_config
from sim.dxl_bus import SimBus
from sim.dxl_servo import EmulatedServo

BAUDS = "1000000,57600,115200"  # the search without 9600's seconds-long broadcast ping


class Bench:
    """The adapter (a symlink) and what is plugged into it."""

    def __init__(self, tmp_path: Path) -> None:
        self.adapter = tmp_path / "adapter"
        self.stack = contextlib.ExitStack()
        self.plugged_in = True  # the adapter's USB cable

    def plug(self, *servos: EmulatedServo) -> None:
        bus = self.stack.enter_context(SimBus(list(servos), check_baud=True, realtime=False))
        self.adapter.unlink(missing_ok=True)
        self.adapter.symlink_to(bus.port_path)

    def ports(self) -> list[str]:
        return [*([str(self.adapter)] if self.plugged_in else []), "/dev/ttyS0"]


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[Bench]:
    b = Bench(tmp_path)
    with b.stack:
        yield b


def three_servo_rig(tmp_path: Path) -> Path:
    doc = tomlkit.parse(installed_config("rig.toml").read_text())
    servos = doc["servos"]
    while len(servos) > 3:
        del servos[-1]
    path = tmp_path / "rig.toml"
    path.write_text(tomlkit.dumps(doc))
    return path


def script(steps: list[tuple[str, str, Callable[[], None] | None]]
           ) -> tuple[Callable[[str], str], list[str]]:
    """``ask`` answering each prompt with the next step (the prompt must contain its
    text; its action runs first), and the list every prompt and line goes to."""
    lines: list[str] = []
    queue = list(steps)

    def ask(prompt: str) -> str:
        lines.append(prompt)
        assert queue, f"no answer scripted for {prompt!r}"
        want, answer, action = queue.pop(0)
        assert want in prompt, "\n".join([want, prompt, *lines[-8:]])
        if action is not None:
            action()
        return answer

    return ask, lines


def test_setup_finds_the_port_writes_it_and_readies_a_box_of_servos(
        tmp_path: Path, bench: Bench) -> None:
    rig = three_servo_rig(tmp_path)
    out = tmp_path / "mine" / "rig.toml"
    # a box: factory-new (ID 1 at 57600), one at 115200 as ID 4, one at 1 Mbps as ID 9
    new1, new2, new3 = (EmulatedServo(1, baud=57600), EmulatedServo(4, baud=115200),
                        EmulatedServo(9, baud=1_000_000))
    stray = EmulatedServo(3, baud=1_000_000)  # an old servo that has ID 3 already
    bench.plug(new1)

    def unplug() -> None:
        bench.plugged_in = False

    def replug() -> None:
        bench.plugged_in = True

    ask, lines = script([
        ("unplug the servo adapter", "", unplug),
        (f"the adapter is {bench.adapter}: plug it back in", "", replug),
        ("[1/3] plug in the servo for ID 1", "", None),
        ("[2/3] plug in the servo for ID 2", "", lambda: bench.plug(new1, new2)),
        # a stray servo with ID 3 left on the bus beside the new one: refused
        ("[3/3] plug in the servo for ID 3", "", lambda: bench.plug(new3, stray)),
        ("[3/3] plug in the servo for ID 3", "", lambda: bench.plug(new3)),
    ])

    def say(text: str) -> None:
        lines.append(text)

    args = build_parser().parse_args(["setup", "--rig", str(rig), "--out", str(out),
                                      "--bauds", BAUDS])
    # servos check at the end: all three chained
    check_after = [new1, new2, new3]
    original = say

    def say_and_chain(text: str) -> None:
        original(text)
        if text.startswith("with all of them chained"):
            bench.plug(*check_after)

    status = run_setup(args, ask=ask, say=say_and_chain, list_ports=bench.ports)
    text = "\n".join(lines)
    assert status == 0, text
    # the port: the one that went away, written into the user's file (the source kept)
    assert load_rig_config(out).bus.port == str(bench.adapter)
    assert load_rig_config(rig).bus.port == ""
    # each servo found at its own baud, given its ID and the rig's baud, torque off
    assert "found a XL330-M288 as ID 1 at 57600 bps" in text
    assert "found a XL330-M288 as ID 4 at 115200 bps" in text
    assert "found a XL330-M288 as ID 9 at 1000000 bps" in text
    # a second servo on the bus that is not one made ready: refused, nothing written
    assert "2 new servos answer at 1000000 bps (IDs 3, 9): plug in one new servo" in text
    assert stray.id == 3 and stray.mem[8] == 3
    for servo, want in ((new1, 1), (new2, 2), (new3, 3)):
        assert servo.id == want and servo.mem[8] == 3  # Baud Rate (8) 3: 1 Mbps
        assert not servo.torque_enabled
    assert "3 servo(s) answered" in text and "the bus matches the rig file" in text


def test_setup_with_a_port_skips_finding_it_and_a_skipped_servo_fails_the_check(
        tmp_path: Path, bench: Bench) -> None:
    rig = three_servo_rig(tmp_path)
    out = tmp_path / "rig_out.toml"
    # at the rig's baud already (one broadcast ping there is 0.8 s, at 57600 1.4 s; the
    # box above moves servos from 57600 and 115200): only its ID is given
    servo = EmulatedServo(5, baud=1_000_000)
    bench.plug(EmulatedServo(9, baud=115200))  # not at the bauds looked at: missing
    ask, lines = script([("ID 1", "", None), ("ID 1", "", lambda: bench.plug(servo)),
                         ("ID 2", "s", None), ("ID 3", "s", None)])
    args = build_parser().parse_args(["setup", "--rig", str(rig), "--out", str(out),
                                      "--port", str(bench.adapter), "--bauds", "1000000"])
    status = run_setup(args, ask=ask, say=lines.append, list_ports=bench.ports)
    text = "\n".join(lines)
    assert status == 1, text  # servos 2 and 3 are missing from the bus
    assert "no new servo answers at any of 1000000 bps" in text  # asked again, then found
    assert "found a XL330-M288 as ID 5 at 1000000 bps" in text
    assert "skipped: 2, 3" in text and "missing" in text
    assert servo.id == 1 and servo.mem[8] == 3
    assert load_rig_config(out).bus.port == str(bench.adapter)


def test_set_id_finds_a_factory_new_servo_at_57600_without_baud(
        bench: Bench, capsys: pytest.CaptureFixture[str]) -> None:
    servo = EmulatedServo(1, baud=57600)
    bench.plug(servo)
    assert main(["servos", "set-id", "--port", str(bench.adapter), "1", "7"]) == 0
    out = capsys.readouterr().out
    assert "servo 1 answers at 57600 bps" in out and "is now ID 7 at 57600 bps" in out
    assert servo.id == 7
    assert main(["servos", "set-baud", "--port", str(bench.adapter), "7", "1000000"]) == 0
    assert "servo 7 answers at 57600 bps" in capsys.readouterr().out
    assert servo.mem[8] == 3
    # none at any baud: the error names what was tried
    assert main(["servos", "set-id", "--port", str(bench.adapter), "5", "6"]) == 2
    err = capsys.readouterr().err
    assert "no servo answers as ID 5" in err and "57600" in err and "9600" in err
    # a scan of some bauds that finds nothing says the others were not looked at
    assert main(["servos", "scan", "--port", str(bench.adapter), "--bauds", "4000000"]) == 0
    out = capsys.readouterr().out
    assert "no servo answered" in out and "without it, scan tries every baud" in out, out
