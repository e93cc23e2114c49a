"""Drive a robot hand from Python with human hand angles (handrig's library API).

    python examples/robot_hand.py                 # the LEAP hand, emulated (--port sim)
    python examples/robot_hand.py --rig orca      # the ORCA hand
    python examples/robot_hand.py --port /dev/ttyUSB0   # a real hand on that adapter

The human angles here come from a few lines of arithmetic (a hand closing into a
fist and opening again); in your program they come from a VR tracker, a vision
model or a recording: any source of the 50 curves of ``handrig.hand.CURVE_NAMES``.
"""

from __future__ import annotations

import argparse
import math
import time

from handrig.app.robot_api import RobotHand

FLEXIONS = [f"ri{finger}{joint}" for finger in ("Index", "Middle", "Ring", "Pinky")
            for joint in ("MCPy", "PIPy", "DIPy")]
THUMB = ["riThumbCMCy", "riThumbMCPz", "riThumbIPz"]


def human_pose(t_s: float, period_s: float = 2.0) -> dict[str, float]:
    """A hand that closes and opens once every ``period_s``: curves in degrees."""
    closed = 0.5 - 0.5 * math.cos(2.0 * math.pi * t_s / period_s)  # 0 open .. 1 fist
    pose = {name: 70.0 * closed for name in FLEXIONS}
    pose.update({name: 30.0 * closed for name in THUMB})
    return pose


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rig", default="leap", help="robot hand preset or rig file")
    p.add_argument("--port", default="sim", help="'sim' (the emulated hand) or a serial device")
    p.add_argument("--seconds", type=float, default=1.5, help="how long to drive the hand")
    args = p.parse_args()
    with RobotHand(args.rig, port=args.port) as robot:
        print(f"{args.rig}: {len(robot.joint_names)} joints, torque on: {robot.torque_on}")
        start = time.monotonic()
        while (t := time.monotonic() - start) < args.seconds:
            # the hand's loop runs in the background: command() sets the pose it
            # follows (at the rig's slew rate) and returns at once
            goals = robot.command(human_pose(t))
            time.sleep(0.01)  # your program's own rate: 100 Hz here
        # move_to() goes to a pose over the given time and returns when it is there
        present = robot.move_to(human_pose(t), seconds=0.3)
        k = int(abs(goals).argmax())
        joint = robot.joint_names[k]
        print(f"last goal {joint} {goals[k]:.1f} deg, present {present[joint]:.1f} deg")
    print(f"torque off after the block (read back from the servos): "
          f"{robot.torque_off_confirmed}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
