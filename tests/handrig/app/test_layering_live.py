"""Takes layered under the live glove, on real parts (issue 40): an emulated glove on a
pty, the live session, the real Dynamixel driver and the byte-level bus emulator
(:class:`sim.dxl_bus.SimBus`, in this process), whose received goal Sync Writes are
what the tests check.

A take is recorded from a sweeping glove on the two-hand puppet; then, under a still
glove, it is layered onto the left hand: on the bus the left hand's goals follow the
take at the run's time while the right hand's hold the glove's pose, and the run's
recording holds the whole pose as played. A cue (``LayerControl.layer``) starts and
stops a layer mid-run; bad takes and groups are refused before any goal is sent.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from handrig.app.layering import LayerControl, LayerOptions, LayerSpec
from handrig.app.parts import build_parts
from handrig.app.result import LiveResult
from handrig.app.session import LiveOptions, run_live
from handrig.cli import main
from handrig.config.rig import RigConfig
from handrig.devices.glove_recording import sweep_recording
from handrig.devices.servo.positions import ticks_to_deg
from handrig.errors import ConfigError
from handrig.loop.rig import Rig
from handrig.outputs.recorder import load_performance
from handrig.pose.pipeline import POSE_NAMES, POSE_SIZE
from handrig.pose.robot_rig import load_rig
from sim.dxl_bus import GOAL_POSITION_ADDRESS, SimBus
from sim.glove_emulator import GloveEmulator

RIG = "puppet_two_hands"
# the performance recorded: the sweep's samples sent at 200 Hz, a third of its speed (its
# sines 3 to 4.5 s long), so that the take stays within the slew limit a live glove has
SWEEP = sweep_recording(12.0, 600.0, 5)
STILL = sweep_recording(4.0, 200.0, 5, low=2000.0, high=2000.0, with_imu=False)
SETTLED_S = 0.6  # the ease in (0.3 s) and the layer's fade in (0.5 s) are over


class GoalWatch:
    """Each goal Sync Write the emulated bus received: its time (the bus thread's read,
    on CLOCK_MONOTONIC, the session's clock too) and each servo's goal in degrees."""

    def __init__(self, rig: RigConfig) -> None:
        self.rig = rig
        self.times_s: list[float] = []
        self.goals: list[dict[int, float]] = []

    def __call__(self, t_s: float, address: int, items: list[tuple[int, bytes]]) -> None:
        if address != GOAL_POSITION_ADDRESS:
            return
        self.times_s.append(t_s)
        self.goals.append({sid: ticks_to_deg(self.rig.servo(sid),
            int.from_bytes(data[:4], "little", signed=True)) for sid, data in items})

    def of(self, sid: int, t0_s: float, start_s: float, end_s: float
           ) -> tuple[np.ndarray, np.ndarray]:
        """Servo ``sid``'s goals written from ``start_s`` to ``end_s`` into the run."""
        t = np.array(self.times_s) - t0_s
        g = np.array([goals.get(sid, np.nan) for goals in self.goals])
        keep = (t >= start_s) & (t <= end_s) & np.isfinite(g)
        return t[keep], g[keep]


def _session(glove: GloveEmulator, sim: SimBus, seconds: float, *,
             layering: LayerOptions | None = None, record: Path | None = None,
             on_hands: Any = None) -> LiveResult:
    lines: list[str] = []
    result = run_live(build_parts(RIG), LiveOptions(
        glove=glove.port_path, bus=sim.port_path, duration_s=seconds,
        record=str(record) if record else None, layering=layering, log=lines.append,
        on_hands=on_hands))
    assert result.started and result.error is None, (result.error, lines[-10:])
    assert result.summary["torque_off"] is True
    return result


def _following(goals: np.ndarray, take: Path, t_s: np.ndarray, joint: str,
               low: float = -np.inf, high: float = np.inf) -> np.ndarray:
    """How far each goal received at ``t_s`` (take time) is from the take's ``joint`` at
    some moment of the 40 ms before it (a loaded machine can stamp a write late). The
    take holds the pose as performed, before the slew limit: where it moved faster than
    [loop] slew_deg_s the layered goals lag it, as the live goals lagged the glove."""
    lags = np.linspace(0.0, 0.04, 9)
    performed = np.stack([np.clip(_take_at(take, t_s - lag, joint), low, high)
                          for lag in lags])
    return np.abs(performed - goals[None, :]).min(axis=0)


def _take_at(take: Path, t_s: np.ndarray, joint: str) -> np.ndarray:
    """The take's ``joint`` at times ``t_s`` from its first frame (the layer's time)."""
    times, poses, wrist = load_performance(take)
    full = np.zeros((len(times), POSE_SIZE))
    full[:, :poses.shape[1]] = poses
    if wrist is not None:
        full[:, poses.shape[1]:] = wrist
    return np.interp(t_s, times - times[0], full[:, POSE_NAMES.index(joint)])


@pytest.fixture(scope="module")
def take(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """1.2 s of the two-hand puppet performed from a sweeping glove, recorded."""
    path = tmp_path_factory.mktemp("takes") / "performance.csv"
    with (GloveEmulator(SWEEP, "frames", rate_hz=200.0, loop=True) as glove,
          SimBus.from_rig(RIG) as sim):
        _session(glove, sim, 1.2, record=path)
    return path


def _rigs(store: dict[str, Rig]) -> Any:
    def on_hands(rigs: Mapping[str, Rig], _all: Any) -> None:
        store.update(rigs)
    return on_hands


def test_a_take_layered_on_the_left_hand_under_a_live_right_glove(
        take: Path, tmp_path: Path) -> None:
    rig = load_rig(RIG)
    watch = GoalWatch(rig)
    layered = tmp_path / "layered.csv"
    rigs: dict[str, Rig] = {}
    with (GloveEmulator(STILL, "frames", rate_hz=200.0, loop=True) as glove,
          SimBus.from_rig(RIG) as sim):
        sim.on_sync_write = watch
        result = _session(glove, sim, 1.5, record=layered, on_hands=_rigs(rigs),
                          layering=LayerOptions(layers=(LayerSpec(str(take), "left"),)))
        outside = sim.stats.goals_outside
    assert outside == 0
    loop = rigs[""]
    t0 = loop.started_at
    pipeline = loop.pipeline
    followed = 0
    for servo in rig.servos:
        k = pipeline.servo_joints.index(servo.joint)
        t, goals = watch.of(servo.id, t0, SETTLED_S, 1.45)
        assert len(t) > 100, servo.joint
        low, high = pipeline.servo_low[k], pipeline.servo_high[k]
        performed = np.clip(_take_at(take, t, servo.joint), low, high)
        if servo.joint.startswith("le"):  # the take's, at the run's time
            err = _following(goals, take, t, servo.joint, low, high)
            assert np.median(np.abs(goals - performed)) < 0.5, servo.joint
            assert np.percentile(err, 95) < 1.0 and err.max() < 5.0, (servo.joint, err.max())
            followed += np.ptp(performed) > 5.0
        else:  # the still glove's: held while the take moved that joint too
            assert np.ptp(goals) < 0.5, (servo.joint, np.ptp(goals))
    assert followed >= 5  # the take moved the left hand a lot, and the bus followed it
    assert any(np.ptp(_take_at(take, np.linspace(SETTLED_S, 1.45, 50), s.joint)) > 5.0
               for s in rig.servos if s.joint.startswith("ri"))
    # the recording of the layered run holds the whole pose as played
    times, poses, _ = load_performance(layered)
    window = (times >= SETTLED_S) & (times <= 1.45)
    for name in ("leIndexMCPy", "leMiddlePIPy", "leThumbCMCz"):
        i = POSE_NAMES.index(name)
        np.testing.assert_allclose(poses[window, i], _take_at(take, times[window], name),
                                   atol=0.05)  # the CSV's rounded times
    right = poses[window, POSE_NAMES.index("riIndexMCPy")]
    assert np.ptp(right) < 0.5
    events = result.summary["events"]
    assert any("layer left <- " in e and "fading in" in e for e in events), events
    assert "left <- " in loop.telemetry.latest().layers[0]


def test_a_cue_layers_a_named_take_mid_run_and_fades_it_out(take: Path) -> None:
    rig = load_rig(RIG)
    watch = GoalWatch(rig)
    rigs: dict[str, Rig] = {}
    controls: list[LayerControl] = []
    cued: dict[str, float] = {}
    refused: list[str] = []

    def cues(control: LayerControl) -> None:  # what the OSC and MIDI cues call
        controls.append(control)

        def script() -> None:
            deadline = time.monotonic() + 30.0
            while (not rigs or rigs[""].stats.frames < 100) and time.monotonic() < deadline:
                time.sleep(0.01)
            for bad in (("chorus", "left"), ("verse", "middle"), ("verse", "left.toe")):
                try:
                    control.layer(*bad)
                except ConfigError as exc:
                    refused.append(str(exc))
            cued["on"] = time.monotonic()
            control.layer("verse", "right.index")
            time.sleep(1.0)
            cued["off"] = time.monotonic()
            control.layer("verse", "off")
        threading.Thread(target=script, daemon=True).start()

    with (GloveEmulator(STILL, "frames", rate_hz=200.0, loop=True) as glove,
          SimBus.from_rig(RIG) as sim):
        sim.on_sync_write = watch
        result = _session(glove, sim, 2.4, on_hands=_rigs(rigs), layering=LayerOptions(
            takes={"verse": str(take)}, on_control=cues))
    assert controls and "on" in cued and "off" in cued
    assert "unknown take" in refused[0] and "verse" in refused[0]
    assert "left.middle or right.middle" in refused[1] and "unknown group" in refused[2]
    sid = next(s.id for s in rig.servos if s.joint == "riIndexMCPy")
    _, before = watch.of(sid, 0.0, 0.0, cued["on"])
    t_on, on = watch.of(sid, cued["on"], 0.55, 0.95)
    _, after = watch.of(sid, cued["off"], 0.55, 0.7)
    glove_value = before[-1]
    # the take from the cue's moment (its own time 0 there), then back to the glove
    performed = _take_at(take, t_on, "riIndexMCPy")
    err = _following(on, take, t_on, "riIndexMCPy")
    assert np.median(np.abs(on - performed)) < 1.0
    assert np.percentile(err, 95) < 1.0 and err.max() < 5.0
    assert np.abs(performed - glove_value).max() > 3.0  # the take went where the glove did not
    assert np.abs(after - glove_value).max() < 0.5
    # the fade in: from the glove's value toward the take's, no write beyond either
    _, fading = watch.of(sid, cued["on"], 0.0, 0.5)
    ends = (glove_value, *_take_at(take, np.linspace(0.0, 0.5, 51), "riIndexMCPy"))
    assert min(ends) - 0.2 <= fading.min() and fading.max() <= max(ends) + 0.2
    events = result.summary["events"]
    assert any("right.index <- verse" in e and "ended" in e for e in events), events


def test_an_unknown_take_or_group_is_refused_before_any_goal(take: Path, capsys: Any) -> None:
    with (GloveEmulator(STILL, "frames", rate_hz=200.0, loop=True) as glove,
          SimBus.from_rig(RIG) as sim):
        for layer, said in ((f"{take.parent / 'nope.csv'}:left", "no such take"),
                            (f"{take}:middle", "left.middle or right.middle")):
            status = main(["run", "--rig", RIG, "--glove", glove.port_path, "--bus",
                           sim.port_path, "--seconds", "1", "--layer", layer])
            err = capsys.readouterr().err
            assert status == 2 and "--layer" in err and said in err, err
        assert sim.stats.goals_decoded == 0
