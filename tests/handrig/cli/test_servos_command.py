"""``handrig servos``: bring-up against the byte-level emulator, through the real SDK.

The emulated bus enforces each servo's Baud Rate item (``check_baud``): a servo
hears, and answers, only packets sent at its own baud, as on a real bus.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import tomlkit

from firmware_protocol.dynamixel import Reg as SimReg
from handrig.cli import main
from handrig.config.paths import installed_config
from sim.dxl_bus import SimBus
from sim.dxl_servo import EmulatedServo


def scan(port: str, capsys: pytest.CaptureFixture[str], *bauds: int) -> list[tuple[int, int]]:
    argv = ["servos", "scan", "--port", port, "--json"]
    if bauds:
        argv += ["--bauds", ",".join(map(str, bauds))]
    assert main(argv) == 0
    found = json.loads(capsys.readouterr().out)
    return sorted((s["id"], s["baud"]) for s in found["servos"])


def test_scan_finds_servos_at_three_bauds_then_set_id_and_set_baud_move_them(
        capsys: pytest.CaptureFixture[str]) -> None:
    servos = [EmulatedServo(1, baud=57600), EmulatedServo(2, "XC330-T288", baud=115200),
              EmulatedServo(3, baud=1_000_000)]
    with SimBus(servos, check_baud=True, realtime=False) as bus:
        port = bus.port_path
        # the table a user reads: one row per servo found (at the servos' three bauds: a
        # scan of every baud, the default, waits ~10 s, most of it at 9600 bps; that the
        # default is every baud is test_servos_scan_default.py's)
        assert main(["servos", "scan", "--port", port, "--bauds", "57600,115200,1000000"]) == 0
        table = capsys.readouterr().out
        rows = re.findall(r"^ *(\d+)  (X\w+-\w+) +\d+ +(\d+)  (\w+)", table, re.M)
        assert sorted((int(i), int(b)) for i, _, b, _ in rows) == [
            (1, 57600), (2, 115200), (3, 1_000_000)], table
        assert {(m, mode) for i, m, _, mode in rows if i == "2"} == {("XC330-T288", "position")}
        assert "more than one baud" in table

        assert main(["servos", "set-id", "--port", port, "--baud", "57600", "1", "4"]) == 0
        assert main(["servos", "set-baud", "--port", port, "--baud", "57600", "4",
                     "1000000"]) == 0
        assert main(["servos", "set-baud", "--port", port, "--baud", "115200", "2",
                     "1000000"]) == 0
        out = capsys.readouterr().out
        assert "servo 1 (XL330-M288) is now ID 4 at 57600 bps" in out
        assert "servo 4 (XL330-M288) now runs at 1000000 bps" in out
        assert scan(port, capsys, 57600, 115200, 1_000_000) == [
            (2, 1_000_000), (3, 1_000_000), (4, 1_000_000)]
        assert bus.servo(4).get(SimReg.BAUD_RATE) == 3  # the EEPROM item itself: 1 Mbps

        # a taken ID is refused, and nothing changes
        assert main(["servos", "set-id", "--port", port, "--baud", "1000000", "4", "2"]) == 2
        assert "ID 2 is taken" in capsys.readouterr().err
        assert scan(port, capsys, 1_000_000) == [(2, 1_000_000), (3, 1_000_000),
                                                 (4, 1_000_000)]
        assert main(["servos", "set-id", "--port", port, "--baud", "1000000", "9", "10"]) == 2
        assert "no servo answers as ID 9" in capsys.readouterr().err


def three_servo_rig(tmp_path: Path) -> Path:
    doc = tomlkit.parse(installed_config("rig.toml").read_text())
    servos = doc["servos"]
    while len(servos) > 3:
        del servos[-1]
    doc["bus"]["port"] = "/dev/null"
    path = tmp_path / "rig.toml"
    path.write_text(tomlkit.dumps(doc))
    return path


def test_check_names_a_missing_servo_a_wrong_model_a_wrong_mode_and_an_extra_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = three_servo_rig(tmp_path)  # servos 1, 2, 3: XL330-M288, position mode, 1 Mbps
    servos = [EmulatedServo(1), EmulatedServo(2, "XC330-T288"), EmulatedServo(7)]
    servos[0].set(SimReg.OPERATING_MODE, 5)
    with SimBus(servos, check_baud=True, realtime=False) as bus:
        status = main(["servos", "check", "--rig", str(rig), "--port", bus.port_path])
    out = capsys.readouterr().out
    assert status == 1
    assert "missing: servo 3 (riThumbCMCz) does not answer at 1000000 bps" in out
    assert "model: servo 2 (riThumbCMCy) is a XC330-T288, the rig file says XL330-M288" in out
    assert "mode: servo 1 is in current_based_position mode (5), the rig wants position" in out
    assert "extra: servo 7 (XL330-M288) answers" in out
    assert "voltage: servo 2" not in out  # 12 V is inside the XC330-T288's range
    assert out.count("->") == 4  # each finding says what to do

    with SimBus([EmulatedServo(1), EmulatedServo(2), EmulatedServo(3)], check_baud=True,
                realtime=False) as bus:
        assert main(["servos", "check", "--rig", str(rig), "--port", bus.port_path]) == 0
    assert "the bus matches the rig file" in capsys.readouterr().out


def test_reboot_clears_a_hardware_error_whose_cause_is_gone(
        capsys: pytest.CaptureFixture[str]) -> None:
    servo = EmulatedServo(5)
    with SimBus([servo], check_baud=True, realtime=False) as bus:
        servo.inject_hardware_error(1 << 5)  # overload
        assert main(["servos", "check", "--rig", "leap", "--port", bus.port_path,
                     "--baud", "1000000", "--json"]) == 1
        found = json.loads(capsys.readouterr().out)
        assert any(f["what"] == "hardware error" and "overload" in f["detail"]
                   for f in found["findings"])
        servo.clear_injected_fault()
        assert main(["servos", "reboot", "--port", bus.port_path, "--baud", "1000000",
                     "5"]) == 0
        assert "hardware errors now: none" in capsys.readouterr().out


def test_scan_and_set_through_sim_bus_servo_baud(capsys: pytest.CaptureFixture[str]) -> None:
    """The same steps against ``handrig sim-bus --servo-baud`` in a process of its own."""
    from handrig.app.factory import port_process

    with port_process(["sim-bus", "--ids", "1,2,3", "--no-puppet", "--no-realtime",
                       "--servo-baud", "1:57600,2:115200,3:1000000"],
                      "the simulated servo bus") as (_, port):
        # the default scan of every baud is the test above's (~10 s: the SDK waits 3 ms
        # per ID for each baud's broadcast ping); here its three bauds and one nobody uses
        assert scan(port, capsys, 57600, 115200, 1_000_000, 4_000_000) == [
            (1, 57600), (2, 115200), (3, 1_000_000)]
        assert main(["servos", "set-id", "--port", port, "--baud", "115200", "2", "5"]) == 0
        assert main(["servos", "set-baud", "--port", port, "--baud", "115200", "5",
                     "1000000"]) == 0
        capsys.readouterr()
        assert scan(port, capsys, 57600, 115200, 1_000_000) == [
            (1, 57600), (3, 1_000_000), (5, 1_000_000)]


def test_a_servo_whose_registers_do_not_answer_is_a_finding_not_a_pass(
        capsys: pytest.CaptureFixture[str]) -> None:
    """A servo that answered its ping but none of the reads after it (a reply line that
    broke meanwhile: muted here from the start, the ping's answer given by hand) is not
    'fine': its fields are unknown, each read tried DESCRIBE_TRIES times, and the check
    says which registers were not checked."""
    from handrig.devices.servo import dynamixel_bringup as bringup
    from sim.dxl_faults import FaultSpec

    servo = EmulatedServo(5)
    with (SimBus([servo], faults=FaultSpec(mute=frozenset({5})), realtime=False) as bus,
          bringup.open_port(bus.port_path, 1_000_000) as sp):
        assert sp.ping(5) is None  # muted: it hears, it does not answer
        found = sp.describe(5, 1200, 50)
    assert found.hardware_error is None and found.operating_mode is None
    assert found.unread == ("OPERATING_MODE", "PRESENT_INPUT_VOLTAGE",
                            "PRESENT_TEMPERATURE", "HARDWARE_ERROR_STATUS")
    assert bus.stats.packets >= 1 + 4 * bringup.DESCRIBE_TRIES  # every read tried again
