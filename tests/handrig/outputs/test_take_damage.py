"""Takes that were damaged, cut or written onto a full disk (issue 41): `record repair`
checks every frame of a performance (CSV, BVH) and of a glove take, keeps the whole
frames before damage and says where it is; a glove take on a full disk is cut back to
whole frames and its counts are what is on disk."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from handrig.devices.glove import GloveSample
from handrig.devices.glove_recording import read_glove_recording
from handrig.errors import DataError
from handrig.outputs.glove_take import GloveTake
from handrig.outputs.recorder import Recorder, load_performance, partial_path, repair

FRAMES = 400


def _performance(path: Path) -> None:
    rng = np.random.default_rng(7)
    with Recorder(path, rate_hz=100.0, sync=False) as rec:
        for i in range(FRAMES):
            rec.add(i / 100.0, rng.uniform(-5, 40, 50), rng.uniform(-10, 10, 4))


def _frame_start(data: bytes, frame: int, fmt: str) -> int:
    """The byte where frame line ``frame`` (0-based) starts."""
    skip = data[: data.index(b"Frame Time:")].count(b"\n") + 1 if fmt == "bvh" else 1
    pos = 0
    for _ in range(skip + frame):
        pos = data.index(b"\n", pos) + 1
    return pos


@pytest.mark.parametrize("fmt", ["csv", "bvh"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fifty_bytes_overwritten_are_found_and_what_is_kept_plays(
        tmp_path: Path, fmt: str, seed: int) -> None:
    path = tmp_path / f"take.{fmt}"
    _performance(path)
    before = load_performance(path)
    data = path.read_bytes()
    rng = np.random.default_rng(seed)
    frame = int(rng.integers(50, len(before[0]) - 50))
    at = _frame_start(data, frame, fmt) + 20
    damaged = bytearray(data)
    damaged[at: at + 50] = rng.bytes(50)
    path.write_bytes(bytes(damaged))
    with pytest.raises(DataError):  # as the issue found it: play refuses the take
        load_performance(path)
    done = repair(path)
    assert done.damage is not None, done.describe()
    assert done.frames == frame  # every whole frame before the damaged one
    line = frame + 1 + (data[: data.index(b"Frame Time:")].count(b"\n") + 1 if fmt == "bvh"
                        else 1)
    assert done.damage.line == line
    assert f"damaged at line {line}" in done.describe()
    t, poses, _ = load_performance(path)  # what repair calls sound plays
    assert len(t) == frame
    np.testing.assert_allclose(poses, before[1][:frame], atol=1e-5)
    moved = done.damage.moved_to
    assert moved.name == f"take.{fmt}.damaged"
    assert path.read_bytes() + moved.read_bytes() == _with_count(bytes(damaged), fmt, frame)
    assert len(done.describe()) < 400


def _with_count(data: bytes, fmt: str, frames: int) -> bytes:
    """``data`` with the BVH header's frame count set to ``frames`` (what repair writes)."""
    if fmt != "bvh":
        return data
    at = data.index(b"Frames: ") + len(b"Frames: ")
    width = data.index(b"\n", at) - at
    return data[:at] + f"{frames:<{width}d}".encode() + data[at + width:]


@pytest.mark.parametrize("fmt", ["csv", "bvh"])
def test_damage_in_the_header_keeps_nothing_and_says_so(tmp_path: Path, fmt: str) -> None:
    path = tmp_path / f"take.{fmt}"
    _performance(path)
    data = bytearray(path.read_bytes())
    at = 40 if fmt == "csv" else data.index(b"RightHandIndex1") - 5
    data[at: at + 50] = b"#" * 50
    path.write_bytes(bytes(data))
    with pytest.raises(DataError, match="nothing to keep"):
        repair(path)
    assert path.read_bytes() == bytes(data)  # left as it was


def test_times_that_go_back_are_damage(tmp_path: Path) -> None:
    path = tmp_path / "take.csv"
    _performance(path)
    lines = path.read_bytes().split(b"\n")
    lines[101] = b"0.5" + lines[101][lines[101].index(b","):]  # frame 100 at 0.5 s
    path.write_bytes(b"\n".join(lines))
    done = repair(path)
    assert done.frames == 100 and done.damage is not None
    assert "its time 0.5 s does not come after 0.99 s" in done.damage.what


def _sample(t: float, k: int) -> GloveSample:
    return GloveSample(np.array([100.0 + k, 200.0, 300.0]), np.array([0.0, 0.0, 0.0, 1.0]),
                       0, False, k, 0, t, k)


def test_glove_take_partials_are_repaired(tmp_path: Path) -> None:
    """The .partial a SIGKILL leaves (the writer's batches on disk, never closed), intact
    and with a torn last row; a finished glove take with a damaged row."""
    path = tmp_path / "glove.csv"
    take = GloveTake(path, channel_names=("a", "b", "c"), rate_hz=100.0, sync=False,
                     flush_s=60.0)
    for k in range(1, 31):
        take.tap(_sample(k * 0.01, k))
    take(0.0, np.zeros(54))
    take._write_pending()  # what the writer thread had written when the run was killed
    part = partial_path(path)
    intact = part.read_bytes()
    done = repair(part)  # an intact .partial: nothing to cut, renamed
    assert done.path == path and done.frames == 30 and done.bytes_dropped == 0
    assert done.kind == "glove take" and not part.exists()
    assert len(read_glove_recording(path)) == 30
    path.rename(part)
    part.write_bytes(intact + b"0.310000,131,20")  # a row torn by the kill
    done = repair(part)
    assert done.frames == 30 and done.bytes_dropped == len(b"0.310000,131,20")
    assert path.read_bytes() == intact
    # a finished take with 50 bytes overwritten, through the command line
    rows = intact.split(b"\n")
    rows[10] = rows[10][:5] + b"x" * 50
    path.write_bytes(b"\n".join(rows))
    out = subprocess.run([sys.executable, "-m", "handrig.cli", "record", "repair", "--json",
                          str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    (report,) = json.loads(out.stdout)
    assert report["kind"] == "glove take" and report["frames"] == 7  # rows 4..10
    assert report["damage"]["line"] == 11
    assert report["damage"]["what"] == "1 value, the header's frames have 9"
    assert len(read_glove_recording(path)) == 7
    take.close()  # the test's writer (its file was repaired away)


_CHILD = textwrap.dedent("""
    import json, resource, signal, sys
    import numpy as np
    from handrig.devices.glove import GloveSample
    from handrig.outputs.glove_take import GloveTake

    path, limit = sys.argv[1], int(sys.argv[2])
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails: EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    logs = []
    take = GloveTake(path, channel_names=("a", "b", "c"), rate_hz=200.0, flush_s=60.0,
                     log=logs.append)
    for k in range(1, 601):
        take.tap(GloveSample(np.array([1000.0 + k, 2000.0, 3000.0]),
                             np.array([0.0, 0.0, 0.0, 1.0]), 0, False, k, 0, k / 200.0, k))
        if k % 7 == 0:  # batches of 7 rows: the limit falls inside one
            take(0.0, np.zeros(54))
            take._write_pending()
    line = take.close()
    st = take.status()
    print(json.dumps({"line": line, "written": st.frames_written, "dropped": st.frames_dropped,
                      "reason": st.stopped_reason, "logs": logs}))
""")


def test_a_full_disk_cuts_the_glove_take_back_to_what_the_summary_says(tmp_path: Path) -> None:
    """A real process with a file size limit (RLIMIT_FSIZE: no root, no small file system);
    its writes past the limit fail as on a full disk."""
    path = tmp_path / "glove.csv"
    limit = 10_000  # bytes: about 250 rows of the 600
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(limit)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    done = json.loads(out.stdout)
    assert len(done["logs"]) == 1 and "the glove take stopped" in done["logs"][0]
    assert 0 < done["written"] < 600 and done["written"] + done["dropped"] == 600
    assert f"keeps its first {done['written']} frames" in done["reason"]
    assert f"{done['written']} glove frames" in done["line"]
    data = path.read_bytes()
    assert data.endswith(b"\n") and len(data) <= limit  # no torn row
    rec = read_glove_recording(path)  # readable as it is
    assert len(rec) == done["written"]
    assert rec.raw[-1, 0] == 1000.0 + done["written"]
