"""The panel says the OpenXR hand joints are going out (and their send errors), within
80 columns, and the plain line names their target; the snapshot reads the output's
status alone."""

from __future__ import annotations

from handrig.app.panel import plain_line
from handrig.app.parts import build_parts
from handrig.app.rig_snapshot import RigSnapshot
from handrig.clock import FakeClock
from handrig.outputs.base import PanelCell
from handrig.outputs.openxr import OpenXrSender
from tests.handrig.app.test_panel import (
    REC_CELL,
    VMC_CELL,
    SteadyGlove,
    screen,
    show_snapshot,
    warm_bus,
)
from tests.helpers.loop import make_rig


def test_openxr_on_the_outputs_line_within_80_columns() -> None:
    xr = PanelCell("XR", "127.0.0.1:39540", errors=3)
    glove = PanelCell("glove", "/shows/glove1.csv", frames=40200)
    outputs = (VMC_CELL, xr, REC_CELL, glove)
    lines = screen(show_snapshot(outputs=outputs))
    assert max(len(line) for line in lines) <= 80
    out = next(line for line in lines if line.startswith("out"))
    assert out.startswith("out    VMC 127.0.0.1:39539 60 Hz  |  XR 3 err  |  rec")
    plain = plain_line(show_snapshot(outputs=outputs))
    assert "XR 127.0.0.1:39540 3 errors" in plain
    out = next(line for line in screen(show_snapshot(outputs=(xr,))) if line.startswith("out"))
    assert out.rstrip() == "out    XR 127.0.0.1:39540 3 err"
    off = next(line for line in screen(show_snapshot()) if line.startswith("out"))
    assert "XR" not in off and "XR" not in plain_line(show_snapshot())


def test_the_snapshot_of_a_running_rig_shows_its_openxr_output() -> None:
    parts = build_parts()
    clock = FakeClock()
    bus = warm_bus(tuple(parts.pipeline.servo_joints), clock)
    with OpenXrSender("127.0.0.1", 9, clock=clock) as xr:
        rig = make_rig(parts, SteadyGlove(clock), bus, clock, outputs=(xr,))
        rig.run(frames=100)
        assert xr.status().frames_written > 0
        snap = RigSnapshot(rig)()
    assert [c.target for c in snap.outputs if c.label == "XR"] == ["127.0.0.1:9"]
    out = next(line for line in screen(snap) if line.startswith("out"))
    assert out.startswith("out    XR 127.0.0.1:9")
