"""Takes keep time on the live rig: gloves at 100 and 500 Hz on a pty drive the
glove-triggered loop and the emulated bus for 3.5 s (plus the 1 s ease to relaxed), with
a 1 s glove silence in the middle, recorded to CSV and BVH at once. Each take lasts as
long as the run did (from its first frame to its end) within one frame, the BVH holds
what the CSV says was sent at each of its frame times, and an outside BVH reader agrees.

"The run" is the cycles' own times, the clock read at each tick's start, which the loop
hands its outputs: the take must hold exactly those. They are checked against the clock
the outputs live on (never ahead of it; the run they span lasts 3.5 s and the ease), not
against the clock read inside the output call, which a loaded host delays by a few
milliseconds more at one end of the run than at the other."""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path

import bvh as outside_bvh
import numpy as np
import pytest

from handrig.app import factory as app
from handrig.app import parts as app_parts
from handrig.clock import MonotonicClock
from handrig.devices.glove_recording import read_glove_recording
from handrig.outputs.recorder import Recorder, load_performance
from sim.demo_recording import DEMO_RECORDING
from sim.glove_emulator import GloveEmulator

# 3.5 s: a second of frames before the silence, its second, 1.5 s after it to resume in;
# each check below is on every frame of the run, whatever its length
RUN_S = 3.5
SILENCE_AT_S, SILENCE_S = 1.0, 1.0


def _record_a_run(glove_hz: float, folder: Path
                  ) -> tuple[float, np.ndarray, np.ndarray, Path, Path, list[str]]:
    """Run the rig on a glove at ``glove_hz`` with a silence; returns the run's duration
    (s, its clock), the times the loop handed its outputs with each frame (s from the
    run's start), the clock times at which the outputs were called (s, the same origin),
    the CSV and BVH takes, and what the rig logged."""
    parts = app_parts.build_parts()
    clock = MonotonicClock()
    events: list[str] = []
    csv_path, bvh_path = folder / f"take{glove_hz:g}.csv", folder / f"take{glove_hz:g}.bvh"
    rec = read_glove_recording(DEMO_RECORDING)
    with GloveEmulator(rec, "frames", rate_hz=glove_hz, loop=True) as emu, \
            contextlib.ExitStack() as stack:
        opened = stack.enter_context(app.servo_bus("sim", parts, clock, log=events.append))
        glove = app.open_glove(emu.port_path, parts.glove_config, clock)
        stack.enter_context(glove)
        opened.bus.connect()
        csv = Recorder(csv_path, rate_hz=glove_hz)
        bvh = Recorder(bvh_path, rate_hz=glove_hz)
        given: list[float] = []  # the time the loop handed along with each frame
        handed: list[float] = []  # when each frame reached the outputs, on the clock

        def probe(t_s: float, pose: np.ndarray) -> None:
            handed.append(clock.now())
            given.append(t_s)

        rig = app.build_rig(parts, glove, opened.bus, clock, outputs=[csv, bvh, probe],
                            log=events.append)

        def silence() -> None:
            time.sleep(SILENCE_AT_S)
            emu.pause()
            time.sleep(SILENCE_S)
            emu.resume()

        rig.prepare()
        with opened.bus.torque(handle_signals=False):
            script = threading.Thread(target=silence)
            script.start()
            stats = rig.run(duration_s=RUN_S)
            script.join()
        csv.close()
        bvh.close()
    t0 = rig.cycle.t0_s  # the run's start on the clock: the origin of the times handed
    return (stats.duration_s, np.array(given), np.array(handed) - t0, csv_path, bvh_path,
            events)


# a slow glove and a fast one (200 Hz, the usual rate, lies between them; test_takes.py
# and the live runs record at it)
@pytest.mark.parametrize("glove_hz", [100.0, 500.0])
def test_takes_last_as_long_as_the_run_at_any_glove_rate(tmp_path: Path,
                                                          glove_hz: float) -> None:
    run_s, given, handed, csv_path, bvh_path, events = _record_a_run(glove_hz, tmp_path)
    frame_s = 1.0 / glove_hz
    t, poses, _ = load_performance(csv_path)
    tb, pb, _ = load_performance(bvh_path)
    assert any("silent or garbled" in e for e in events)  # the silence happened
    assert RUN_S + 0.9 <= run_s <= RUN_S + 1.5  # the run and the 1 s ease to relaxed
    assert 0.0 <= t[0] <= 0.5 and len(given) == len(t)
    # the times handed along are the clock's: none later than the call that got it (an
    # output's time made up from a frame count or the glove's rate would not be)
    assert np.all(given <= handed), float(np.max(given - handed))
    # the run the outputs were handed, a frame each: RUN_S and the 1 s ease from the first
    # frame on (later on a loaded machine: a host stall near the end lengthens the run,
    # and the take with it; a run that lost the silence would be 1 s short)
    run_from_first_s = given[-1] - given[0] + frame_s
    assert -0.05 <= run_from_first_s - (RUN_S + 1.0 - t[0]) <= 0.5
    csv_s = t[-1] - t[0] + frame_s
    bvh_s = len(tb) * frame_s
    print(f"{glove_hz:g} Hz glove: run {run_from_first_s:.4f} s from its first frame,"
          f" CSV {csv_s:.4f} s ({len(t)} rows), BVH {bvh_s:.4f} s ({len(tb)} frames);"
          f" outputs called {1e3 * np.median(handed - given):.2f} ms after their tick"
          f" (median), {1e3 * np.max(handed - given):.2f} ms at most")
    # the CSV holds each frame at the time the loop gave it (6 decimals), so it lasts
    # as long as the run; the BVH, evenly spaced from the first frame, ends with the
    # frame whose time slot holds the run's last frame: within one frame after it
    assert np.allclose(t, given, rtol=0.0, atol=1e-6), float(np.max(np.abs(t - given)))
    assert abs(csv_s - run_from_first_s) <= 2e-6
    assert 0.0 < bvh_s - (given[-1] - given[0]) <= frame_s + 1e-5, bvh_s - run_from_first_s
    # the silence is in both: the CSV has no second-long gap it made up or dropped,
    # its times cover the silence, and each BVH frame is the newest CSV row at its time
    assert np.all(np.diff(t) >= 0)
    covered = (t > SILENCE_AT_S + 0.1) & (t < SILENCE_AT_S + SILENCE_S - 0.1)
    assert covered.sum() > 0 or np.max(np.diff(t)) >= SILENCE_S - 0.2
    # (the CSV's times have 6 decimals: a row within 2 us of a frame's boundary may
    # belong to either side)
    due = t[0] + tb + 0.5 * frame_s
    lo = np.searchsorted(t, due - 2e-6, side="right") - 1
    hi = np.searchsorted(t, due + 2e-6, side="right") - 1
    near = np.isclose(pb, poses[lo], atol=1e-4).all(axis=1) | (
        np.isclose(pb, poses[hi], atol=1e-4).all(axis=1))
    assert near.all(), f"BVH frames {np.flatnonzero(~near)[:5]} hold no CSV row near them"
    with open(bvh_path) as f:
        outside = outside_bvh.Bvh(f.read())
    assert outside.nframes == len(tb)
    assert outside.frame_time == pytest.approx(frame_s)
