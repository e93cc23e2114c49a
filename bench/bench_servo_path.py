"""The servo-target step (one compiled call a cycle): the human rig, the LEAP hand with its
retarget step, and the same LEAP curves without the step."""

from __future__ import annotations

import dataclasses
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from handrig.app import parts as app_parts
from handrig.pose import kernels
from handrig.pose.pipeline import PosePipeline

FRAMES = 20000


def _time(step: Callable[[int], object], frames: int = FRAMES) -> tuple[float, float]:
    for i in range(1000):
        step(i)
    clock = time.perf_counter_ns
    times = np.empty(frames)
    for i in range(frames):
        t0 = clock()
        step(i)
        times[i] = clock() - t0
    return float(np.median(times)) / 1e3, float(np.percentile(times, 99)) / 1e3


def _inputs(pl: PosePipeline) -> np.ndarray:
    rng = np.random.default_rng(0)
    means = pl.control_means_deg
    return np.ascontiguousarray(means + rng.normal(0.0, 10.0, size=(256, len(means))))


def _pipeline_step(pl: PosePipeline) -> Callable[[int], object]:
    inputs = _inputs(pl)
    return lambda i: pl.servo_targets(inputs[i & 255], -60.0, 20.0, 0.005)


def _without_the_step(pl: PosePipeline) -> Callable[[int], object]:
    """The kernel of a human rig on the curves the LEAP retarget reads: the LEAP path
    minus the retarget step."""
    robot = pl.robot_path
    assert robot is not None
    path, tables = robot.human, robot.human.sag
    inputs = _inputs(pl)
    features = np.zeros(inputs.shape[1] + len(path.knots))
    u = len(robot.curves)
    targets, raw = np.zeros(u), np.zeros(u)

    def step(i: int) -> object:
        return kernels.servo_targets(
            inputs[i & 255], path.knots, features, path.a, path.b, tables.inclination_axis_deg,
            tables.rotation_axis_deg, tables.rotation0_deg, tables.cell_offsets_deg,
            path.sag_slot, float(path.sag_gain), path.map_low, path.map_high, -60.0, 20.0,
            robot.human_low, robot.human_high, targets, 3.6, False, raw)
    return step


def _with_the_step(pl: PosePipeline) -> Callable[[int], object]:
    """The LEAP kernel called directly (no pipeline method around it)."""
    robot = pl.robot_path
    assert robot is not None
    path, tables = robot.human, robot.human.sag
    inputs = _inputs(pl)
    features = np.zeros(inputs.shape[1] + len(path.knots))
    human = np.zeros(len(robot.curves))
    n = len(pl.servo_joints)
    targets, raw = np.zeros(n), np.zeros(n)

    def step(i: int) -> object:
        return kernels.robot_servo_targets(
            inputs[i & 255], path.knots, features, path.a, path.b, tables.inclination_axis_deg,
            tables.rotation_axis_deg, tables.rotation0_deg, tables.cell_offsets_deg,
            path.sag_slot, float(path.sag_gain), path.map_low, path.map_high, -60.0, 20.0,
            robot.human_low, robot.human_high, human, robot.gain_start, robot.gain_curve,
            robot.gain_value, robot.offset, pl.servo_low, pl.servo_high, targets, 3.6, False, raw)
    return step


def _leap_with_sag(parts: app_parts.RigParts) -> PosePipeline:
    rig, old = parts.rig_config, parts.pipeline
    return PosePipeline(
        parts.expander, parts.sag, old.servo_joints,
        servo_limits_deg=np.array([[s.min_deg, s.max_deg] for s in rig.servos]),
        slew_deg_s=rig.loop.slew_deg_s, sag_gain=rig.loop.sag_gain,
        left_hand=rig.loop.left_hand, control_means_deg=old.control_means_deg,
        left_forearm_deg=rig.loop.left_forearm_deg, retarget=old.retarget)


def main() -> None:
    human = app_parts.build_parts().pipeline
    parts = app_parts.build_parts("leap")
    leap = parts.pipeline
    assert leap.robot_path is not None
    u = len(leap.robot_path.curves)
    rows = (
        (f"human rig, {len(human.servo_joints)} servos (sag on), pipeline call",
         _pipeline_step(human)),
        (f"LEAP, {len(leap.servo_joints)} servos: {u} curves + retarget (sag off), "
         "pipeline call", _pipeline_step(leap)),
        (f"LEAP, {u} curves + retarget, sag switched on, pipeline call",
         _pipeline_step(_leap_with_sag(parts))),
        (f"LEAP kernel with the retarget step ({u} curves -> {len(leap.servo_joints)} "
         "joints, sag off), kernel call", _with_the_step(leap)),
        (f"the same {u} curves without the retarget step (sag off), kernel call",
         _without_the_step(leap)),
    )
    for label, step in rows:
        med, p99 = _time(step)
        print(f"servo targets, {label}: median {med:.2f} us, p99 {p99:.2f} us")
    step = _pipeline_step(human)
    for gap_s in GAPS_S:
        med, again = _after_a_gap(step, gap_s)
        print(f"servo targets, human rig, after the thread spun {gap_s * 1e3:g} ms on the "
              f"clock: median {med:.2f} us (called again at once: {again:.2f} us)")
    if human.expander.map.piecewise:  # last: a base without the row still pairs line by line
        _hinges_side_by_side(human)


def _hinges_side_by_side(pl: PosePipeline, rounds: int = 5) -> None:
    """The human rig's step with the shipped piecewise-linear map and with the same map
    without its hinges (linear), alternated in one process: what the hinges cost."""
    linear = dataclasses.replace(pl.expander.map, knots_deg=None, hinge_gains=None)
    with tempfile.TemporaryDirectory() as d:
        lin = app_parts.build_parts(map_file=linear.save(Path(d) / "linear.toml")).pipeline
    steps = {"piecewise": _pipeline_step(pl), "linear": _pipeline_step(lin)}
    meds: dict[str, list[float]] = {k: [] for k in steps}
    for _ in range(rounds):
        for name, step in steps.items():
            meds[name].append(_time(step, FRAMES // 4)[0])
    print(f"servo targets, human rig, the shipped map with and without its hinges, {rounds}"
          " rounds alternated: " + ", ".join(
              f"{k} median {np.median(v):.2f} us (min {min(v):.2f})" for k, v in meds.items()))


GAPS_S = (0.0, 0.0001, 0.001, 0.004)  # 4 ms: about the gap between two 200 Hz frames


def _after_a_gap(step: Callable[[int], object], gap_s: float, n: int = 300
                 ) -> tuple[float, float]:
    """Median time of ``step`` after the thread did nothing but read the clock for
    ``gap_s``, and of a second call straight after: the cost of caches that went cold
    meanwhile (on a VM, other guests share them) with no sleep or idle state involved."""
    clock = time.perf_counter
    first, second = np.empty(n), np.empty(n)
    for i in range(n):
        end = clock() + gap_s
        while clock() < end:
            pass
        t0 = clock()
        step(i)
        t1 = clock()
        step(i + 1)
        first[i], second[i] = t1 - t0, clock() - t1
    return float(np.median(first)) * 1e6, float(np.median(second)) * 1e6
