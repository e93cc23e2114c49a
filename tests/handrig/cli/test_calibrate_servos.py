"""``handrig calibrate servos`` against the byte-level emulator (real dynamixel-sdk)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from handrig.cli.calibrate_servos import calibrate, calibration_rig, update_zero_ticks
from handrig.config.loading import CONFIG_DIR
from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo import DynamixelBus
from handrig.errors import ConfigError
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


PROMPT = re.compile(r"at (\d+) ticks \(([+-][\d.]+) deg")


def two_servo_bus(rig: RigConfig, sim: SimBus) -> DynamixelBus:
    two = rig.__class__(bus=rig.bus, loop=rig.loop, servos=(rig.servo(7), rig.servo(8)))
    bus = DynamixelBus(sim.port_path, calibration_rig(two))
    bus.connect()
    return bus


def test_each_jog_shows_where_the_servo_settled_and_enter_accepts_that() -> None:
    rig = load_rig_config()
    said: list[str] = []
    prompts: list[str] = []
    answers = iter(["+1000", "nan", "inf", "+5", "+5", "", "s"])

    def ask(prompt: str) -> str:  # answers at once: no pause for the servo to arrive
        prompts.append(prompt)
        return next(answers)

    with SimBus.from_rig(rig, ids=[7, 8]) as sim:
        bus = two_servo_bus(rig, sim)
        try:
            with bus.torque(handle_signals=False):
                zeros = calibrate(bus, rig, [7, 8], jog=True, yes=False, ask=ask,
                                  say=said.append)
        finally:
            bus.close()
    assert sum("not a jog" in s for s in said) == 3
    shown = [PROMPT.search(p) for p in prompts]
    assert all(shown), prompts
    ticks = [int(m.group(1)) for m in shown if m]
    degs = [float(m.group(2)) for m in shown if m]
    # prompts 4, 5, 6 (servo 7): before any jog, after +5, after +5 more (10 deg in all)
    assert degs[3] == pytest.approx(0.0, abs=0.2)
    assert degs[4] == pytest.approx(5.0, abs=0.2)
    assert degs[5] == pytest.approx(10.0, abs=0.2)
    assert set(zeros) == {7}
    assert zeros[7] == ticks[5]  # exactly the reading the last prompt showed
    assert zeros[7] == pytest.approx(2048 + 10 * 4096 / 360, abs=3)


def test_by_hand_enter_reads_again_and_accepts_only_what_was_shown() -> None:
    rig = load_rig_config()
    said: list[str] = []
    prompts: list[str] = []
    with SimBus.from_rig(rig, ids=[7, 8]) as sim:
        moves = iter([2200, None, None])

        def ask(prompt: str) -> str:
            prompts.append(prompt)
            to = next(moves)
            if to is not None:  # a person moves the joint, then presses Enter
                servo = sim.servo(7)
                servo.set_motion(float(to), 0.0, 0.0)
            return "" if len(prompts) < 3 else "s"

        bus = two_servo_bus(rig, sim)
        try:
            bus.disable_torque()
            zeros = calibrate(bus, rig, [7, 8], jog=False, yes=False, ask=ask,
                              say=said.append)
        finally:
            bus.close()
    assert any("it moved (2048 -> 2200 ticks)" in s for s in said), said
    assert PROMPT.search(prompts[1]).group(1) == "2200"  # type: ignore[union-attr]
    assert zeros == {7: 2200}


def test_default_output_is_the_users_copy_and_the_checkout_stays_clean(tmp_path: Path) -> None:
    import os
    import subprocess
    import sys

    checkout = Path(__file__).resolve().parents[3]

    def status() -> str:
        res = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all",
                              "config"], cwd=checkout, capture_output=True, text=True)
        if res.returncode:
            pytest.skip("not a git checkout")
        return res.stdout

    before = status()
    env = {**os.environ, "XDG_CONFIG_HOME": str(tmp_path / "cfg")}
    res = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "calibrate", "servos", "--bus", "sim",
         "--ids", "1", "--yes"], capture_output=True, text=True, timeout=120, env=env,
    )
    assert res.returncode == 0, res.stderr
    mine = tmp_path / "cfg" / "handrig" / "rig.toml"
    assert f"wrote 1 zero(s) to {mine}" in res.stdout
    assert f"handrig run --config {mine}" in res.stdout
    assert load_rig_config(mine).servo(1).zero_ticks == pytest.approx(2048, abs=2)
    assert status() == before


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
