"""A live view's page that stopped reading: the frames queued for it, and the run's exit.

Each run launches ``handrig run --bus sim --glove replay:DEMO --frames 40000 --json
--view 127.0.0.1:0`` and opens the page's socket from this process as a page that
stops reading does (a frozen tab, a phone whose network went away): a raw WebSocket
client with a 4 kB receive buffer. It reads the scene and a few frames, then

* reads nothing for ``STALL`` seconds (``HANDRIG_BENCH_STALL_S``, default 25: left to
  itself the kernel grows a socket's send buffer to 4 MB, about 20 s of frames), then
  reads again: the frames that were queued for it arrive back to back (the burst ends
  at the first gap over 15 ms, when live frames come again, 33 ms apart). Printed:
  their count and kilobytes, and the seconds a link that carries just the view (30
  frames a second) needs to get through them before the page is live again;
* stops reading again for ``STALL`` seconds, then Ctrl-C (SIGINT to the run's process
  group): seconds from the signal to the run's exit. The same run with a page that
  reads on is the reference (``page reading``).

``--base COMMIT`` runs every case on that commit too (a temporary git worktree, same
Python and packages, ``PYTHONPATH`` set to each side's tree), alternating run by run;
``--runs N`` (default 2, ``HANDRIG_BENCH_RUNS``) runs per side; median and worst.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from bench.compare import base_worktree, resolve_commit
from bench.rig_steps import cpu_times, steal_percent

ROOT = Path(__file__).resolve().parent.parent
RECORDING = "config/recordings/demo_glove.csv"
GAP_S = 0.015  # live frames come 33 ms apart; queued ones back to back
VIEW_RATE_HZ = 30.0


class Page:
    """A WebSocket client on a raw socket that reads only when asked."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        self.sock.settimeout(10)
        self.sock.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n".encode())
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            self.buf += self._recv()
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        if not head.startswith(b"HTTP/1.1 101"):
            raise RuntimeError(f"the view refused the socket: {head[:200]!r}")

    def _recv(self) -> bytes:
        data = self.sock.recv(65536)
        if not data:
            raise EOFError("the view closed the socket")
        return data

    def _need(self, n: int) -> bytes:
        while len(self.buf) < n:
            self.buf += self._recv()
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def message(self) -> tuple[int, dict]:
        """The next message from the server (opcode, JSON of a text message)."""
        b0, b1 = self._need(2)
        n = b1 & 0x7F
        if n == 126:
            n = int.from_bytes(self._need(2), "big")
        elif n == 127:
            n = int.from_bytes(self._need(8), "big")
        payload = self._need(n)
        opcode = b0 & 0x0F
        return opcode, (json.loads(payload) if opcode == 1 else {})

    def frame(self) -> tuple[dict, int]:
        """The next frame (pings skipped: this page never answers them) and its size."""
        while True:
            opcode, msg = self.message()
            if opcode == 1 and msg.get("type") == "frame":
                return msg, len(json.dumps(msg))


def start_run(root: Path) -> tuple[subprocess.Popen[str], int]:
    argv = [sys.executable, "-m", "handrig.cli", "run", "--bus", "sim", "--glove",
            f"replay:{ROOT / RECORDING}", "--frames", "40000", "--json", "--view",
            "127.0.0.1:0"]
    proc = subprocess.Popen(argv, cwd=root, env=dict(os.environ, PYTHONPATH=str(root)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    assert proc.stderr is not None
    while True:
        line = proc.stderr.readline()
        if not line:
            proc.kill()
            raise SystemExit(f"the run in {root} ended before its view: "
                             f"{proc.communicate(timeout=10)[1][-2000:]}")
        if line.startswith("view: "):
            return proc, int(line.split()[1].rsplit(":", 1)[1].strip("/"))


def sigint_to_exit(proc: subprocess.Popen[str]) -> float:
    t0 = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    proc.communicate(timeout=120)
    return time.monotonic() - t0


def stalled_run(root: Path, stall_s: float) -> dict[str, float]:
    proc, port = start_run(root)
    try:
        page = Page(port)
        for _ in range(5):
            page.frame()
        time.sleep(stall_s)
        burst: list[tuple[dict, int]] = [page.frame()]
        last = time.monotonic()
        while True:
            got = page.frame()
            now = time.monotonic()
            if now - last > GAP_S:
                break  # a live frame, after the queued ones
            burst.append(got)
            last = now
        frames = len(burst)
        queued_kb = sum(size for _, size in burst) / 1000
        time.sleep(stall_s)
        took = sigint_to_exit(proc)
        page.sock.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return {"frames queued for the page": frames, "kB queued": queued_kb,
            "s to catch up at 30 frames/s": frames / VIEW_RATE_HZ,
            "SIGINT to exit, page stalled (s)": took}


def reading_run(root: Path) -> dict[str, float]:
    proc, port = start_run(root)
    try:
        page = Page(port)
        for _ in range(30):
            page.frame()
        page.sock.setblocking(False)
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        while proc.poll() is None:  # reads on while the run eases down
            try:
                page.sock.recv(65536)
            except BlockingIOError:
                time.sleep(0.002)
            except OSError:
                break
        proc.communicate(timeout=120)
        took = time.monotonic() - t0
        page.sock.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return {"SIGINT to exit, page reading (s)": took}


def measure(sides: dict[str, Path], runs: int, stall_s: float) -> None:
    figures: dict[tuple[str, str], list[float]] = {}
    for k in range(runs):
        for side in (list(sides) if k % 2 == 0 else list(sides)[::-1]):
            for run in (lambda r: stalled_run(r, stall_s), reading_run):
                for name, value in run(sides[side]).items():
                    figures.setdefault((name, side), []).append(value)
    names = list(dict.fromkeys(name for name, _ in figures))
    width = max(len(n) for n in names)
    print(f"  {'case':<{width}}" + "".join(f"  {s + ' median':>12} {'worst':>7}" for s in sides))
    for name in names:
        cells = [figures[(name, s)] for s in sides]
        print(f"  {name:<{width}}" + "".join(
            f"  {statistics.median(xs):12.2f} {max(xs):7.2f}" for xs in cells))


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m bench view_exit",
                                description=__doc__.split("\n")[0] if __doc__ else None)
    p.add_argument("--base", default=None, metavar="COMMIT",
                   help="also run on this commit (a temporary worktree), alternating")
    p.add_argument("--runs", type=int, default=int(os.environ.get("HANDRIG_BENCH_RUNS", 2)),
                   help="runs per side (default 2)")
    return p.parse_args(sys.argv[1:] if argv is None else argv)


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    if args.runs < 1:
        raise SystemExit("--runs must be at least 1")
    stall_s = float(os.environ.get("HANDRIG_BENCH_STALL_S", 25))
    load0, before = os.getloadavg(), cpu_times()
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                          capture_output=True, text=True).stdout.strip()
    what = (f"200 Hz run on the simulated rig with --view; the page stalls {stall_s:g} s "
            f"twice; {args.runs} runs per side")
    if args.base is None:
        print(f"this tree ({head}); {what}")
        measure({"new": ROOT}, args.runs, stall_s)
    else:
        sha = resolve_commit(args.base)
        with base_worktree(sha, prefix="bench_view_exit_") as base_root:
            print(f"base {sha[:9]} (a worktree) against new: this tree ({head}); {what}, "
                  "alternating")
            measure({"base": base_root, "new": ROOT}, args.runs, stall_s)
    print(f"load average {load0[0]:.2f} at the start, {os.getloadavg()[0]:.2f} at the end; "
          f"steal {steal_percent(before, cpu_times())} %")


if __name__ == "__main__":
    main()
