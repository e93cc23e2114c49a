"""The robot API moves (issue 37): the README's snippet, run as written, prints a value
near what it asked; input that is not a pose is refused with a ConfigError naming it
and leaves no joint stuck. (A rig without a port asks for one:
tests/handrig/cli/test_first_hour_messages.py, no emulator needed.)"""

from __future__ import annotations

import contextlib
import io
import math
import re
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.app.robot_api import RobotHand
from handrig.errors import ConfigError
from sim.dxl_bus import SimBus

ROOT = Path(__file__).resolve().parents[3]


def readme_snippet() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    found = [b for b in blocks if "RobotHand(" in b]
    assert len(found) == 1, "the README has one RobotHand snippet"
    return found[0]


def test_the_readme_snippet_prints_a_value_near_what_it_asked() -> None:
    snippet = readme_snippet()
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(snippet, "README.md", "exec"), {})  # as written, in this process
    lines = printed.getvalue().split()
    present, confirmed = float(lines[0]), lines[-1]
    asked = re.search(r"move_to\((\{.*?\})", snippet)
    assert asked is not None
    with_names = eval(asked.group(1))  # the snippet's own literal dict of curves
    # what the robot joint is asked (the retarget table, no hardware): the ORCA index MCP
    from handrig.app.parts import build_parts
    from handrig.pose.robot_rig import robot_retarget

    cfg = build_parts("orca").rig_config
    table = robot_retarget(cfg)
    human = np.array([with_names.get(n, 0.0) for n in hand.CURVE_NAMES])
    want = float(np.asarray(table.apply(human))[table.index("right_i-mcp")])
    servo = next(s for s in cfg.servos if s.joint == "right_i-mcp")
    want = min(max(want, servo.min_deg), servo.max_deg)
    assert abs(want) > 20.0  # a move worth checking
    assert present == pytest.approx(want, abs=3.0), (present, want, printed.getvalue())
    assert confirmed == "True"


BAD_POSES: list[tuple[object, str]] = [
    (None, "not a pose"),
    ("riIndexMCPy", "not a pose"),
    ([1.0, 2.0], "expected 50 human curves"),
    (np.zeros((2, 25)), "expected 50 human curves"),
    (["x"] * 50, "not a pose"),
    ({"riIndexMCPy": "forty"}, "riIndexMCPy = .*not a number"),
    ({"riIndexMCPy": None}, "riIndexMCPy: not a number"),
    ({"riIndexMCPy": math.inf}, "riIndexMCPy = .*not a finite number"),
    ({"riIndexPIPy": 1e300}, "riIndexPIPy = .*no joint angle"),
    ([1e308] * 50, f"^{hand.CURVE_NAMES[0]} = 1e\\+308: .*no joint angle"),
    ({7: 1.0}, "not a human curve"),
]


@pytest.fixture(scope="module")
def orca() -> Iterator[tuple[SimBus, RobotHand]]:
    """One ORCA hand on an in-process kinematic emulator, shared by the tests below (its
    start and its ease to rest on the way out are a second and a half); on the way out,
    torque off must be read back from every servo."""
    from handrig.config.rig_files import rig_file_path as rig_path

    with SimBus.from_rig(rig_path("orca"), realtime=False) as sim:
        with RobotHand("orca", port=sim.port_path) as robot:
            yield sim, robot
        assert robot.torque_off_confirmed is True


def test_input_that_is_not_a_pose_is_refused_and_leaves_no_joint_stuck(
        orca: tuple[SimBus, RobotHand]) -> None:
    _sim, robot = orca
    i = robot.joint_names.index("right_i-mcp")
    bent = {"riIndexMCPy": 30.0}
    robot.move_to(bent, seconds=0.1)
    held = np.array(list(robot.goals_deg().values()))
    for pose, message in BAD_POSES:
        with pytest.raises(ConfigError, match=message):
            robot.command(pose)  # type: ignore[arg-type]
        with pytest.raises(ConfigError, match=message):
            robot.move_to(pose, seconds=0.1)  # type: ignore[arg-type]
    # the loop kept the last good pose: the goals did not move
    np.testing.assert_allclose(list(robot.goals_deg().values()), held)
    with pytest.raises(ConfigError, match="seconds"):
        robot.move_to(bent, seconds=math.nan)
    # and every joint still follows: back to the flat hand and bent again
    flat = robot.targets_deg({})
    present = robot.move_to({}, seconds=0.1)
    assert present["right_i-mcp"] == pytest.approx(flat[i], abs=3.0)
    present = robot.move_to(bent, seconds=0.1)
    assert present["right_i-mcp"] == pytest.approx(robot.targets_deg(bent)[i], abs=3.0)


def test_a_silent_servo_meets_the_rigs_silence_policy_and_the_others_move_on(
        orca: tuple[SimBus, RobotHand]) -> None:
    """The robot API runs the show's loop: ORCA's [silence] (the defaults: warn, hold,
    then continue) makes a servo that stops answering NaN in the readings while the
    other joints keep following their commands."""
    from sim.dxl_faults import FaultSpec

    sim, robot = orca
    try:
        i = robot.joint_names.index("right_i-mcp")
        robot.move_to({}, seconds=0.0)
        sim.faults = FaultSpec(missing=frozenset({5}))  # right_m-abd stops answering
        bent = {"riIndexMCPy": 30.0}
        silent_since = time.monotonic()
        present = robot.move_to(bent, seconds=0.2)
        assert present["right_i-mcp"] == pytest.approx(robot.targets_deg(bent)[i], abs=3.0)
        # no reading for longer than hold_s (0.25 s): NaN; waited on, as move_to can
        # return before hold_s has passed (seen once on a loaded host)
        while not math.isnan(robot.present_deg()["right_m-abd"]):
            assert time.monotonic() - silent_since < 5.0, "servo 5's silence never showed"
            time.sleep(0.02)
        assert robot.torque_on  # "continue": the run goes on
        sim.faults = FaultSpec()  # it answers again: read again, and torque off reaches it
        t0 = time.monotonic()
        while math.isnan(robot.present_deg()["right_m-abd"]):
            assert time.monotonic() - t0 < 5.0, "servo 5 was never read again"
            time.sleep(0.02)
    finally:
        sim.faults = FaultSpec()  # torque off at the fixture's end reaches servo 5
