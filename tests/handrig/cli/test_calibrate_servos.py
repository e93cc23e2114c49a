"""``handrig calibrate servos`` against the byte-level emulator (real dynamixel-sdk)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from handrig.cli.calibrate_servos import calibrate, update_zero_ticks
from handrig.config.loading import CONFIG_DIR
from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo.dynamixel_zeroing import DynamixelZeroing
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
    import tomllib

    text = ("[bus]\nbaud = 1000000\n\n[[servos]]  # the index PIP\n"
            "zero_ticks = 100  # set by hand\nid = 3\n"
            "joint = \"riIndexPIPy\"\n\n[[servos]]\nid = 4\njoint = \"riRingPIPy\"\n")
    new = update_zero_ticks(text, {3: 2000, 4: 2100})
    assert "[[servos]]  # the index PIP\nzero_ticks = 2000  # set by hand\nid = 3" in new
    servos = tomllib.loads(new)["servos"]
    assert [(s["id"], s["zero_ticks"]) for s in servos] == [(3, 2000), (4, 2100)]


PROMPT = re.compile(r"at (\d+) ticks \(([+-][\d.]+) deg")


def two_servo_bus(rig: RigConfig, sim: SimBus, ids: tuple[int, int] = (7, 8)
                  ) -> DynamixelZeroing:
    two = rig.__class__(bus=rig.bus, loop=rig.loop, servos=tuple(rig.servo(i) for i in ids))
    bus = DynamixelZeroing(sim.port_path, two)
    bus.connect()
    return bus


def test_each_jog_shows_where_the_servo_settled_and_two_enters_accept_that() -> None:
    rig = load_rig_config()
    said: list[str] = []
    prompts: list[str] = []
    answers = iter(["+1000", "nan", "inf", "+5", "+5", "", "", "s"])

    def ask(prompt: str) -> str:  # answers at once: no pause for the servo to arrive
        prompts.append(prompt)
        return next(answers)

    with SimBus.from_rig(rig, ids=[7, 8]) as sim:
        bus = two_servo_bus(rig, sim)
        try:
            with bus.torque(handle_signals=False):
                changes = calibrate(bus, rig, [7, 8], jog=True, yes=False, ask=ask,
                                    say=said.append, direction_check=False)
        finally:
            bus.close()
    assert sum("not a jog" in s for s in said) == 3
    assert "between -110 and +110 (the joint's range)" in said[0]  # riIndexMCPy: -20..90
    shown = [PROMPT.search(p) for p in prompts[:6]]
    assert all(shown), prompts
    ticks = [int(m.group(1)) for m in shown if m]
    degs = [float(m.group(2)) for m in shown if m]
    # prompts 4, 5, 6 (servo 7): before any jog, after +5, after +5 more (10 deg in all)
    assert degs[3] == pytest.approx(0.0, abs=0.2)
    assert degs[4] == pytest.approx(5.0, abs=0.2)
    assert degs[5] == pytest.approx(10.0, abs=0.2)
    assert "Enter accepts this zero" in prompts[6]  # the second step
    assert set(changes) == {7}
    assert changes[7] == {"zero_ticks": ticks[5]}  # exactly the reading the prompt showed
    assert ticks[5] == pytest.approx(2048 + 10 * 4096 / 360, abs=3)


def test_one_jog_may_cover_the_joints_range_and_a_large_shift_needs_yes_typed() -> None:
    rig = load_rig_config()
    said: list[str] = []
    answers = iter(["-60", "", "", "", "-20", "", "yes"])
    with SimBus.from_rig(rig, ids=[19, 20]) as sim:
        bus = two_servo_bus(rig, sim, (19, 20))
        try:
            with bus.torque(handle_signals=False):
                changes = calibrate(bus, rig, [19], jog=True, yes=False,
                                    ask=lambda _p: next(answers), say=said.append,
                                    direction_check=False)
        finally:
            bus.close()
    text = "\n".join(said)
    assert "not a jog" not in text
    # -60 deg in one jog; Enter reads, Enter does not accept a shift over 20 deg: it reads again
    assert text.count("needs a confirmation: the zero moves -60.") == 2
    assert "max_zero_shift_deg = 20" in text
    assert changes[19]["zero_ticks"] == pytest.approx(2048 - 80 * 4096 / 360, abs=4)


def test_by_hand_enter_reads_then_enter_accepts_only_what_was_shown() -> None:
    rig = load_rig_config()
    said: list[str] = []
    prompts: list[str] = []
    with SimBus.from_rig(rig, ids=[7, 8]) as sim:
        moves = iter([2200, 2250, None, None, None])

        def ask(prompt: str) -> str:
            prompts.append(prompt)
            to = next(moves)
            if to is not None:  # a person moves the joint, then presses Enter
                sim.servo(7).set_motion(float(to), 0.0, 0.0)
            return "" if "riIndexMCPy" in prompt else "s"

        bus = two_servo_bus(rig, sim)
        try:
            bus.relax()
            changes = calibrate(bus, rig, [7, 8], jog=False, yes=False, ask=ask,
                                say=said.append, direction_check=False)
        finally:
            bus.close()
    # read 2200; moved to 2250 before Enter accepted: not taken, read again
    assert any("it moved (2200 -> 2250 ticks)" in s for s in said), said
    assert any("reads 2250 ticks: zero_ticks 2048 -> 2250" in s for s in said), said
    assert changes == {7: {"zero_ticks": 2250}}


def test_a_zero_whose_range_leaves_the_servos_travel_narrows_the_limits() -> None:
    rig = load_rig_config()
    wrist = rig.servo(19)  # -70..80 deg
    propose = DynamixelZeroing("not opened", rig).propose  # nothing on the wire
    fine = propose(wrist, 2100, 20.0)
    assert fine.reasons == () and fine.limits_deg is None
    assert fine.shift_deg == pytest.approx(52 * 360 / 4096)
    far = propose(wrist, 600, 20.0)  # -127 deg: 80 deg of flexion needs ticks up to 1510,
    assert len(far.reasons) == 2  # -70 deg ticks down to -196: outside 0..4095
    assert "more than [calibration] max_zero_shift_deg = 20" in far.reasons[0]
    assert "outside the servo's travel 0..4095" in far.reasons[1]
    assert far.limits_deg == (pytest.approx(-52.7), 80.0)
    assert load_rig_config().servo(19).min_deg == -70.0


def test_direction_check_by_hand_flips_a_reversed_servo() -> None:
    rig = load_rig_config()
    said: list[str] = []
    answers = iter(["", "", "", "y"])
    with SimBus.from_rig(rig, ids=[7, 8]) as sim:
        bus = two_servo_bus(rig, sim)
        calls = 0

        def ask(prompt: str) -> str:
            nonlocal calls
            calls += 1
            if calls == 3:  # the person flexes the joint: this servo reads it as -15 deg
                sim.servo(7).set_motion(2048 - 15 * 4096 / 360, 0.0, 0.0)
            return next(answers)

        try:
            bus.relax()
            changes = calibrate(bus, rig, [7], jog=False, yes=False, ask=ask, say=said.append)
        finally:
            bus.close()
    assert changes == {7: {"zero_ticks": 2048, "direction": -1}}


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
    assert f"wrote 1 servo calibration(s) to {mine}" in res.stdout
    assert "`handrig run` and `handrig demo` read it from now on" in res.stdout
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
    assert "wrote 2 servo calibration(s)" in res.stdout
    cfg = load_rig_config(out)  # the written file loads and validates
    assert abs(cfg.servo(1).zero_ticks - 2048) <= 2 and cfg.servo(3).zero_ticks == 2048
    bad = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "calibrate", "servos", "--bus", "sim",
         "--ids", "1,99", "--yes", "--out", str(out)],
        capture_output=True, text=True, timeout=90,
    )
    assert bad.returncode == 2 and "--ids" in bad.stderr and "Traceback" not in bad.stderr


def test_direction_check_jogging_asks_whether_the_joint_flexed_and_flips_on_no() -> None:
    rig = load_rig_config()
    prompts: list[str] = []
    answers = iter(["", "", "n"])
    with SimBus.from_rig(rig, ids=[7, 8]) as sim:
        bus = two_servo_bus(rig, sim)
        seen: list[int] = []

        def ask(prompt: str) -> str:
            prompts.append(prompt)
            seen.append(sim.servo(7).goal)
            return next(answers)

        try:
            with bus.torque(handle_signals=False):
                changes = calibrate(bus, rig, [7], jog=True, yes=False, ask=ask,
                                    say=lambda _s: None)
            back = sim.servo(7).goal
        finally:
            bus.close()
    assert "Did the joint flex" in prompts[2]
    assert seen[2] == round(2048 + 10 * 4096 / 360)  # +10 deg, inside [-20, 90]
    assert back == 2048  # returned to the zero after the question
    assert changes == {7: {"zero_ticks": 2048, "direction": -1}}


def test_no_clamps_means_no_clamp_advice_in_the_summary() -> None:
    from handrig.app.summary import format_summary, summary_dict
    from handrig.devices.servo.bus import BusStats
    from handrig.loop.stats import RunStats

    summary = summary_dict(RunStats(frames=100, duration_s=1.0), BusStats(20), None, True)
    summary["clamp_advice"] = "no clamps"
    text = format_summary(summary)
    assert "limit clamps      0 servo targets" in text
    assert "high all the time" not in text and "recalibrate the glove" not in text
