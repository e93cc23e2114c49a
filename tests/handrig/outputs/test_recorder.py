"""Recorder (CSV, BVH), load_performance and Playback: round trips, bad files, timing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.clock import FakeClock
from handrig.errors import DataError
from handrig.offline import mocap
from handrig.offline.bvh import read_bvh
from handrig.outputs import recorder
from handrig.outputs.recorder import Playback, Recorder, load_performance


def _performance(n: int, seed: int = 0, rate_hz: float = 200.0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    lim = hand.curve_limits_deg()
    poses = rng.uniform(lim[:, 0], lim[:, 1], (n, 50))
    wrist = rng.uniform([-70, -30, -70, -30], [80, 20, 80, 20], (n, 4))
    t_s = 3.0 + np.arange(n) / rate_hz
    return t_s, poses, wrist


def _record(path: Path, t_s: np.ndarray, poses: np.ndarray, wrist: np.ndarray | None,
            rate_hz: float = 200.0) -> Path:
    with Recorder(path, rate_hz=rate_hz) as rec:
        for i in range(len(t_s)):
            rec.add(t_s[i], poses[i], None if wrist is None else wrist[i])
        assert rec.n_frames == len(t_s)
    return path


@pytest.mark.parametrize("with_wrist", [True, False])
def test_csv_round_trip_within_1e6(tmp_path: Path, with_wrist: bool) -> None:
    t_s, poses, wrist = _performance(53)
    path = _record(tmp_path / "take.csv", t_s, poses, wrist if with_wrist else None)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:3] == ["t_s", "riThumbCMCx", "riThumbCMCy"]
    assert len(header) == (55 if with_wrist else 51)
    t2, p2, w2 = load_performance(path)
    np.testing.assert_allclose(t2, t_s, atol=1e-6, rtol=0)
    np.testing.assert_allclose(p2, poses, atol=1e-6, rtol=0)
    if with_wrist:
        assert w2 is not None
        np.testing.assert_allclose(w2, wrist, atol=1e-6, rtol=0)
    else:
        assert w2 is None


def test_csv_columns_are_found_by_name(tmp_path: Path) -> None:
    t_s, poses, _ = _performance(5)
    names = ["t_s", *reversed(hand.CURVE_NAMES)]
    rows = np.column_stack([t_s, poses[:, ::-1]])
    path = tmp_path / "reordered.csv"
    np.savetxt(path, rows, fmt="%.6f", delimiter=",", header=",".join(names), comments="")
    _, p2, _ = load_performance(path)
    np.testing.assert_allclose(p2, poses, atol=1e-6, rtol=0)


def test_bvh_round_trip_within_1e4_deg(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(41, seed=1, rate_hz=60.0)
    path = _record(tmp_path / "take.bvh", t_s, poses, wrist, rate_hz=60.0)
    t2, p2, w2 = load_performance(path)
    np.testing.assert_allclose(p2, poses, atol=1e-4, rtol=0)
    assert w2 is not None
    np.testing.assert_allclose(w2, wrist, atol=1e-4, rtol=0)
    np.testing.assert_allclose(t2, np.arange(41) / 60.0, atol=1e-6)


def test_bvh_skeleton_channels_and_frame_time(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(4)
    bvh = read_bvh(_record(tmp_path / "take.bvh", t_s, poses, wrist, rate_hz=200.0))
    assert bvh.frame_time_s == pytest.approx(0.005)
    for side in ("Right", "Left"):
        for digit in hand.DIGITS:
            for k in (1, 2, 3):
                j = bvh.joint(f"{side}Hand{digit}{k}")
                assert j.channels == ("Zrotation", "Xrotation", "Yrotation")
                assert np.linalg.norm(j.offset) > 0.5  # cm: plausible, never zero
    # index MCP flexion is the Zrotation of <S>HandIndex1, right sign +1, left -1
    col = bvh.column("RightHandIndex1", "Zrotation")
    np.testing.assert_allclose(bvh.motion[:, col], poses[:, hand.curve_index("riIndexMCPy")],
                               atol=1e-6)
    col = bvh.column("LeftHandIndex1", "Zrotation")
    np.testing.assert_allclose(bvh.motion[:, col], -poses[:, hand.curve_index("leIndexMCPy")],
                               atol=1e-6)
    # mirrored skeleton: right hand bones along -X, left along +X
    assert bvh.joint("RightHandMiddle2").offset[0] < 0 < bvh.joint("LeftHandMiddle2").offset[0]


def test_bvh_reads_back_through_the_mocap_profile(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(12, seed=2)
    path = _record(tmp_path / "take.bvh", t_s, poses, wrist)
    # a recording is the puppet's pose, not a suit's capture: no calibration offsets
    curves = mocap.load_curves(path, recorder.BVH_PROFILE, condition=False)
    np.testing.assert_allclose(curves.curves, poses, atol=1e-4, rtol=0)


def test_reference_capture_loads_as_a_performance() -> None:
    t_s, poses, wrist = load_performance(mocap.REFERENCE_BVH)
    ref = mocap.load_reference(condition=False)  # a performance plays as recorded
    np.testing.assert_array_equal(poses, ref.curves)
    assert wrist is not None and wrist.shape == (ref.n_frames, 4)
    assert t_s[1] == pytest.approx(1 / 24, rel=1e-4)


def test_frames_stream_to_the_partial_file_and_close_renames_it(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(30)
    path = tmp_path / "take.bvh"
    part = tmp_path / "take.bvh.partial"
    rec = Recorder(path, rate_hz=200.0)
    for i in range(20):
        rec.add(t_s[i], poses[i], wrist[i])
    rec.flush()
    # the BVH's newest frame waits for the next (or the close): a frame within half a
    # frame of its time would take its place
    assert not path.exists() and rec.frames_written == 19
    text = part.read_text()
    lines = text.splitlines()
    motion = lines.index("MOTION")
    assert lines[motion + 1] == "Frames: 19" + " " * 10  # fixed width, kept up to date
    assert len(lines) - (motion + 3) == 19
    for i in range(20, 30):
        rec.add(t_s[i], poses[i], wrist[i])
    assert rec.close() == path
    assert path.exists() and not part.exists()
    assert read_bvh(path).n_frames == 30
    assert rec.close() == path  # idempotent
    with pytest.raises(ValueError, match="closed"):
        rec.add(t_s[1], poses[1])


def test_the_writer_flushes_on_its_own_within_flush_s(tmp_path: Path) -> None:
    import time

    t_s, poses, _ = _performance(5)
    rec = Recorder(tmp_path / "t.csv", flush_s=0.05)
    for i in range(5):
        rec.add(t_s[i], poses[i])
    deadline = time.monotonic() + 10.0
    while rec.frames_written < 5 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert rec.frames_written == 5
    assert (tmp_path / "t.csv.partial").read_text().count("\n") == 6  # header + 5
    rec.close()


def test_memory_is_bounded_when_the_disk_falls_behind(tmp_path: Path) -> None:
    _, poses, _ = _performance(1)
    rec = Recorder(tmp_path / "t.csv", rate_hz=100.0, flush_s=1.0, max_pending_s=1.0)
    with rec._io_lock:  # the writer is stuck (a stalled disk): nothing leaves the list
        for i in range(250):
            rec.add(i / 100.0, poses[0])
        assert len(rec._pending) <= 101 and rec.frames_dropped >= 149  # 1 s and the header
    rec.close()
    assert rec.frames_dropped + rec.frames_written == 250
    assert len(load_performance(tmp_path / "t.csv")[0]) == rec.frames_written


def test_a_leftover_partial_take_is_never_overwritten(tmp_path: Path) -> None:
    (tmp_path / "take.csv.partial").write_text("t_s,...")
    with pytest.raises(DataError, match=r"take\.csv\.partial: an unfinished take.*record repair"):
        Recorder(tmp_path / "take.csv")
    assert (tmp_path / "take.csv.partial").read_text() == "t_s,..."


@pytest.mark.parametrize("fmt", ["csv", "bvh"])
def test_repair_keeps_every_whole_frame_of_a_cut_take(tmp_path: Path, fmt: str) -> None:
    t_s, poses, wrist = _performance(40)
    rec = Recorder(tmp_path / f"take.{fmt}", rate_hz=200.0)
    for i in range(40):
        rec.add(t_s[i], poses[i], wrist[i])
    rec.flush()  # as after a crash: the .partial holds the frames
    # (a BVH's newest frame waits for the next one or the close: 39 of the 40 are in)
    written = 40 if fmt == "csv" else 39
    assert rec.frames_written == written
    part = tmp_path / f"take.{fmt}.partial"
    data = part.read_bytes()
    if fmt == "bvh":  # killed between batches: readable as it is
        assert len(load_performance(part)[0]) == written
    rec._stop = True  # abandon the recorder without closing (the process "died")
    cut = data[: len(data) - 37] + b"\x00" * 600  # a cut last line and a power cut's zeros
    part.write_bytes(cut)
    with pytest.raises(DataError, match="record repair"):
        load_performance(part)
    fixed = recorder.repair(part)
    kept = written - 1
    assert fixed.path == tmp_path / f"take.{fmt}" and not part.exists()
    assert fixed.frames == kept and fixed.bytes_dropped > 600
    assert fixed.declared_frames == (written if fmt == "bvh" else None)
    assert f"{kept} whole frames" in fixed.describe()
    t2, p2, _ = load_performance(fixed.path)
    assert len(t2) == kept
    np.testing.assert_allclose(p2, poses[:kept], atol=1e-4)
    again = recorder.repair(fixed.path)  # a whole file: nothing to do
    assert again.frames == kept and again.bytes_dropped == 0


def test_repair_refuses_a_damaged_header(tmp_path: Path) -> None:
    bad = tmp_path / "x.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    with pytest.raises(DataError, match=r"x\.bvh: no MOTION block.*nothing to keep"):
        recorder.repair(bad)
    csv = tmp_path / "x.csv"
    csv.write_text("1,2,3\n")
    with pytest.raises(DataError, match=r"x\.csv: no header row"):
        recorder.repair(csv)
    with pytest.raises(DataError, match="not found"):
        recorder.repair(tmp_path / "nope.csv")


def test_wrist_must_stay_consistent(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(2)
    with Recorder(tmp_path / "w.csv") as rec:
        rec.add(t_s[0], poses[0], wrist[0])
        with pytest.raises(ValueError, match="wrist"):
            rec.add(t_s[1], poses[1])


def test_bad_path_and_suffix_fail_before_recording(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="cannot create"):
        Recorder(tmp_path / "missing_dir" / "take.csv")
    with pytest.raises(DataError, match=r"unknown recording suffix '\.txt'"):
        Recorder(tmp_path / "take.txt")
    assert recorder.format_of(tmp_path / "take.dat", "bvh") == "bvh"


def _csv_lines(tmp_path: Path, n: int = 6) -> list[str]:
    t_s, poses, wrist = _performance(n)
    return _record(tmp_path / "good.csv", t_s, poses, wrist).read_text().splitlines()


def _write(path: Path, lines: list[str], tail: str = "\n") -> Path:
    path.write_text("\n".join(lines) + tail)
    return path


def test_truncated_csv_names_file_and_line(tmp_path: Path) -> None:
    lines = _csv_lines(tmp_path)
    text = "\n".join(lines)
    path = tmp_path / "cut.csv"
    path.write_text(text[: len(text) - 200])  # cut inside the last row
    with pytest.raises(DataError, match=r"cut\.csv: line 7: \d+ values, expected 55 .*truncated"):
        load_performance(path)


def test_corrupt_csv_value_names_line_and_column(tmp_path: Path) -> None:
    lines = _csv_lines(tmp_path)
    fields = lines[3].split(",")
    fields[10] = "1.2.3"
    lines[3] = ",".join(fields)
    with pytest.raises(DataError, match=r"bad\.csv: line 4, column 11: '1\.2\.3' is not a number"):
        load_performance(_write(tmp_path / "bad.csv", lines))


def test_csv_nan_time_going_backwards_and_bad_header(tmp_path: Path) -> None:
    lines = _csv_lines(tmp_path)
    nan = [*lines]
    nan[2] = nan[2].replace(nan[2].split(",")[5], "nan", 1)
    with pytest.raises(DataError, match=r"nan\.csv: line 3: value nan is not finite"):
        load_performance(_write(tmp_path / "nan.csv", nan))
    back = [lines[0], lines[2], lines[1], *lines[3:]]
    with pytest.raises(DataError, match=r"back\.csv: line 3: time goes backwards"):
        load_performance(_write(tmp_path / "back.csv", back))
    with pytest.raises(DataError, match=r"hdr\.csv: line 1: unknown column 'riIndexMCPq'"):
        load_performance(_write(tmp_path / "hdr.csv",
                                [lines[0].replace("riIndexMCPy", "riIndexMCPq"), *lines[1:]]))
    with pytest.raises(DataError, match=r"empty\.csv: empty file"):
        load_performance(_write(tmp_path / "empty.csv", [], tail=""))


def test_truncated_bvh_names_file_and_frame(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(10)
    text = _record(tmp_path / "good.bvh", t_s, poses, wrist).read_text()
    path = tmp_path / "cut.bvh"
    path.write_text(text[: len(text) - 700])
    with pytest.raises(DataError, match=r"cut\.bvh: MOTION is truncated at frame 9"):
        load_performance(path)
    path.write_text(text[: text.index("MOTION") // 2])
    with pytest.raises(DataError, match=r"cut\.bvh: no MOTION block"):
        load_performance(path)


def test_bvh_of_another_skeleton_is_rejected(tmp_path: Path) -> None:
    text = "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
    text += "End Site\n{\nOFFSET 0 1 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.04\n0 0 0\n"
    path = tmp_path / "body.bvh"
    path.write_text(text)
    with pytest.raises(DataError, match=r"body\.bvh: joint 'LeftHandIndex1' not found"):
        load_performance(path)
    with pytest.raises(DataError, match="not found"):
        load_performance(tmp_path / "nope.csv")


def test_playback_iterates_at_recorded_times(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(20, rate_hz=50.0)
    t_s[7:] += 0.013  # a late frame: playback keeps the recorded spacing
    path = _record(tmp_path / "take.csv", t_s, poses, wrist)
    clock = FakeClock(100.0)
    seen = []
    for t, pose, w in Playback(path, clock):
        seen.append((clock.now() - 100.0, t))
        assert w is not None
        np.testing.assert_allclose(pose, poses[len(seen) - 1], atol=1e-6)
    played, recorded = np.array(seen).T
    np.testing.assert_allclose(played, recorded - recorded[0], atol=1e-9)
    assert len(seen) == 20


def test_playback_sample_is_nonblocking_and_ends(tmp_path: Path) -> None:
    t_s, poses, _ = _performance(10, rate_hz=10.0)
    path = _record(tmp_path / "take.csv", t_s, poses, None)
    clock = FakeClock()
    pb = Playback(path, clock, speed=2.0)
    pb.start()
    clock.advance(0.26)  # 0.52 s of performance at 2x: frame 5
    got = pb.sample()
    assert got is not None and got[1] is None
    np.testing.assert_allclose(got[0], poses[5], atol=1e-6)
    assert clock.sleeps == 0
    clock.advance(0.3)  # 1.12 s: past the end (1.0 s incl. the last frame's period)
    assert pb.sample() is None
    looped = Playback(path, clock, loop=True)
    looped.start()
    clock.advance(1.05)  # wraps to 0.05 s: frame 0
    again = looped.sample()
    assert again is not None
    np.testing.assert_allclose(again[0], poses[0], atol=1e-6)


def test_rig_output_hook_records_the_54_pose(tmp_path: Path) -> None:
    t_s, poses, wrist = _performance(7)
    with Recorder(tmp_path / "hook.bvh", rate_hz=200.0) as rec:
        for i in range(7):
            rec(t_s[i], np.concatenate([poses[i], wrist[i]]))
    _, p2, w2 = load_performance(tmp_path / "hook.bvh")
    np.testing.assert_allclose(p2, poses, atol=1e-4)
    assert w2 is not None
    np.testing.assert_allclose(w2, wrist, atol=1e-4)


def _fk_tips(bvh_path: Path, frame: int) -> dict[str, np.ndarray]:
    """World positions (cm) of every joint and end site, BVH rotations intrinsic ZXY."""
    from scipy.spatial.transform import Rotation

    bvh = read_bvh(bvh_path)
    rot: list[np.ndarray] = []
    pos: list[np.ndarray] = []
    out: dict[str, np.ndarray] = {}
    for j in bvh.joints:
        vals = dict(zip(j.channels, bvh.motion[frame, j.channel_start:], strict=False))
        local = Rotation.from_euler(
            "ZXY", [vals.get("Zrotation", 0.0), vals.get("Xrotation", 0.0),
                    vals.get("Yrotation", 0.0)], degrees=True).as_matrix()
        if j.parent < 0:
            p, r = np.asarray(j.offset, dtype=float), local
        else:
            p = pos[j.parent] + rot[j.parent] @ np.asarray(j.offset)
            r = rot[j.parent] @ local
        pos.append(p)
        rot.append(r)
        out[j.name] = p
    return out


def test_bvh_fingers_curl_toward_the_palm_on_both_hands(tmp_path: Path) -> None:
    """In a BVH viewer the skeleton is palm down (-Y): flexion must lower the fingertips."""
    rest = np.zeros(50)
    fist = np.zeros(50)
    for c in hand.select_curves(motion=hand.Motion.FLEXION):
        if c.digit != "Thumb":
            fist[c.index] = 60.0
    wrist = np.array([[0.0, 0, 0, 0], [0.0, 0, 0, 0], [40.0, 0, 40.0, 0], [0.0, 15, 0.0, 15]])
    path = tmp_path / "fist.bvh"
    with Recorder(path, rate_hz=10.0) as rec:  # a frame every 0.1 s: one BVH frame each
        rec.add(0.0, rest, wrist[0])
        rec.add(0.1, fist, wrist[1])
        rec.add(0.2, rest, wrist[2])
        rec.add(0.3, rest, wrist[3])
    r0, r1, r2, r3 = (_fk_tips(path, k) for k in range(4))
    for side in ("Right", "Left"):
        # the distal joint of the index: with a fist it drops below the knuckle plane
        assert r1[f"{side}HandIndex3"][1] < r0[f"{side}HandIndex3"][1] - 2.0
        # wrist flexion (palmar) lowers the knuckles, radial deviation moves them forward
        assert r2[f"{side}HandMiddle1"][1] < r0[f"{side}HandMiddle1"][1] - 2.0
        assert r3[f"{side}HandMiddle1"][2] > r0[f"{side}HandMiddle1"][2] + 1.0


def test_a_write_error_never_reaches_the_loop_and_close_says_what_to_do(tmp_path: Path) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("needs /dev/full (Linux)")
    _, poses, _ = _performance(1)
    rec = Recorder(tmp_path / "t.csv", sync=False)
    os.close(rec._fd)
    rec._fd = os.open("/dev/full", os.O_WRONLY)  # every write fails: ENOSPC
    for i in range(5):
        rec.add(i / 200.0, poses[0])
    rec.flush()
    assert rec.error is not None and "No space left" in str(rec.error)
    rec.add(1.0, poses[0])  # dropped and counted, not raised
    assert rec.frames_dropped == 6
    with pytest.raises(DataError, match=r"writing the recording failed.*record repair"):
        rec.close()
