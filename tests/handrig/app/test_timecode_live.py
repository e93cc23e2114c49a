"""Timecode on the live rig (issue 40), on real parts: LTC written into a WAV with a
known start, drift, jump and stop; ``run --ltc --record`` stamps every frame of the take
with it; ``play --chase-ltc`` plays a take locked to it onto the byte-level bus emulator,
the frame served every cycle within one frame of the true timecode."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.app.parts import build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.app.summary import format_summary
from handrig.app.takes import load_play_take, play_parts
from handrig.app.timecode import chase_setup
from handrig.cli import main
from handrig.config.rig import load_rig_config
from handrig.devices.glove_recording import sweep_recording, write_glove_recording
from handrig.devices.timecode.ltc import RATES, Timecode
from handrig.devices.timecode.ltc_encode import Segment, render, write_wav
from handrig.outputs.recorder import Recorder, load_performance
from handrig.outputs.timecode_stamp import read_stamps, stamp_path
from handrig.pose.pipeline import POSE_SIZE
from sim.dxl_bus import SimBus

FPS = RATES["25"]
SR = 48000


def ltc_wav(path: Path, segments: list[Segment]) -> list[tuple[float, float, int, float]]:
    """The WAV, and the truth: (from_s, to_s, first frame, frames a second) per stretch."""
    r = render(segments, SR)
    write_wav(path, r.samples, SR)
    truth, k = [], 0
    for seg in segments:
        if seg.start is None:
            continue
        t0 = float(r.starts_s[k])
        rate = FPS.rate_hz * seg.speed
        truth.append((t0, t0 + seg.frames / rate, seg.start.frame_number(25), rate))
        k += seg.frames
    return truth


def performance(path: Path, seconds: float = 3.0, rate_hz: float = 100.0) -> Path:
    """The right index MCP sweeping 0 -> 80 deg over the take."""
    index = hand.curve_index("riIndexMCPy")
    with Recorder(path, rate_hz=rate_hz, with_wrist=True, sync=False) as rec:
        for ti in np.arange(round(seconds * rate_hz)) / rate_hz:
            pose = np.zeros(POSE_SIZE)
            pose[index] = 80.0 * ti / seconds
            rec.add(float(ti), pose[:50], pose[50:])
    return path


def test_run_stamps_every_frame_of_the_take_with_the_timecode(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    wav = tmp_path / "ltc.wav"
    ltc_wav(wav, [Segment(Timecode(1, 0, 0, 0), 200, FPS, 1.001)])  # 8 s, 0.1 % fast
    glove = tmp_path / "glove.csv"
    write_glove_recording(glove, sweep_recording(3.0, 200.0, 5))
    take = tmp_path / "take.csv"
    with SimBus.from_rig(load_rig_config()) as sim:
        status = main(["run", "--glove", f"replay:{glove}", "--bus", sim.port_path,
                       "--seconds", "1", "--record", str(take), "--ltc", str(wav), "--json"])
        s = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert status == 0, s.get("error")
        # the stamps are a take too: never replaced, refused before the bus is touched
        goals = sim.stats.goals_decoded
        take.rename(tmp_path / "moved.csv")
        status = main(["run", "--glove", f"replay:{glove}", "--bus", sim.port_path,
                       "--seconds", "1", "--record", str(take), "--ltc", str(wav), "--json"])
        refused = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert status == 2 and "timecode.csv" in refused["error"]
        assert sim.stats.goals_decoded == goals and not take.exists()
    t_s, _, _ = load_performance(tmp_path / "moved.csv")
    stamps = read_stamps(stamp_path(take))
    assert stamps.fps == FPS
    # a stamp for every frame of the take, at the take's times
    assert np.allclose(stamps.t_s, t_s, atol=2e-6)
    ok = np.isfinite(stamps.frame)
    assert ok.mean() > 0.9 and ok[len(ok) // 10:].all()  # locked after the first frames
    # the timecode advanced with the take's time, at 25 fps (0.1 % fast), to a frame
    fit = stamps.frame[ok] - t_s[ok] * 25.025
    assert np.ptp(fit) < 1.0, np.ptp(fit)
    assert 90000 <= stamps.frame[ok][0] < 90000 + 30
    tl = s["outputs"]["timecode"]
    assert tl["frames_stamped"] == int(ok.sum()) and tl["jumps"] == 0
    said = format_summary(s)  # what a person reads at the end of the run
    assert f"timecode LTC {wav}: " in said and f"stamped in {stamp_path(take)}" in said


def test_play_chases_the_timecode_within_a_frame_through_start_jump_and_stop(
        tmp_path: Path) -> None:
    take = performance(tmp_path / "take.csv")
    wav = tmp_path / "ltc.wav"
    # the take starts at 01:00:00:10; the timecode runs from 00:59:58:15 (a pre-roll while
    # the rig commissions) 0.1 % fast, jumps to 01:00:02:00 (1.6 s into the take), stops
    truth = ltc_wav(wav, [Segment(Timecode(0, 59, 58, 15), 50, FPS, 1.001),
                          Segment(Timecode(1, 0, 2, 0), 15, FPS, 1.001),
                          Segment(None, silence_s=0.4)])
    rig = load_rig_config()
    parts = build_parts(None, None)
    played = load_play_take(take, parts.glove_config)
    parts = play_parts(parts, played)
    args = argparse.Namespace(speed=1.0, loop=False, chase_ltc=str(wav), ltc_fps=None,
                              chase_at="01:00:00:10")
    setup = chase_setup(args, played)
    with SimBus.from_rig(rig) as sim:
        result = run_live(parts, LiveOptions(
            glove=f"replay:{take}", take=setup.glove, timecode=setup.reader,
            bus=sim.port_path, duration_s=setup.duration_s, panel=False))
        outside = sim.stats.goals_outside
    assert result.error is None and result.summary["torque_off"] is True and outside == 0
    chase = setup.chase
    assert chase is not None
    served = np.array(chase.log)  # (clock time, timecode frame, take time served)
    assert len(served) > 50
    wav_s = served[:, 0] - setup.reader.audio_start_s
    # the true timecode: each stretch from its first frame's start, held at its end
    ends = [a for a, _, _, _ in truth[1:]] + [np.inf]
    true_frame = np.full(len(served), np.nan)
    for (a, b, n0, rate), end in zip(truth, ends, strict=True):
        inside = (wav_s >= a) & (wav_s < end)
        true_frame[inside] = n0 + (np.minimum(wav_s[inside], b) - a) * rate
    take_start = Timecode(1, 0, 0, 10).frame_number(25)
    err_frames = served[:, 2] * 25.0 - (true_frame - take_start)
    assert np.isfinite(err_frames).all()
    # a jump can only be heard once the first frame after it has come whole (its sync word
    # ends it): until then, one frame and an audio block (10 ms) and a cycle (10 ms), the
    # chase is where the old timecode was going
    jump_s = truth[1][0]
    hearing = (wav_s >= jump_s) & (wav_s < jump_s + 1.0 / 25 + 0.025)
    assert hearing.sum() <= 7
    # every other cycle, the take's frame served is the one at the true timecode, to a frame
    assert np.abs(err_frames[~hearing]).max() < 1.0, np.abs(err_frames[~hearing]).max()
    assert (wav_s > jump_s + 1.0 / 25 + 0.025).sum() > 10  # the jump was followed
    # it started when the timecode reached the take (35 + 10 frames in), jumped, stopped
    reached_s = truth[0][0] + 45 / truth[0][3]
    assert abs(wav_s[0] - reached_s) < 1.0 / 25, wav_s[0] - reached_s
    assert (chase.starts, chase.jumps, chase.stops) == (1, 1, 1)
    assert chase.started_at.startswith("01:00:00:1")
    events = " | ".join(result.summary["events"])  # the run's events say what happened
    assert "timecode jumped from 01:00:00:14 to 01:00:02:00" in events, events
    assert "timecode stopped or lost after 01:00:02:14" in events, events
    figures = chase.figures()
    assert figures["ltc_frames"] == 65 and figures["ltc_losses"] == 0


def test_play_chase_ltc_from_the_take_s_own_stamps_and_its_errors(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    take = performance(tmp_path / "take.csv", seconds=1.0)
    wav = tmp_path / "ltc.wav"
    ltc_wav(wav, [Segment(Timecode(0, 59, 59, 10), 45, FPS, 1.0)])  # a 0.8 s pre-roll
    # no stamps and no --chase-at: refused, naming what to give
    status = main(["play", str(take), "--bus", "/dev/null", "--chase-ltc", str(wav),
                   "--json"])
    refused = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert status == 2 and "--chase-at" in refused["error"]
    status = main(["play", str(take), "--bus", "/dev/null", "--chase-ltc", str(wav),
                   "--speed", "2", "--chase-at", "01:00:00:00", "--json"])
    refused = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert status == 2 and "--speed" in refused["error"]
    stamps = stamp_path(take)  # as `run --ltc --record` writes them: t_s 0 at 01:00:00:04
    stamps.write_text("# handrig timecode stamps 1: take.csv, source LTC x.wav\n"
                      "t_s,timecode,frame,fps\n0.000000,,,\n0.100000,01:00:00:06,90006.500,25\n")
    with SimBus.from_rig(load_rig_config()) as sim:
        status = main(["play", str(take), "--bus", sim.port_path, "--chase-ltc", str(wav),
                       "--json"])
        s = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert status == 0, s.get("error")
    chase = s["chase"]
    # the take's time 0 on the timecode, from its stamps: 01:00:00:04 exactly
    assert chase["take_starts_at_frame"] == pytest.approx(90004.0)
    assert chase["starts"] == 1 and "01:00:00:04" <= chase["started_at"] < "01:00:01:04"
    assert chase["ltc_frames"] == 45 and chase["state"] == "stopped"
    assert s["outputs"]["timecode"]["source"] == f"LTC {wav}"
