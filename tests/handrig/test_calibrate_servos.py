"""``handrig calibrate servos`` against the byte-level emulator (real dynamixel-sdk)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from handrig.commands.calibrate_servos import calibrate, calibration_rig, update_zero_ticks
from handrig.config import CONFIG_DIR
from handrig.errors import ConfigError
from handrig.rigconfig import load_rig_config
from handrig.servo import DynamixelBus
from sim.dxl_bus import SimBus


def test_update_keeps_comments_and_changes_only_zero_ticks():
    text = (CONFIG_DIR / "rig.toml").read_text()
    new = update_zero_ticks(text, {7: 2100, 20: 1990})
    changed = [(a, b) for a, b in zip(text.splitlines(), new.splitlines(), strict=True)
               if a != b]
    assert changed == [("zero_ticks = 2048", "zero_ticks = 2100"),
                       ("zero_ticks = 2048", "zero_ticks = 1990")]
    assert new.count("#") == text.count("#")
    with pytest.raises(ConfigError, match="no \\[\\[servos\\]\\] block"):
        update_zero_ticks(text, {99: 1})


def test_update_binds_zero_ticks_to_its_block_whatever_the_line_order():
    text = ("[bus]\nbaud = 1000000\n\n[[servos]]  # the index PIP\n"
            "zero_ticks = 100  # set by hand\nid = 3\n"
            "joint = \"riIndexPIPy\"\n\n[[servos]]\nid = 4\njoint = \"riRingPIPy\"\n")
    new = update_zero_ticks(text, {3: 2000, 4: 2100})
    assert "zero_ticks = 2000  # set by hand\nid = 3" in new
    assert "id = 4\nzero_ticks = 2100\njoint" in new
    assert new.count("zero_ticks") == 2


def test_jogging_a_servo_sets_its_zero(tmp_path: Path):
    rig = load_rig_config()
    two = rig.__class__(bus=rig.bus, loop=rig.loop, servos=(rig.servo(7), rig.servo(8)))
    said: list[str] = []
    with SimBus.from_rig(rig, ids=[7, 8]) as sim:
        bus = DynamixelBus(sim.port_path, calibration_rig(two))
        bus.connect()
        try:
            # wild jogs are refused; a person is slow (longer than the 100 ms watchdog)
            answers = iter(["+1000", "nan", "inf", "WAIT", "+5", "WAIT", "+5", "WAIT", "",
                            "s"])

            def ask(prompt: str) -> str:
                a = next(answers)
                if a == "WAIT":
                    time.sleep(0.4)  # let the emulated servo travel; a human pause
                    a = next(answers)
                return a

            with bus.torque(handle_signals=False):
                zeros = calibrate(bus, rig, [7, 8], jog=True, yes=False, ask=ask,
                                  say=said.append)
        finally:
            bus.close()
    # +10 joint degrees at direction +1, gear 1: about 114 ticks above 2048
    assert set(zeros) == {7}
    assert zeros[7] == pytest.approx(2048 + 10 * 4096 / 360, abs=3)
    assert sum("not a jog" in s for s in said) == 3


def test_cli_writes_a_checked_copy_of_the_rig_file(tmp_path: Path):
    import subprocess
    import sys

    out = tmp_path / "rig.toml"
    res = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "calibrate", "servos", "--bus", "sim",
         "--ids", "1,2", "--yes", "--out", str(out)],
        capture_output=True, text=True, timeout=90,
    )
    assert res.returncode == 0, res.stderr
    assert "wrote 2 zero(s)" in res.stdout
    cfg = load_rig_config(out)  # the written file loads and validates
    assert abs(cfg.servo(1).zero_ticks - 2048) <= 2 and cfg.servo(3).zero_ticks == 2048
    bad = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "calibrate", "servos", "--bus", "sim",
         "--ids", "1,99", "--yes", "--out", str(out)],
        capture_output=True, text=True, timeout=90,
    )
    assert bad.returncode == 2 and "--ids" in bad.stderr and "Traceback" not in bad.stderr
