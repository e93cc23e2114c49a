"""A servo missing at start-up that answers later is admitted; one that restarts
mid-show is given torque back (issue 24.2).

A real ``handrig run`` (shipped ``[silence] action = "continue"``) against the bus
emulator on a pty whose servo 7 does not answer at start-up (``missing=7``). A
second into the run it is plugged back (the fault switched off), resting away from
its zero. Watched on the bus side: no goal reaches servo 7 before it has torque
(commissioned), its first goal is where it rests, its goals then move at most the
slew limit per write (eased in, never a jump), no goal to any servo is outside its
limits; the run names it, the summary lists it as admitted and counts it, and
torque is off on every servo at the end. A servo that restarts on its own mid-run
(a power loss: the emulated servo's reboot, torque off and RAM reset) is found by
its Bus Watchdog reading 0, commissioned again and eased back from where it rests.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from handrig.config.rig import TICKS_PER_DEG, load_rig_config
from sim.demo_recording import DEMO_RECORDING
from sim.dxl_bus import GOAL_POSITION_ADDRESS, SimBus
from sim.dxl_faults import FaultSpec

CLI = [sys.executable, "-m", "handrig.cli"]
MISSING = 7


def test_a_servo_missing_at_start_is_admitted_when_it_answers_and_eased_in(
        tmp_path: Path) -> None:
    rig = load_rig_config()
    assert rig.silence.action == "continue"  # the shipped policy
    servo = rig.servo(MISSING)
    who = f"servo {MISSING} ({servo.joint})"
    ticks_per_deg = servo.direction * servo.gear_ratio * TICKS_PER_DEG
    rest_deg = servo.min_deg + 0.2 * (servo.max_deg - servo.min_deg)
    rest_ticks = round(servo.zero_ticks + rest_deg * ticks_per_deg)
    env = {**os.environ, "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path / "cfg"),
           "MUJOCO_GL": "egl"}
    # (time, goal ticks, servo 7's torque on, its Present Position) per goal Sync Write
    seen: list[tuple[float, int, bool, int]] = []
    writes_without_it = [0]

    with SimBus.from_rig(rig, faults=FaultSpec(missing=frozenset({MISSING}))) as sim:
        emulated = sim.servo(MISSING)

        def on_write(t_s: float, address: int, items: list[tuple[int, bytes]]) -> None:
            if address != GOAL_POSITION_ADDRESS:
                return
            goal = dict(items).get(MISSING)
            if goal is None:
                writes_without_it[0] += 1
                return
            seen.append((t_s, int.from_bytes(goal, "little", signed=True),
                         emulated.torque_enabled, emulated.present))

        sim.on_sync_write = on_write
        err = tmp_path / "stderr.txt"
        with open(err, "w") as f:
            proc = subprocess.Popen(
                [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", sim.port_path,
                 "--seconds", "4", "--json"],
                stdout=subprocess.PIPE, stderr=f, text=True, env=env)
        try:
            deadline = time.monotonic() + 120
            while "commissioned" not in err.read_text():
                assert proc.poll() is None, err.read_text()
                assert time.monotonic() < deadline, "the rig never commissioned the servos"
                time.sleep(0.05)
            time.sleep(1.0)  # the others follow the glove; servo 7 is left out
            with sim.lock:  # it rests away from its zero, torque off, then answers again
                d = -1 if emulated.mem[10] & 1 else 1
                homing = int.from_bytes(emulated.mem[20:24], "little", signed=True)
                emulated.set_motion(d * (rest_ticks - homing), 0.0, 0.0)
                assert emulated.present == rest_ticks
                sim.faults = FaultSpec()
            out, _ = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        torque_at_end = [sim.servo(s.id).torque_enabled for s in rig.servos]
        outside = sim.stats.goals_outside
    said = err.read_text()
    summary = json.loads(out.strip().splitlines()[-1])
    assert proc.returncode == 0 and "error" not in summary, (summary.get("error"), said)
    assert writes_without_it[0] > 50, "the others never followed the glove before"
    assert seen, f"{who} was never sent a goal after it answered: {said[-2000:]}"
    # commissioned and given torque before its first goal, which is where it rests
    assert all(torque for _, _, torque, _ in seen), "a goal reached it before torque-on"
    first_ticks = seen[0][1]
    assert abs(first_ticks - rest_ticks) <= rig.loop.slew_deg_s * 0.02 * abs(ticks_per_deg), (
        first_ticks, rest_ticks)
    # eased in: no step between its goals faster than the slew limit (plus a tick)
    for (t0, g0, _, _), (t1, g1, _, _) in itertools.pairwise(seen):
        allowed = rig.loop.slew_deg_s * max(t1 - t0, 0.006) * abs(ticks_per_deg) + 2
        assert abs(g1 - g0) <= allowed, f"goal jumped {g1 - g0} ticks in {t1 - t0:.4f} s"
    assert len(seen) > 50  # it followed the glove for the rest of the run
    assert outside == 0
    assert summary["servos_left_out"] == [who]
    assert summary["servos_admitted"] == [who]
    assert summary["silence"]["admitted"] == 1
    assert summary["silence"]["held"] == 0  # no tiers for a servo left out
    assert any(e.startswith(f"{who} answered") and "commissioned" in e
               for e in summary["events"]), summary["events"]
    assert summary["torque_off"] is True and not any(torque_at_end)


def test_a_servo_that_restarts_mid_run_gets_torque_back_where_it_rests(
        tmp_path: Path) -> None:
    rig = load_rig_config()
    servo = rig.servo(MISSING)
    who = f"servo {MISSING} ({servo.joint})"
    ticks_per_deg = servo.direction * servo.gear_ratio * TICKS_PER_DEG
    rest_deg = servo.min_deg + 0.2 * (servo.max_deg - servo.min_deg)
    rest_ticks = round(servo.zero_ticks + rest_deg * ticks_per_deg)
    env = {**os.environ, "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path / "cfg"),
           "MUJOCO_GL": "egl"}
    seen: list[tuple[float, int, bool]] = []  # (time, goal ticks, torque on) for servo 7
    with SimBus.from_rig(rig) as sim:
        emulated = sim.servo(MISSING)

        def on_write(t_s: float, address: int, items: list[tuple[int, bytes]]) -> None:
            goal = dict(items).get(MISSING) if address == GOAL_POSITION_ADDRESS else None
            if goal is not None:
                seen.append((t_s, int.from_bytes(goal, "little", signed=True),
                             emulated.torque_enabled))

        sim.on_sync_write = on_write
        err = tmp_path / "stderr.txt"
        with open(err, "w") as f:
            proc = subprocess.Popen(
                [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", sim.port_path,
                 "--seconds", "4", "--json"],
                stdout=subprocess.PIPE, stderr=f, text=True, env=env)
        try:
            deadline = time.monotonic() + 120
            while "commissioned" not in err.read_text():
                assert proc.poll() is None, err.read_text()
                assert time.monotonic() < deadline, "the rig never commissioned the servos"
                time.sleep(0.05)
            time.sleep(1.0)
            with sim.lock:  # power lost and back: torque off, RAM reset; it sags to rest
                emulated.reboot(sim.clock.now())
                d = -1 if emulated.mem[10] & 1 else 1
                homing = int.from_bytes(emulated.mem[20:24], "little", signed=True)
                emulated.set_motion(d * (rest_ticks - homing), 0.0, 0.0)
                restarted = len(seen)
            out, _ = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        outside = sim.stats.goals_outside
    summary = json.loads(out.strip().splitlines()[-1])
    assert proc.returncode == 0 and "error" not in summary, (summary.get("error"),
                                                              err.read_text())
    after = seen[restarted:]
    back = next((k for k, (_, _, torque) in enumerate(after) if torque), None)
    assert back is not None and back > 0, "torque never came back (or never went)"
    # the first goal with torque back is where it rests; then at most the slew limit
    assert abs(after[back][1] - rest_ticks) <= rig.loop.slew_deg_s * 0.02 * abs(ticks_per_deg)
    for (t0, g0, _), (t1, g1, _) in itertools.pairwise(after[back:]):
        allowed = rig.loop.slew_deg_s * max(t1 - t0, 0.006) * abs(ticks_per_deg) + 2
        assert abs(g1 - g0) <= allowed, f"goal jumped {g1 - g0} ticks in {t1 - t0:.4f} s"
    assert outside == 0
    assert summary["bus"]["reboots"] >= 1
    assert any(e.startswith(f"{who} restarted on its own") and "torque on where it is" in e
               for e in summary["events"]), summary["events"]
    assert summary["torque_off"] is True
