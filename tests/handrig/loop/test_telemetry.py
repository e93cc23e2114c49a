"""The loop's telemetry: frozen snapshots of plain tuples, published at most 30 times a second,
read from another thread while the loop runs."""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
import threading
from pathlib import Path

import numpy as np
import pytest

from handrig.clock import FakeClock
from handrig.loop.telemetry import LoopSnapshot, Telemetry
from handrig.outputs.base import Output, OutputStatus
from handrig.outputs.recorder import Recorder
from handrig.pose.pipeline import POSE_NAMES
from tests.helpers.fakes import FakeBus, ScriptedGlove
from tests.helpers.loop import MID, make_rig


class CountingOutput(Output):
    def __init__(self) -> None:
        self.frames = 0

    def __call__(self, t_s: float, pose_deg: np.ndarray) -> None:
        self.frames += 1

    def status(self) -> OutputStatus:
        return OutputStatus(kind="test", name="counter", frames_written=self.frames)


def test_publication_is_rate_limited_and_numbered() -> None:
    tel = Telemetry(every_s=0.05)
    built: list[int] = []
    times: list[float] = []

    def build(t: float, seq: int) -> LoopSnapshot:
        built.append(seq)
        times.append(t)
        return LoopSnapshot(t, seq, "running", "", 200.0, None, None, 0, seq, 0)

    assert tel.latest() is None
    published = [tel.offer(k * 0.005, build) for k in range(100)]  # 0.5 s at 200 Hz
    assert sum(published) == 10 and built == list(range(1, 11))
    snap = tel.latest()
    assert snap is not None and snap.seq == 10 and snap.t_s == times[-1]
    assert min(np.diff(times)) >= 0.05 - 1e-9 and max(np.diff(times)) <= 0.055 + 1e-9
    assert tel.offer(0.451, build, force=True) and tel.latest().seq == 11  # type: ignore[union-attr]
    with pytest.raises(dataclasses.FrozenInstanceError):
        snap.mode = "stopped"  # type: ignore[misc]


def test_a_run_publishes_what_the_loop_did(tmp_path: Path) -> None:
    from handrig.app.parts import build_parts

    parts = build_parts()
    clock = FakeClock(10.0)
    glove = ScriptedGlove(clock, lambda t: MID)
    joints = tuple(s.joint for s in parts.rig_config.servos)
    bus = FakeBus(joints, clock, write_cost_s=50e-6)
    counter = CountingOutput()
    rec = Recorder(tmp_path / "take.csv", rate_hz=200.0, sync=False)
    rig = make_rig(parts, glove, bus, clock, outputs=[counter, rec])
    seen: list[LoopSnapshot] = []
    done = threading.Event()

    def watch() -> None:  # another thread reads while the loop runs
        while not done.is_set():
            s = rig.telemetry.latest()
            if s is not None and (not seen or s.seq != seen[-1].seq):
                seen.append(s)

    t = threading.Thread(target=watch)
    t.start()
    try:
        rig.run(frames=200)
    finally:
        done.set()
        t.join()
    rec.close()
    last = rig.telemetry.latest()
    assert last is not None and last.mode == "stopped"
    # 200 frames + 0.5 s of easing at 200 Hz = 1.5 s: a snapshot every 1/30 s or so
    # (at the first cycle at least that long after the last: every 7th at 200 Hz)
    assert 38 <= last.seq <= 47
    assert all(b.seq > a.seq and b.t_s >= a.t_s for a, b in itertools.pairwise(seen))
    assert last.cycles == rig.stats.frames and last.frames_lost == 0
    assert last.latency_p50_us == pytest.approx(50.0, abs=1.0)
    assert last.rate_hz == pytest.approx(200.0, rel=0.05)
    assert last.servo_joints == joints and len(last.servo_ids) == len(joints)
    np.testing.assert_allclose(last.goals_deg, bus.goals[-1])
    assert last.positions_deg and all(p is not None for p in last.positions_deg)
    assert last.curve_names == POSE_NAMES and len(last.pose_deg) == len(POSE_NAMES)
    assert all(math.isfinite(v) for v in last.pose_deg)
    assert len(last.controls) == len(last.control_names) == len(parts.pipeline.expander.controls)
    np.testing.assert_allclose(last.raw, MID)
    assert last.glove_connected and last.glove_frames_ok == glove.n
    kinds = {o.kind: o for o in last.outputs}
    assert kinds["test"].frames_written == counter.frames > 0
    assert kinds["recorder"].path == str(tmp_path / "take.csv")
    assert isinstance(last.controls, tuple) and isinstance(last.goals_deg, tuple)


def test_each_control_is_shown_with_its_own_channels_count() -> None:
    """A glove wired in another order than the map's controls (the glove file's
    ``[[channels]] index``): each control's raw count is its own channel's."""
    from handrig.app.parts import build_parts, control_channels

    parts = build_parts()
    controls = parts.pipeline.expander.controls
    cfg = parts.glove_config
    n = len(cfg.channels)
    wired = dataclasses.replace(cfg, channels=tuple(  # channel k now on raw input n-1-k
        dataclasses.replace(ch, index=n - 1 - ch.raw_index()) for ch in cfg.channels))
    channels = control_channels(wired, controls)
    assert sorted(channels) == list(range(n)) and channels != tuple(range(n))
    assert control_channels(cfg, controls) == tuple(range(n))  # the shipped glove: in order
    # a control this glove does not drive: -1, its count shown as missing
    assert control_channels(cfg, (*controls, "riRingMCPy")) == (*range(n), -1)
    clock = FakeClock(10.0)
    raw = np.arange(1000.0, 1000.0 + 100 * n, 100.0)  # each input's own count
    glove = ScriptedGlove(clock, lambda t: raw)
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, raw_channels=channels)
    rig.run(frames=20)
    last = rig.telemetry.latest()
    assert last is not None
    np.testing.assert_allclose(last.raw, raw[list(channels)])
    plain = make_rig(parts, ScriptedGlove(clock, lambda t: raw), bus, clock)
    plain.run(frames=20)
    snap = plain.telemetry.latest()
    assert snap is not None
    np.testing.assert_allclose(snap.raw, raw)  # no wiring given: the glove's own order
    unwired = make_rig(parts, ScriptedGlove(clock, lambda t: raw), bus, clock,
                       raw_channels=(*channels[:-1], -1))
    unwired.run(frames=20)
    u = unwired.telemetry.latest()
    assert u is not None and math.isnan(u.raw[-1])
    np.testing.assert_allclose(u.raw[:-1], raw[list(channels[:-1])])


def test_two_hands_each_loop_shows_its_own_gloves_channels(tmp_path: Path) -> None:
    """In a two-hand rig each loop's controls are both hands'; its glove drives its
    own hand's only (a left glove may be calibrated with the right's curve names)."""
    from handrig.app.hands import build_session_parts, side_control_channels
    from handrig.config.loading import CONFIG_DIR

    text = (CONFIG_DIR / "glove.toml").read_text()
    left = tmp_path / "left_glove.toml"  # the right glove's file, its inputs reversed
    left.write_text(re.sub(r"(?m)^index = (\d)", lambda m: f"index = {4 - int(m[1])}", text))
    two = build_session_parts("puppet_two_hands", left_glove_file=left, glove_per_hand=True)
    right, lefts = (side_control_channels(side) for side in two.hands)
    assert right == (0, 1, 2, 3, 4, -1, -1, -1, -1, -1)
    assert lefts == (-1, -1, -1, -1, -1, 4, 3, 2, 1, 0)
