"""Robot gravity: how far the emulated LEAP's joints rest from their goals at Goal Current
350, compensation off vs on (simulated time), and what the per-cycle step costs beside
MuJoCo's own inverse dynamics.

Accuracy: ``sim.robot_gravity_check.gravity_error`` at three poses (every flexing joint
at 10, 25, 40 % of the way from 0 to its upper limit, side-to-side joints at 0), per
orientation of the hand (``[robot].gravity_direction``): per joint the mean |goal -
settled angle| over the poses, then RMS and max over all. Cost: the compiled step
(``GravityCompensation.apply``, 16 goals in, 16 out) and, for the same torques,
``mj_kinematics + mj_comPos + mj_rne`` on the compiled model, alternated in one run;
min and median of 25 batches of 2000 calls. ``HANDRIG_BENCH_GRAVITY_RIG``: the rig
(default ``leap``).
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import time
from collections.abc import Callable

import numpy as np

from handrig.app.robot_gravity import build_gravity
from handrig.pose.robot_rig import RobotRigConfig, load_rig
from sim.robot_gravity_check import gravity_error

DIRECTIONS: dict[str, tuple[float, float, float]] = {
    "as drawn [0,0,-1]": (0.0, 0.0, -1.0), "upside down [0,0,1]": (0.0, 0.0, 1.0),
    "on its side [0,1,0]": (0.0, 1.0, 0.0), "on its side [1,0,0]": (1.0, 0.0, 0.0),
}
GOAL_CURRENT_MA = 350


def _rig(name: str, direction: tuple[float, float, float]) -> RobotRigConfig:
    rig = load_rig(name)
    if not isinstance(rig, RobotRigConfig) or rig.robot is None:
        raise SystemExit(f"{name} is not a robot rig")
    return dataclasses.replace(rig, robot=dataclasses.replace(
        rig.robot, gravity=True, gravity_direction=direction))


def _batches_us(fn: Callable[[], object], calls: int = 2000) -> list[float]:
    t0 = time.perf_counter()
    for _ in range(calls):
        fn()
    return [(time.perf_counter() - t0) / calls * 1e6]


def main() -> None:
    name = os.environ.get("HANDRIG_BENCH_GRAVITY_RIG", "leap")
    print(f"{name}: goal - settled angle at Goal Current {GOAL_CURRENT_MA} mA, "
          "degrees (simulated time)")
    joints: tuple[str, ...] = ()
    for label, direction in DIRECTIONS.items():
        rig = _rig(name, direction)
        low = np.array([s.min_deg for s in rig.servos])
        high = np.array([s.max_deg for s in rig.servos])
        comp = build_gravity(rig, low, high)
        off = gravity_error(rig, None, goal_current_ma=GOAL_CURRENT_MA)
        on = gravity_error(rig, comp, goal_current_ma=GOAL_CURRENT_MA)
        if not joints:
            joints = off.joints
            print(f"  {'orientation':22s} {'':4s} {'rms':>6s} {'max':>6s}  "
                  + " ".join(f"{j:>6s}" for j in joints))
        for what, err in (("off", off), ("on", on)):
            print(f"  {label:22s} {what:4s} {err.rms_deg:6.3f} {err.max_deg:6.3f}  "
                  + " ".join(f"{v:6.2f}" for v in err.per_joint_deg))
    rig = _rig(name, (0.0, 0.0, -1.0))
    assert rig.robot is not None
    low = np.array([s.min_deg for s in rig.servos])
    high = np.array([s.max_deg for s in rig.servos])
    comp = build_gravity(rig, low, high)
    assert comp is not None
    import mujoco

    model = mujoco.MjModel.from_xml_path(rig.robot.model)
    data = mujoco.MjData(model)
    goals = low + 0.3 * (high - low)

    def with_mujoco() -> None:
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_rne(model, data, 0, data.qfrc_bias)

    ours: list[float] = []
    theirs: list[float] = []
    for _ in range(25):  # alternated: both see the same load
        ours += _batches_us(lambda: comp.apply(goals))
        theirs += _batches_us(with_mujoco)
    print(f"per-cycle cost, us (min / median of 25 x 2000 calls; load {os.getloadavg()[0]:.1f}):")
    print(f"  GravityCompensation.apply (torques + goals)  {min(ours):6.2f} / "
          f"{statistics.median(ours):6.2f}")
    print(f"  mj_kinematics + mj_comPos + mj_rne (torques)  {min(theirs):6.2f} / "
          f"{statistics.median(theirs):6.2f}")


if __name__ == "__main__":
    main()
