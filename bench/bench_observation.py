"""LeRobot robot observation: how old the servo positions are when LeRobot asks, the
robot loop's newest read (what ``handrig_leap``'s ``get_observation`` gives) against
its telemetry snapshot (what it gave before), side by side on the same calls.

The emulated LEAP hand (in-process, kinematic servos, no wire timing) under
``HandRobot`` (the plugin's logic), its loop at the preset's 200 Hz reading every 4
cycles; a caller asks at LeRobot's 30 fps for ``HANDRIG_BENCH_SECONDS`` (default 5)
while the hand closes and opens. Per call: the age of the newest read (now minus the
time that read ended) and of the snapshot's positions (now minus the newest reading
time in it); min, median, p99 and max in ms.
"""

from __future__ import annotations

import os
import time

import numpy as np

from handrig.app.lerobot.hand import HandRobot
from handrig.config.rig_files import rig_file_path
from sim.dxl_bus import SimBus

FPS = 30.0


def _row(name: str, ages_s: list[float]) -> str:
    a = np.asarray(ages_s) * 1e3
    return (f"  {name:<28} {a.min():6.1f} {np.median(a):6.1f} {np.percentile(a, 99):6.1f} "
            f"{a.max():6.1f}")


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", "5"))
    with SimBus.from_rig(rig_file_path("leap"), realtime=False) as sim:
        robot = HandRobot("leap", sim.port_path)
        robot.connect()
        try:
            loop = robot.hand._open_loop()
            names = robot.joint_names
            newest: list[float] = []
            snapshot: list[float] = []
            t0 = time.perf_counter()
            k = 0
            while (now := time.perf_counter()) - t0 < seconds:
                bend = 60.0 if int((now - t0) * 2) % 2 else 0.0  # close, open: 1 Hz
                robot.send({f"{j}.pos": bend if j.endswith(("_mcp", "_pip")) else 0.0
                            for j in names})
                robot.observation()
                snap = loop.snapshot()
                asked = time.perf_counter()
                if robot.observed is not None and snap is not None and snap.positions_deg:
                    newest.append(asked - robot.observed_at_s)
                    snapshot.append(asked - (snap.t_s - min(snap.reading_ages_s)))
                k += 1
                time.sleep(max(0.0, t0 + k / FPS - time.perf_counter()))
        finally:
            robot.disconnect()
    print(f"observation age at {FPS:g} fps over {seconds:g} s ({len(newest)} calls), ms:")
    print(f"  {'':<28} {'min':>6} {'median':>6} {'p99':>6} {'max':>6}")
    print(_row("newest read (now)", newest))
    print(_row("telemetry snapshot (before)", snapshot))


if __name__ == "__main__":
    main()
