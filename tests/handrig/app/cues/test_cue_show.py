"""What a cue looks like to the show: the mode machine's explicit relax and resume (a
cue never toggles the wrong way), the panel's cues line, the ``r`` key, the view's frame."""

from __future__ import annotations

import io
import json
import os

from rich.console import Console

from handrig.app.cues.dispatch import Cue
from handrig.app.cues.live import CueOptions, LiveCues
from handrig.app.hands import AllHands
from handrig.app.keys import SHOW_KEYS, KeyReader
from handrig.app.panel import PanelSnapshot, plain_line, render
from handrig.app.rig_snapshot import HandsSnapshot
from handrig.app.view.encode import FrameEncoder
from handrig.app.view.encode import HandsSnapshot as ViewHands
from handrig.clock import FakeClock
from handrig.loop.modes import Mode, ModeMachine


def _machine() -> tuple[ModeMachine, list[str]]:
    said: list[str] = []
    m = ModeMachine(glove_timeout_s=0.25, relax_time_s=1.0, event=said.append)
    m.start(0.0)
    m.frame(0.0, False)
    return m, said


def test_relax_and_resume_by_cue_are_requests_not_toggles() -> None:
    m, said = _machine()
    m.request_relax("relax (OSC)")
    m.request_relax("relax (MIDI)")  # a second relax keeps it relaxed
    m.poll()
    assert m.held and m.mode is Mode.RELAXING
    assert said[-2].startswith("relax (OSC): relaxed until")
    assert said[-1] == "relax (MIDI): held relaxed already"
    m.request_resume("resume (OSC)")
    m.request_resume("resume (OSC)")
    m.poll()
    assert not m.held and said[-2].startswith("resume (OSC): resuming")
    assert said[-1] == "resume (OSC): not held relaxed, nothing to resume"
    m.toggle_relax()  # the key still toggles
    m.poll()
    assert m.held


def test_the_panel_lists_the_last_cues_newest_first_within_80_columns() -> None:
    cues = ("relax (OSC)", "record/start act1 (MIDI): recording takes/act1.csv", "stop (OSC)")
    snap = PanelSnapshot(cues=cues)
    console = Console(width=80, height=24, record=True, file=io.StringIO(),
                      force_terminal=True)
    console.print(render(snap))
    lines = console.export_text().splitlines()
    line = next(x for x in lines if x.startswith("cues"))
    assert len(line) <= 80 and line.index("stop (OSC)") < line.index("record/start act1")
    assert "cues stop (OSC) < record/start" in plain_line(snap)
    console = Console(width=80, height=24, record=True, file=io.StringIO(),
                      force_terminal=True)
    console.print(render(PanelSnapshot()))
    assert not any(x.startswith("cues") for x in console.export_text().splitlines())
    assert "cues" not in plain_line(PanelSnapshot())


def test_the_panel_snapshot_takes_the_cues_from_the_session() -> None:
    first = PanelSnapshot(mode="running")
    snap = HandsSnapshot({"": lambda: first}, cues=lambda: ("estop (OSC)",))  # type: ignore[dict-item]
    assert snap().cues == ("estop (OSC)",) and snap().mode == "running"


def test_r_starts_a_take_and_stops_it_and_the_view_and_panel_see_it(tmp_path) -> None:
    assert "r" in SHOW_KEYS
    hands = AllHands([])
    cues = LiveCues(CueOptions(takes=str(tmp_path)), hands, FakeClock(), 100.0,
                    log=lambda text: None)
    r, w = os.pipe()
    try:
        keys = KeyReader.for_show(r, toggle_relax=lambda: None, stop=lambda: None,
                                  estop=lambda: None, record=cues.record_key)
        os.write(w, b"r")
        assert keys.poll(1.0) == 1 and cues.takes.recording.startswith(str(tmp_path))
        os.write(w, b"r")
        assert keys.poll(1.0) == 1 and cues.takes.recording == ""
    finally:
        os.close(r)
        os.close(w)
        cues.close()
    recent = hands.recent_cues()
    assert recent[0].startswith("record/start (key): recording")
    assert recent[1].startswith("record/stop (key): take")
    s = cues.summary()
    assert cues.used and s["by_source"] == {"key": 2} and len(s["takes"]["done"]) == 1
    cues.dispatcher.dispatch(Cue("relax", (), "OSC"))  # no hands: still a cue taken


def test_the_view_frame_carries_the_cues() -> None:
    from handrig.loop.telemetry import LoopSnapshot
    from handrig.pose.pipeline import POSE_NAMES

    one = LoopSnapshot(
        t_s=1.0, seq=3, mode="running", mode_reason="", rate_hz=200.0, latency_p50_us=150.0,
        latency_p99_us=200.0, frames_lost=0, cycles=400, overruns=0, controls=(0.5,),
        raw=(2000.0,), control_names=("riIndexMCPy",), inclination_deg=0.0, rotation_deg=0.0,
        glove_connected=True, pose_deg=(10.0,) * len(POSE_NAMES), curve_names=POSE_NAMES,
        servo_ids=(1,), servo_joints=("riIndexMCPy",), goals_deg=(0.0,), positions_deg=(None,),
        temperatures_c=(31.0,), hardware_errors=(0,), stale=(False,), outputs=())
    encoder = FrameEncoder({}, {})
    frame = json.loads(encoder.frame(ViewHands({"": one}, ("relax (OSC)", "stop (MIDI)"))))
    assert frame["cues"] == ["relax (OSC)", "stop (MIDI)"]
    assert json.loads(encoder.frame(one))["cues"] == []


def test_the_printed_summary_has_the_cues_part() -> None:
    from handrig.app.summary import format_summary, summary_dict
    from handrig.loop.stats import RunStats

    log_cues = LiveCues(CueOptions(), AllHands([]), FakeClock(), 100.0, log=lambda t: None)
    for _ in range(14):
        log_cues.dispatcher.dispatch(Cue("relax", (), "OSC"))
    log_cues.log.count("received", "OSC", 15)
    log_cues.log.count("malformed", "OSC")
    summary = summary_dict(RunStats(), None, None, None)
    summary["cues"] = log_cues.summary()
    text = format_summary(summary)
    assert "cues              15 received (OSC 15): 14 acted, 0 refused; ignored 0 unknown, " \
           "1 malformed, 0 unmapped" in text
    assert text.count("relax (OSC)") == 12 and "... 2 more" in text
    assert "cues" not in format_summary(summary_dict(RunStats(), None, None, None))


def test_layers_attached_after_the_cues_are_built_get_play_and_layer() -> None:
    calls: list[tuple[str, ...]] = []
    cues = LiveCues(CueOptions(), AllHands([]), FakeClock(), 100.0, log=lambda t: None)
    cues.dispatcher.dispatch(Cue("play", ("intro",)))  # no layers yet: refused
    cues.attach_layers(lambda name: calls.append(("play", name)),
                       lambda name, group: calls.append(("layer", name, group)))
    cues.dispatcher.dispatch(Cue("play", ("intro",), "MIDI"))
    cues.dispatcher.dispatch(Cue("layer", ("intro", "off")))
    assert calls == [("play", "intro"), ("layer", "intro", "off")]
    assert cues.log.counts["refused"] == 1 and cues.log.counts["acted"] == 2
