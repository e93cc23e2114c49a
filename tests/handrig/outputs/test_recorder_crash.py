"""A take survives SIGKILL: a real process records at 200 Hz, is killed, the take is repaired."""

from __future__ import annotations

import contextlib
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from handrig.errors import DataError
from handrig.outputs.recorder import load_performance, partial_path, repair

RATE_HZ = 200.0
FLUSH_S = 0.5

# Records frames paced by the wall clock and prints how many it has added after each.
CHILD = """
import sys, time
import numpy as np
from handrig.outputs.recorder import Recorder
rec = Recorder(sys.argv[1], rate_hz={rate}, flush_s={flush})
pose = np.linspace(-10.0, 60.0, 50)
wrist = np.array([5.0, -3.0, 4.0, 2.0])
t0 = time.monotonic()
i = 0
while True:
    time.sleep(max(0.0, t0 + i / {rate} - time.monotonic()))
    rec.add(i / {rate}, pose + (i % 7), wrist)
    i += 1
    print(i, flush=True)
"""


def _last_count(proc: subprocess.Popen[bytes], until: int, timeout_s: float) -> tuple[int, bytes]:
    """Read the child's counts until it reports ``until`` frames: the last count read and
    the bytes of a count not yet ended by a newline."""
    assert proc.stdout is not None
    fd = proc.stdout.fileno()
    buf = b""
    last = 0
    deadline = time.monotonic() + timeout_s
    while last < until and time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.5)
        if ready:
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            buf += chunk
            lines = buf.split(b"\n")
            buf = lines[-1]
            if len(lines) > 1 and lines[-2]:
                last = int(lines[-2])
    return last, buf


@pytest.mark.parametrize("fmt", ["bvh", "csv"])
def test_sigkill_mid_take_loses_at_most_about_a_second(tmp_path: Path, fmt: str) -> None:
    take = tmp_path / f"take.{fmt}"
    script = CHILD.format(rate=RATE_HZ, flush=FLUSH_S)
    proc = subprocess.Popen([sys.executable, "-c", script, str(take)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        # killed 2 s in: four of the writer's batches on disk, and twice the second the
        # test lets it lose
        before, buf = _last_count(proc, until=int(2 * RATE_HZ), timeout_s=60.0)
        assert before > 0, proc.stderr.read() if proc.stderr else ""
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        assert proc.stdout is not None
        counts = (buf + proc.stdout.read()).split()  # what it printed up to the kill
        added = max(before, *(int(c) for c in counts[:-1] or [b"0"]), 0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert not take.exists() and partial_path(take).exists()
    try:  # killed between batches it reads as it is; inside one, it says to repair
        load_performance(partial_path(take))
    except DataError as exc:
        assert "record repair" in str(exc), exc
    fixed = repair(partial_path(take))
    assert fixed.path == take
    t_s, poses, wrist = load_performance(take)
    assert len(t_s) == fixed.frames
    lost = added - fixed.frames
    # the writer hands frames to the OS every FLUSH_S; a killed process loses at most that
    # batch (and the one frame whose line was being formatted)
    print(f"{fmt}: {added} frames added before SIGKILL, {fixed.frames} recovered,"
          f" {lost} lost ({lost / RATE_HZ:.2f} s)")
    assert -1 <= lost <= RATE_HZ * 1.0 + 1, (added, fixed.frames)
    i = np.arange(fixed.frames)
    expected = np.linspace(-10.0, 60.0, 50)[None, :] + (i % 7)[:, None]
    np.testing.assert_allclose(poses, expected, atol=1e-4)
    assert wrist is not None


def test_record_repair_command(tmp_path: Path) -> None:
    from handrig.outputs.recorder import Recorder

    part = partial_path(tmp_path / "take.bvh")
    rec = Recorder(tmp_path / "take.bvh")
    for i in range(10):
        rec.add(i / 200.0, np.zeros(50), np.zeros(4))
    rec.flush()
    assert rec.frames_written == 9  # the newest BVH frame waits for the next one
    part.write_bytes(part.read_bytes()[:-50])
    cli = [sys.executable, "-m", "handrig.cli", "record", "repair"]
    out = subprocess.run([*cli, str(part)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "take.bvh: 8 whole frames" in out.stdout
    assert len(load_performance(tmp_path / "take.bvh")[0]) == 8
    bad = tmp_path / "bad.bvh"
    bad.write_text("garbage")
    out = subprocess.run([*cli, str(bad)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "bad.bvh: no MOTION block" in out.stderr
    assert "Traceback" not in out.stderr


def _descendants(pid: int) -> list[int]:
    """Child processes of ``pid``, recursively (from /proc; Linux)."""
    out: list[int] = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tasks:
        try:
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                kids = [int(k) for k in f.read().split()]
        except OSError:
            continue
        for k in kids:
            out += [k, *_descendants(k)]
    return out


def _frame_lines(path: Path) -> int:
    try:
        data = path.read_bytes()
    except OSError:
        return 0
    return max(0, data.count(b"\n") - data[: data.find(b"MOTION")].count(b"\n") - 3)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_sigkilled_handrig_run_leaves_a_repairable_take(tmp_path: Path) -> None:
    from sim.demo_recording import DEMO_RECORDING

    take = tmp_path / "show.bvh"
    proc = subprocess.Popen(
        [sys.executable, "-m", "handrig.cli", "run", "--glove", f"replay:{DEMO_RECORDING}",
         "--bus", "sim", "--seconds", "60", "--record", str(take)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    kids: list[int] = []
    try:
        deadline = time.monotonic() + 120
        seen = 0
        while seen < RATE_HZ and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)  # a second of the take on disk: two of the writer's batches
            seen = _frame_lines(partial_path(take))
        assert seen >= RATE_HZ, proc.stderr.read() if proc.poll() is not None else seen
        time.sleep(0.7)  # past the next flush
        seen = _frame_lines(partial_path(take))
        kids = _descendants(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        for pid in [proc.pid, *kids]:  # the emulators it started do not outlive the test
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        if proc.poll() is None:
            proc.wait()
    fixed = repair(partial_path(take))
    assert fixed.path == take and fixed.frames >= seen
    t_s, poses, wrist = load_performance(take)
    assert len(t_s) == fixed.frames and wrist is not None
    assert np.all(np.isfinite(poses))
