"""Layers on fakes, deterministic (issue 40): :class:`LayerControl` hands a take to each
hand's loop (a glove per hand: each loop's own servos), the goals written follow it and
the other servos the glove, and the panel, its plain line, the live view's frame and
the telemetry show the layers. A fake clock, a steady glove and a fake bus (subclasses
of the real ABCs); no emulator."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from handrig import hand
from handrig.app.hands import build_session_parts
from handrig.app.layering import LayerControl
from handrig.app.panel import PanelSnapshot, plain_line, render
from handrig.app.parts import RigParts
from handrig.app.rig_snapshot import RigSnapshot
from handrig.app.view.encode import FrameEncoder, HandsSnapshot
from handrig.clock import FakeClock
from handrig.devices.glove import GloveSample, GloveSource, GloveStats
from handrig.errors import ConfigError
from handrig.loop.rig import Rig
from handrig.outputs.recorder import csv_header
from tests.helpers.fakes import FakeBus
from tests.helpers.loop import make_rig

TAKE_DEG = 30.0


class SteadyGlove(GloveSource):
    """The same sample every cycle, stamped now."""

    def __init__(self, clock: FakeClock) -> None:
        super().__init__()
        self.clock, self.n = clock, 0

    def latest(self) -> GloveSample | None:
        self.n += 1
        raw = np.array([2000.0, 2100.0, 2000.0, 2100.0, 2100.0])
        return GloveSample(raw, np.array([0.0, 0.0, 0.0, 1.0]), 0, False, self.n, 0,
                           self.clock.now(), self.n)

    def stats(self) -> GloveStats:
        return GloveStats(frames_ok=self.n)


@pytest.fixture(scope="module")
def take(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A performance holding every curve at TAKE_DEG for 2 s."""
    path = tmp_path_factory.mktemp("take") / "still.csv"
    rows = [[t, *([TAKE_DEG] * len(hand.CURVE_NAMES))] for t in (0.0, 1.0, 2.0)]
    path.write_text(",".join(csv_header(False)) + "\n"
                    + "\n".join(",".join(f"{v:g}" for v in row) for row in rows) + "\n")
    return path


def _run(hands: list[RigParts], control: LayerControl | None, frames: int = 300
         ) -> tuple[list[Rig], list[np.ndarray]]:
    """Each hand's loop on fakes for ``frames`` cycles; the goals each bus got last."""
    rigs, buses = [], []
    for side in hands:
        clock = FakeClock()
        bus = FakeBus(tuple(side.pipeline.servo_joints), clock)
        rigs.append(make_rig(side, SteadyGlove(clock), bus, clock))
        buses.append(bus)
    if control is not None:
        control.connect(rigs)
    for rig in rigs:
        rig.run(frames=frames)
    return rigs, [np.asarray(bus.goals[-1 - 120]) for bus in buses]  # before the relax


def test_a_layer_on_the_left_hand_of_a_glove_per_hand_rig_moves_the_left_loop_only(
        take: Path) -> None:
    # fresh parts for each run: a hand's parts keep state from a run (its filter's)
    _, live = _run(list(build_session_parts("puppet_two_hands", glove_per_hand=True).hands),
                   None)
    hands = list(build_session_parts("puppet_two_hands", glove_per_hand=True).hands)
    control = LayerControl([side.pipeline for side in hands], {"still": str(take)})
    control.layer("still", "left.index")
    with pytest.raises(ConfigError, match="unknown take"):
        control.layer("nope", "left")
    rigs, layered = _run(hands, control)
    left = hands[1]
    np.testing.assert_array_equal(layered[0], live[0])  # the right hand's loop: untouched
    for k, joint in enumerate(left.pipeline.servo_joints):
        if joint.startswith("leIndex"):
            want = np.clip(TAKE_DEG, left.pipeline.servo_low[k], left.pipeline.servo_high[k])
            assert layered[1][k] == pytest.approx(want), joint
            assert abs(live[1][k] - want) > 1.0, joint  # the glove's was elsewhere
        else:
            assert layered[1][k] == pytest.approx(live[1][k]), joint
    # the panel, its plain line, the view's frame: the layer, its take, group and state
    status = control.status()
    assert [(s.take, s.group, s.loop) for s in status] == [("still", "left.index", True)]
    snap = RigSnapshot(rigs[1])()
    assert snap.layers == ("left.index <- still (loop, on)",)
    console = Console(width=80, height=24, record=True, file=io.StringIO(), force_terminal=True)
    console.print(render(snap, 24))
    screen = console.export_text()
    assert "layers left.index <- still (loop, on)" in screen and "keys off" in screen
    assert "layers left.index <- still (loop, on)" in plain_line(snap)
    assert "layers" not in plain_line(PanelSnapshot())
    latest = rigs[1].telemetry.latest()
    assert latest is not None
    frame = FrameEncoder({}, {}).frame(HandsSnapshot({"le": latest}))
    assert '"layers":["left.index <- still (loop, on)"]' in frame


def test_off_fades_a_layer_out_and_the_glove_has_the_joint_again(take: Path) -> None:
    _, live = _run([build_session_parts("puppet_two_hands").hands[0]], None)
    side = build_session_parts("puppet_two_hands").hands[0]
    control = LayerControl([side.pipeline], {"still": str(take)})
    control.layer("still", "right.thumb")
    control.layer("still", "off")  # taken in the same cycle: on, then fading out
    rigs, layered = _run([side], control)
    np.testing.assert_allclose(layered[0], live[0])
    assert rigs[0].cycle.layers.active == 0 and control.status() == ()
    events = rigs[0].stats.events
    assert any("right.thumb <- still" in e and "ended" in e for e in events), events
