"""Takes are never replaced, keep time (CSV as recorded, BVH resampled), and survive a
full disk: the recorder stops at once, says why, and what it wrote stays readable."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import bvh as outside_bvh  # an outside BVH reader, to check ours against
import numpy as np
import pytest

from handrig.errors import DataError
from handrig.offline.bvh import read_bvh
from handrig.outputs.recorder import Recorder, free_path, load_performance, repair


def _poses(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-20, 60, (n, 50)), rng.uniform(-30, 30, (n, 4))


# -- a take is never replaced -------------------------------------------------------


def test_an_existing_take_is_refused_naming_it_and_the_next_free_name(tmp_path: Path) -> None:
    take = tmp_path / "take.csv"
    take.write_text("the first take\n")
    (tmp_path / "take-2.csv").write_text("the second take\n")
    with pytest.raises(DataError) as err:
        Recorder(take)
    text = str(err.value)
    assert text.startswith(f"{take}: a take is already there, and a take is never replaced")
    assert str(tmp_path / "take-3.csv") in text and "(the next free name)" in text
    assert take.read_text() == "the first take\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take-2.csv", "take.csv"]
    assert free_path(tmp_path / "new.bvh") == tmp_path / "new.bvh"


def test_a_file_that_appears_during_the_run_is_kept_and_the_take_gets_the_next_name(
        tmp_path: Path) -> None:
    take = tmp_path / "take.bvh"
    logged: list[str] = []
    poses, wrist = _poses(10)
    rec = Recorder(take, rate_hz=100.0, log=logged.append)
    for i in range(10):
        rec.add(i / 100.0, poses[i], wrist[i])
    take.write_text("someone else's file\n")  # e.g. a second run started at the same time
    final = rec.close()
    assert final == tmp_path / "take-2.bvh" == rec.path
    assert take.read_text() == "someone else's file\n"
    assert read_bvh(final).n_frames == 10 and not (tmp_path / "take.bvh.partial").exists()
    assert logged == [f"{take} appeared during the run and is kept: the take is {final}"]


# -- takes keep time ----------------------------------------------------------------


def _glove_times(rate_hz: float, seconds: float, silence: tuple[float, float] | None,
                 seed: int = 1) -> np.ndarray:
    """Frame times of a glove at ``rate_hz`` with USB jitter (up to a third of a period),
    silent over ``silence`` = (start, end) s if given."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    t = t + rng.uniform(0.0, 1.0 / (3 * rate_hz), t.shape)
    t[0] = 0.0
    if silence is not None:
        t = t[(t < silence[0]) | (t >= silence[1])]
    return np.sort(t) + 0.25  # the first frame comes a little after the run starts


@pytest.mark.parametrize("glove_hz", [100.0, 200.0, 500.0])
def test_bvh_is_resampled_from_the_frames_times_and_keeps_a_silence(
        tmp_path: Path, glove_hz: float) -> None:
    t = _glove_times(glove_hz, 4.0, silence=(1.5, 2.5))
    poses, wrist = _poses(len(t))
    bvh_rate = 120.0  # another rate than the glove's: the user's choice
    with Recorder(tmp_path / "t.bvh", rate_hz=bvh_rate) as b, \
            Recorder(tmp_path / "t.csv", rate_hz=glove_hz) as c:
        for i in range(len(t)):
            b.add(t[i], poses[i], wrist[i])
            c.add(t[i], poses[i], wrist[i])
    span = t[-1] - t[0]
    # CSV: every frame with its own time, the silence a 1 s gap between two rows
    tc, pc, wc = load_performance(tmp_path / "t.csv")
    np.testing.assert_allclose(tc, t, atol=1e-6)
    np.testing.assert_allclose(pc, poses, atol=1e-6)
    assert wc is not None
    np.testing.assert_allclose(wc, wrist, atol=1e-6)
    assert np.max(np.diff(tc)) == pytest.approx(1.0, abs=2.0 / glove_hz)
    # BVH: one frame per 1/120 s from the first frame to the last, each the newest frame
    # at or before half a frame after its time (what the servos held then)
    tb, pb, wb = load_performance(tmp_path / "t.bvh")
    assert len(tb) == int(np.floor(span * bvh_rate + 1e-6)) + 1
    assert abs(len(tb) / bvh_rate - (span + 1.0 / bvh_rate)) <= 1.0 / bvh_rate
    src = np.searchsorted(t, t[0] + tb + 0.5 / bvh_rate + 1e-7, side="right") - 1
    np.testing.assert_allclose(pb, poses[src], atol=1e-4)
    assert wb is not None
    np.testing.assert_allclose(wb, wrist[src], atol=1e-4)
    in_silence = (t[0] + tb > 1.5 + 0.25 + 0.01) & (t[0] + tb < 2.5 + 0.25 - 0.01)
    assert in_silence.sum() >= np.floor(0.98 * bvh_rate)  # 0.98 s of frames...
    assert len(set(src[in_silence])) == 1  # ...all holding the last pose before it
    # an outside reader agrees on the frame count and the frame time
    with open(tmp_path / "t.bvh") as f:
        mocap = outside_bvh.Bvh(f.read())
    assert mocap.nframes == len(tb) and mocap.frame_time == pytest.approx(1.0 / bvh_rate)


def test_bvh_frames_hold_the_frame_up_to_half_a_frame_after_their_time(tmp_path: Path) -> None:
    """Frame k (time k / rate) holds the newest frame at or before (k + 1/2) / rate, and
    is written as soon as a frame shows that none nearer comes."""
    poses, wrist = _poses(3)
    rec = Recorder(tmp_path / "g.bvh", rate_hz=100.0)
    rec.add(0.0, poses[0], wrist[0])
    rec.add(0.025, poses[1], wrist[1])  # 0.00, 0.01 hold frame 0; 0.02 takes it (tie)
    rec.flush()
    assert rec.frames_written == 3
    rec.add(0.04, poses[2], wrist[2])  # 0.03 holds frame 1; 0.04 waits for what follows
    rec.flush()
    assert rec.frames_written == 4
    rec.close()  # nothing follows: 0.04 is frame 2's, the last time a frame came
    _, p, _ = load_performance(tmp_path / "g.bvh")
    np.testing.assert_allclose(p, poses[[0, 0, 1, 1, 2]], atol=1e-4)


def test_a_jittery_glove_at_the_bvh_rate_maps_one_to_one(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    t = np.arange(400) / 200.0 + rng.uniform(-0.4, 0.4, 400) / 200.0  # +-0.4 frame
    t[0] = 0.0
    poses, wrist = _poses(len(t))
    with Recorder(tmp_path / "j.bvh", rate_hz=200.0) as rec:
        for i in range(len(t)):
            rec.add(t[i], poses[i], wrist[i])
    _, p, _ = load_performance(tmp_path / "j.bvh")
    n = int(np.floor(t[-1] * 200.0 + 1e-9)) + 1
    np.testing.assert_allclose(p, poses[:n], atol=1e-4)  # none doubled, none dropped


@pytest.mark.parametrize("fmt", ["csv", "bvh"])
def test_repair_and_the_readers_handle_an_uneven_take_cut_short(tmp_path: Path,
                                                                 fmt: str) -> None:
    t = _glove_times(200.0, 2.0, silence=(0.8, 1.3))
    poses, wrist = _poses(len(t))
    path = tmp_path / f"cut.{fmt}"
    rec = Recorder(path, rate_hz=200.0)
    for i in range(len(t)):
        rec.add(t[i], poses[i], wrist[i])
    rec.flush()
    written = rec.frames_written
    os.close(rec._fd)  # the run dies here: the take stays a .partial
    part = tmp_path / f"cut.{fmt}.partial"
    with open(part, "ab") as f:
        f.write(b"12.5,3" if fmt == "csv" else b"0.000000 1.2")  # a frame cut in half
    done = repair(part)
    assert done.path == path and done.frames == written and done.bytes_dropped > 0
    t2, p2, _ = load_performance(path)
    assert len(t2) == written
    if fmt == "csv":
        np.testing.assert_allclose(t2, t[:written], atol=1e-6)
    else:
        src = np.searchsorted(t, t[0] + t2 + 0.5 / 200.0 + 1e-7, side="right") - 1
        np.testing.assert_allclose(p2, poses[src], atol=1e-4)


# -- a full disk ----------------------------------------------------------------------

_CHILD = textwrap.dedent("""
    import json, resource, signal, sys, time
    import numpy as np
    from handrig.outputs.recorder import Recorder

    path, limit = sys.argv[1], int(sys.argv[2])
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails: EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    rec = Recorder(path, rate_hz=200.0, flush_s=0.05,
                   log=lambda m: print("LOG", json.dumps(m), flush=True))
    pose, wrist = np.linspace(-10, 50, 50), np.zeros(4)
    for i in range(600):  # 3 s at 200 Hz: the show goes on
        rec.add(i / 200.0, pose + i * 1e-3, wrist)
        if i % 50 == 0:
            print("FRAME", i, flush=True)
        time.sleep(0.005)
    final = rec.close()
    print("DONE", json.dumps({"path": str(final), "written": rec.frames_written,
                              "dropped": rec.frames_dropped, "added": rec.n_frames,
                              "reason": rec.stopped_reason}), flush=True)
""")


@pytest.mark.parametrize("fmt", ["csv", "bvh"])
def test_a_full_disk_stops_the_recording_at_once_and_the_take_stays_readable(
        tmp_path: Path, fmt: str) -> None:
    """A real process with a file size limit (RLIMIT_FSIZE: no root, no loop device): its
    writes past the limit fail as on a full disk."""
    path = tmp_path / f"take.{fmt}"
    limit = 60_000  # bytes: about 150 (CSV) or 240 (BVH) frames of the 600
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(limit)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    logs = [i for i, ln in enumerate(lines) if ln.startswith("LOG ")]
    assert len(logs) == 1
    message = json.loads(lines[logs[0]][4:])
    assert message.startswith("recording stopped: the file size limit was reached")
    assert f"{path} keeps its first" in message
    assert "the show goes on" in message
    # said during the run, not at its end: frames were still being added after it
    assert any(ln.startswith("FRAME ") for ln in lines[logs[0]:])
    done = json.loads(next(ln for ln in lines if ln.startswith("DONE "))[5:])
    assert done["path"] == str(path) and done["reason"] == message
    assert 0 < done["written"] < 600 and done["dropped"] > 0
    assert done["added"] == 600
    assert path.stat().st_size <= limit
    t, poses, _ = load_performance(path)  # readable as it is, no repair needed
    assert len(t) == done["written"]
    np.testing.assert_allclose(poses[-1], np.linspace(-10, 50, 50) + (len(t) - 1) * 1e-3,
                               atol=1e-4)


# -- the same, through a real `handrig run` -------------------------------------------

CLI = [sys.executable, "-m", "handrig.cli"]


def test_handrig_run_refuses_an_existing_take_before_the_servos(tmp_path: Path) -> None:
    from sim.demo_recording import DEMO_RECORDING

    take = tmp_path / "take.bvh"
    take.write_text("yesterday's take\n")
    out = subprocess.run([*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", "sim",
                          "--seconds", "1", "--record", str(take), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert (f"handrig: error: {take}: a take is already there, and a take is never"
            f" replaced; record to {tmp_path / 'take-2.bvh'}") in out.stderr
    summary = json.loads(out.stdout)
    assert summary["torque_off"] is None and summary["frames"] == 0
    # refused before the bus was opened
    assert "simulated servo bus" not in (out.stdout + out.stderr).lower()
    assert take.read_text() == "yesterday's take\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take.bvh"]


def _file_size_limit(limit: int) -> None:
    import resource
    import signal

    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # kept across exec: writes fail, EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


def test_handrig_run_goes_on_when_the_disk_fills_and_says_so_at_once(tmp_path: Path) -> None:
    from sim.demo_recording import DEMO_RECORDING

    take = tmp_path / "take.csv"
    limit = 75_000  # bytes: about 0.6 s of the 200 Hz take (the run is 3 s and the ease)
    proc = subprocess.Popen(
        [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", "sim", "--seconds", "3",
         "--record", str(take), "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: _file_size_limit(limit))
    try:
        out, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    lines = err.splitlines()
    stopped = [i for i, ln in enumerate(lines) if ln.startswith("recording stopped: ")]
    assert len(stopped) == 1, err
    assert "the file size limit was reached" in lines[stopped[0]]
    assert f"{take} keeps its first" in lines[stopped[0]]
    assert "the show goes on" in lines[stopped[0]]
    done = next(i for i, ln in enumerate(lines) if "3 s done" in ln)
    assert stopped[0] < done  # said while the show ran, not after it
    summary = json.loads(out)
    assert summary["torque_off"] is True and "error" not in summary
    assert summary["stop_reason"] == "3 s done" and summary["frames"] > 500
    rec = summary["outputs"]["recording"]
    assert rec["stopped_reason"] == lines[stopped[0]]
    assert rec["frames"] > 0 and rec["frames_dropped"] > 0
    t, poses, _ = load_performance(take)  # readable as it is
    assert len(t) == rec["frames"] and take.stat().st_size <= limit
    assert np.all(np.diff(t) >= 0) and np.isfinite(poses).all()


def test_record_convert_writes_a_bvh_at_the_rate_the_user_chooses(tmp_path: Path) -> None:
    t = _glove_times(100.0, 3.0, silence=(1.0, 2.0))
    poses, wrist = _poses(len(t))
    take = tmp_path / "take.csv"
    with Recorder(take, rate_hz=100.0) as rec:
        for i in range(len(t)):
            rec.add(t[i], poses[i], wrist[i])
    bvh_path = tmp_path / "take60.bvh"
    out = subprocess.run([*CLI, "record", "convert", str(take), str(bvh_path), "--rate", "60",
                          "--json"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    done = json.loads(out.stdout)
    span = t[-1] - t[0]
    n = int(np.floor(span * 60.0 + 1e-6)) + 1
    assert done["frames_in"] == len(t) and done["frames_out"] == n
    with open(bvh_path) as f:
        outside = outside_bvh.Bvh(f.read())
    assert outside.nframes == n and outside.frame_time == pytest.approx(1 / 60)
    tb, pb, _ = load_performance(bvh_path)
    src = np.searchsorted(t, t[0] + tb + 0.5 / 60 + 1e-7, side="right") - 1
    np.testing.assert_allclose(pb, poses[src], atol=1e-4)
    # and back to a CSV: the BVH's frame times, its poses
    back = tmp_path / "back.csv"
    out = subprocess.run([*CLI, "record", "convert", str(bvh_path), str(back)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith(f"{back}: {n} frames from {n}")
    tc, pc, _ = load_performance(back)
    np.testing.assert_allclose(tc, np.arange(n) / 60.0, atol=1e-6)
    np.testing.assert_allclose(pc, pb, atol=1e-4)
    # a take is never replaced, by convert either
    out = subprocess.run([*CLI, "record", "convert", str(bvh_path), str(back)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and f"{back}: a take is already there" in out.stderr
    assert "Traceback" not in out.stderr


def test_a_run_records_bvh_at_the_glove_rate_or_the_rate_asked_for(tmp_path: Path) -> None:
    import contextlib
    import dataclasses

    from handrig.app import factory as app
    from handrig.app import parts as app_parts
    from handrig.clock import MonotonicClock

    rig_cfg = app_parts.build_parts().rig_config
    fixed = dataclasses.replace(rig_cfg, loop=dataclasses.replace(rig_cfg.loop, mode="fixed"))
    cases = [(rig_cfg, None, 100.0), (rig_cfg, 60.0, 60.0), (fixed, None, rig_cfg.loop.rate_hz)]
    for i, (cfg, asked, expected) in enumerate(cases):
        with contextlib.ExitStack() as stack:
            outs = app.outputs(stack, cfg, MonotonicClock(), record=str(tmp_path / f"{i}.bvh"),
                               log=lambda _: None, glove_rate_hz=100.0, record_rate_hz=asked)
            (rec,) = outs
            assert isinstance(rec, Recorder) and rec.rate_hz == expected


def test_handrig_run_record_rate_sets_the_bvh_frame_time(tmp_path: Path) -> None:
    from sim.demo_recording import DEMO_RECORDING

    take = tmp_path / "take.bvh"
    out = subprocess.run([*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", "sim",
                          "--seconds", "2", "--record", str(take), "--record-rate", "60",
                          "--json"], capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    with open(take) as f:
        outside = outside_bvh.Bvh(f.read())
    assert outside.frame_time == pytest.approx(1 / 60)
    rec = summary["outputs"]["recording"]
    assert rec["frames"] == outside.nframes
    # 2 s and the 1 s ease, from the first frame: within a frame of the run
    assert abs(outside.nframes / 60 - rec["duration_s"]) <= 1 / 60 + 0.01
    assert abs(rec["duration_s"] - summary["duration_s"]) <= 0.1
    out = subprocess.run([*CLI, "run", "--record", str(tmp_path / "x.bvh"), "--record-rate",
                          "0", "--bus", "sim"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "--record-rate: must be in 1..2000, got '0'" in out.stderr
