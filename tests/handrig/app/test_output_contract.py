"""An output owns what the panel and the run summary say of it (issue 35): a kind that
nothing in ``app/`` knows, defined here, shows on the panel of a running rig (with its
rate) and in the summary's text, through ``OutputStatus.cell`` and ``Output.summary``
alone; and the panel, its snapshot and the summary name no output kind."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any

from handrig.app.panel import PanelSnapshot, plain_line
from handrig.app.parts import build_parts
from handrig.app.rig_snapshot import HandsSnapshot, RigSnapshot
from handrig.app.summary import format_summary, outputs_summary, summary_dict
from handrig.clock import FakeClock
from handrig.devices.servo.bus import BusStats
from handrig.loop.stats import RunStats
from handrig.outputs.base import FloatArray, Output, OutputStatus, PanelCell
from tests.handrig.app.test_panel import SteadyGlove, screen, warm_bus
from tests.helpers.loop import make_rig

ROOT = Path(__file__).resolve().parents[3]


class BeaconStatus(OutputStatus):
    def cell(self) -> PanelCell:
        return PanelCell("BCN", self.address, rate=True, frames=self.frames_written)


class Beacon(Output):
    """A new kind of output: it counts the poses it was handed."""

    def __init__(self) -> None:
        self.poses = 0

    def __call__(self, t_s: float, pose_deg: FloatArray) -> None:
        self.poses += 1

    def status(self) -> OutputStatus:
        return BeaconStatus(kind="beacon", name="beacon", address="10.0.0.7:7000",
                            frames_written=self.poses)

    def summary(self, duration_s: float) -> tuple[str, dict[str, Any]]:
        return "beacon", {"poses": self.poses, "said": f"beacon lit {self.poses} times"}


class Plain(Output):
    """A new kind that says nothing of itself: the default cell and summary line."""

    def __call__(self, t_s: float, pose_deg: FloatArray) -> None:
        pass

    def status(self) -> OutputStatus:
        return OutputStatus(kind="plain", name="plain", path="/tmp/plain.out", errors=2,
                            stopped_reason="stopped: no room")


def test_a_new_output_shows_on_the_panel_and_in_the_summary_by_its_contract() -> None:
    parts = build_parts()
    clock = FakeClock()
    bus = warm_bus(tuple(parts.pipeline.servo_joints), clock)
    beacon, plain = Beacon(), Plain()
    rig = make_rig(parts, SteadyGlove(clock), bus, clock, outputs=(beacon, plain))
    snapshot = RigSnapshot(rig)
    rig.run(frames=100)
    first = rig.telemetry.latest()
    assert first is not None and snapshot().outputs[0].label == "BCN"
    beacon.poses += 50  # half a second later: the rate over the last snapshots
    rig.telemetry.publish(dataclasses.replace(
        first, t_s=first.t_s + 0.5, outputs=(beacon.status(), plain.status())))
    snap = snapshot()
    cell = next(c for c in snap.outputs if c.label == "BCN")
    assert cell.target == "10.0.0.7:7000" and cell.frames == beacon.poses > 100
    assert cell.rate_hz == 100.0
    out = next(line for line in screen(snap) if line.startswith("out"))
    assert out.startswith(f"out    BCN 10.0.0.7:7000 100 Hz {beacon.poses}  |  plain")
    assert "plain" in out and "2 err" in out and len(out) <= 80
    assert "plain /tmp/plain.out 2 errors stopped: no room" in plain_line(snap)

    outputs = outputs_summary([beacon, plain], duration_s=1.0)
    assert outputs["beacon"] == {"poses": beacon.poses, "said": f"beacon lit {beacon.poses} times"}
    text = format_summary(summary_dict(RunStats(), BusStats(20), None, True, outputs=outputs))
    assert f"outputs           beacon lit {beacon.poses} times" in text
    assert "                  plain /tmp/plain.out: 0 frames, 2 errors (stopped: no room)" in text


def test_the_panel_and_the_summary_name_no_output_kind() -> None:
    """A branch on a kind is a kind's string (``out.kind == "vmc"``, ``get("recording")``)
    or a look at ``.kind``: none in the modules that show every output."""
    kinds = re.compile(r"[\"'](vmc|recorder|recording|openxr|glove[ _]take|timecode)[\"']"
                       r"|\.kind\b", re.IGNORECASE)
    found = [f"{rel}:{n}: {line.strip()}"
             for rel in ("handrig/app/rig_snapshot.py", "handrig/app/panel.py",
                         "handrig/app/summary.py")
             for n, line in enumerate((ROOT / rel).read_text().splitlines(), start=1)
             if kinds.search(line)]
    assert not found, "\n".join(found)


class Fixed(RigSnapshot):
    """A hand's panel as given (its rig not needed)."""

    def __init__(self, snap: PanelSnapshot) -> None:
        self.snap = snap

    def __call__(self) -> PanelSnapshot:
        return self.snap


def test_every_hands_outputs_show_on_the_panel_of_several_hands() -> None:
    """The shared outputs run on the first hand's loop, each hand's glove take on its own:
    the panel of two hands shows them all."""
    right = PanelSnapshot(outputs=(PanelCell("VMC", "127.0.0.1:39539", rate=True),
                                   PanelCell("glove", "/t/right.csv", frames=10)))
    left = PanelSnapshot(outputs=(PanelCell("glove", "/t/left.csv", frames=20),))
    snap = HandsSnapshot({"ri": Fixed(right), "le": Fixed(left)})()
    assert [(c.label, c.target) for c in snap.outputs] == [
        ("VMC", "127.0.0.1:39539"), ("glove", "/t/right.csv"), ("glove", "/t/left.csv")]
    assert "glove /t/right.csv 10 | glove /t/left.csv 20" in plain_line(snap)
