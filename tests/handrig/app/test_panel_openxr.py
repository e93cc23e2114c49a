"""The panel says the OpenXR hand joints are going out (and their send errors), within
80 columns, and the plain line names their target; the snapshot reads the output's
status alone."""

from __future__ import annotations

from handrig.app.panel import Outputs, plain_line
from handrig.app.parts import build_parts
from handrig.app.rig_snapshot import RigSnapshot
from handrig.clock import FakeClock
from handrig.outputs.openxr import OpenXrSender
from tests.handrig.app.test_panel import SteadyGlove, screen, show_snapshot, warm_bus
from tests.helpers.loop import make_rig


def test_openxr_on_the_outputs_line_within_80_columns() -> None:
    outputs = Outputs("127.0.0.1:39539", 60.0, 0, "/shows/take1.bvh", 3_400_000, 201.0,
                      glove_take_path="/shows/glove1.csv", glove_take_frames=40200,
                      openxr_target="127.0.0.1:39540", openxr_errors=3)
    lines = screen(show_snapshot(outputs=outputs))
    assert max(len(line) for line in lines) <= 80
    out = next(line for line in lines if line.startswith("out"))
    assert out.startswith("out    VMC+XR 127.0.0.1:39539 60 Hz 3 err  |  rec")
    plain = plain_line(show_snapshot(outputs=outputs))
    assert "openxr 127.0.0.1:39540 3 errors" in plain
    alone = Outputs(openxr_target="127.0.0.1:39540")
    out = next(line for line in screen(show_snapshot(outputs=alone)) if line.startswith("out"))
    assert out.startswith("out    XR 127.0.0.1:39540  |  rec off")
    off = next(line for line in screen(show_snapshot()) if line.startswith("out"))
    assert "XR" not in off and "openxr" not in plain_line(show_snapshot())


def test_the_snapshot_of_a_running_rig_shows_its_openxr_output() -> None:
    parts = build_parts()
    clock = FakeClock()
    bus = warm_bus(tuple(parts.pipeline.servo_joints), clock)
    with OpenXrSender("127.0.0.1", 9, clock=clock) as xr:
        rig = make_rig(parts, SteadyGlove(clock), bus, clock, outputs=(xr,))
        rig.run(frames=100)
        assert xr.status().frames_written > 0
        snap = RigSnapshot(rig)()
    assert snap.outputs.openxr_target == "127.0.0.1:9"
    out = next(line for line in screen(snap) if line.startswith("out"))
    assert out.startswith("out    XR 127.0.0.1:9")
