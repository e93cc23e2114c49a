"""Cues on a live run: ``handrig run --bus sim --osc-in 0`` driven by a UDP client sending
every address (the summary's events and counts, the stop reason, the take on disk,
torque off), and a MIDI input on a virtual port where this machine has a sequencer."""

from __future__ import annotations

import json
import queue
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from handrig.app.cues.osc import encode_bundle, encode_message
from handrig.outputs.recorder import load_performance
from sim.demo_recording import DEMO_RECORDING

CLI = [sys.executable, "-m", "handrig.cli"]
WAIT_S = 30.0


class Lines:
    """A process's stderr, read line by line in a thread; :meth:`wait` for one."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.seen: list[str] = []
        self._q: queue.Queue[str] = queue.Queue()
        assert proc.stderr is not None
        stream = proc.stderr
        threading.Thread(target=lambda: [self._q.put(line) for line in stream],
                         daemon=True).start()

    def wait(self, test: Callable[[str], bool], what: str) -> str:
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            try:
                line = self._q.get(timeout=0.1)
            except queue.Empty:
                continue
            self.seen.append(line)
            if test(line):
                return line
        raise AssertionError(f"no line with {what}; stderr so far:\n{''.join(self.seen)}")


def test_every_osc_address_on_a_live_run(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", "sim", "--json",
         "--osc-in", "0", "--cue-takes", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        lines = Lines(proc)
        port = int(lines.wait(lambda s: s.startswith("cues: OSC on"), "the OSC port")
                   .split(":")[2].split()[0])
        lines.wait(lambda s: s.startswith("first frame"), "the first frame")

        def cue(data: bytes, expect: str) -> str:
            client.sendto(data, ("127.0.0.1", port))
            return lines.wait(lambda s: expect in s, repr(expect))

        cue(encode_message("/handrig/relax"), "relax (OSC): relaxed until")
        cue(encode_message("/handrig/resume"), "resume (OSC): resuming")
        cue(encode_message("/handrig/record/start", "act1"), "recording")
        partial = tmp_path / "act1.csv.partial"
        deadline = time.monotonic() + WAIT_S
        while partial.stat().st_size < 4000 and time.monotonic() < deadline:
            time.sleep(0.05)  # until the take holds frames (written every 0.5 s)
        cue(encode_message("/handrig/record/stop"), "closed")
        cue(encode_message("/handrig/record/start", "act1"), "never replaced")
        cue(encode_message("/handrig/nope", 1), "unknown: /handrig/nope")
        cue(b"not osc!", "malformed: 1 message")
        cue(encode_message("/handrig/layer", "intro"), "malformed: /handrig/layer intro")
        cue(encode_bundle(encode_message("/handrig/play", "intro"), b"junk"), "malformed")
        lines.wait(lambda s: "play intro (OSC) refused" in s, "play refused")
        client.sendto(encode_message("/handrig/stop"), ("127.0.0.1", port))
        out, _ = proc.communicate(timeout=WAIT_S)
    finally:
        client.close()
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, "".join(lines.seen)
    s = json.loads(out)
    assert s["stop_reason"] == "stop (OSC)" and s["torque_off"] is True
    assert any(e.startswith("relax (OSC): relaxed until") for e in s["events"])
    assert any(e.startswith("resume (OSC): resuming") for e in s["events"])
    cues = s["cues"]
    assert (cues["unknown"], cues["malformed"], cues["refused"]) == (1, 3, 2)
    assert cues["acted"] == 5 and cues["received"] == 11 and cues["by_source"] == {"OSC": 11}
    events = "\n".join(cues["events"])
    for said in ("relax (OSC)", "resume (OSC)", "record/start act1 (OSC): recording",
                 "record/stop (OSC): take", "refused: ", "play intro (OSC) refused",
                 "stop (OSC)"):
        assert said in events
    take = tmp_path / "act1.csv"
    t_s, poses, _ = load_performance(take)
    assert len(t_s) > 50 and t_s[0] == 0.0 and poses.shape[1] == 50
    assert not (tmp_path / "act1-2.csv").exists()
    takes = cues["takes"]
    assert takes["recording"] == "" and takes["done"][0]["path"] == str(take)
    assert s["outputs"] == {"vmc": None, "recording": None}  # the cue takes are in cues


def test_the_relay_process_hands_over_cues_and_counts_the_rest() -> None:
    from handrig.app.cues.dispatch import CueDispatcher, CueLog, CueTargets
    from handrig.app.cues.receiver import OscReceiver
    from handrig.clock import MonotonicClock

    calls: list[str] = []
    targets = CueTargets(relax=calls.append, resume=calls.append, stop=calls.append,
                         estop=calls.append, record_start=lambda name: "",
                         record_stop=lambda: "")
    log = CueLog(MonotonicClock())
    lines: list[str] = []
    port = OscReceiver("127.0.0.1", 0, CueDispatcher(targets, log, on_event=lines.append))
    port.start()
    assert port.ready.wait(WAIT_S)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as client:
        for k in range(300):
            client.sendto(encode_message("/handrig/level", 0.5), ("127.0.0.1", port.port))
            if k % 20 == 19:
                time.sleep(0.002)  # within the socket's buffer
        client.sendto(encode_message("/handrig/relax"), ("127.0.0.1", port.port))
        deadline = time.monotonic() + WAIT_S
        while not calls and time.monotonic() < deadline:
            time.sleep(0.01)
    port.close()  # the relay's last counts read before it returns
    assert calls == ["relax (OSC)"]
    assert (log.counts["received"], log.counts["unknown"], log.counts["acted"]) == (301, 300, 1)
    assert len(lines) == 6 and "counted only" in lines[4]


def _virtual_midi() -> str:
    """Why a virtual MIDI port cannot be made here ("" when it can)."""
    try:
        import rtmidi

        port = rtmidi.MidiOut()
        port.open_virtual_port("handrig-probe")
        port.close_port()
    except Exception as exc:  # rtmidi raises its own SystemError without a sequencer
        return f"no virtual MIDI port on this machine ({exc}): no ALSA sequencer " \
               "(/dev/snd/seq); the mapping is tested on mido messages in test_cue_parsing"
    return ""


def test_a_midi_note_stops_a_live_run(tmp_path: Path) -> None:
    why = _virtual_midi()
    if why:
        pytest.skip(why)
    import mido

    show = tmp_path / "show.toml"
    show.write_text(f'[show]\nrig = "puppet"\n[gloves]\nright = "replay:{DEMO_RECORDING}"\n'
                    '[buses]\nright = "sim"\n[midi]\nport = "virtual:handrig-cues"\n'
                    'note.60 = "relax"\ncc.20 = "stop"\n')
    proc = subprocess.Popen([*CLI, "run", "--show", str(show), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = Lines(proc)
        lines.wait(lambda s: s.startswith("first frame"), "the first frame")
        with mido.open_output("handrig-cues") as out_port:
            out_port.send(mido.Message("note_on", note=60, velocity=100))
            lines.wait(lambda s: "relax (MIDI)" in s, "relax (MIDI)")
            out_port.send(mido.Message("note_on", note=61, velocity=100))
            out_port.send(mido.Message("control_change", control=20, value=127))
        out, _ = proc.communicate(timeout=WAIT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    s = json.loads(out)
    assert s["stop_reason"] == "stop (MIDI)" and s["torque_off"] is True
    assert s["cues"]["unmapped"] == 1 and s["cues"]["by_source"] == {"MIDI": 3}
