"""The bus emulator's reply path from outside: host time per packet with the puppet on.

The emulated bus (``sim.dxl_bus.SimBus``, wire timing on, the MuJoCo puppet
driving its servos) runs in a child process, as ``handrig sim-bus`` does; this
process drives it with handrig's driver (goal Sync Write + Fast Sync Read, as
fast as the wire allows) and then with the plain dynamixel-sdk's Fast Sync Read.
The child times every packet from its last byte read to its reply ready (the
moment the bus starts waiting for the reply's wire instant) and prints p50, p99,
mean and max, with how late replies left after their wire instant. The timing
wraps ``SimBus._send``, which every version of the emulator has, so the same file
measures an older tree: ``PYTHONPATH=/tmp/base python bench/bench_emulator.py``
runs the emulator and driver of the tree at /tmp/base
(``git worktree add /tmp/base 22013e1``).

HANDRIG_BENCH_SECONDS (default 3) seconds per way; HANDRIG_BENCH_RIG: ``20`` (the
first 20 servos of config/rig.toml at 4 Mbps, default) or ``two_hands`` (the
``puppet_two_hands`` preset: 40 servos on one bus at 4 Mbps).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

_CHILD = """
import signal, sys, time
import numpy as np
from handrig.realtime import apply_cpus_from_env
apply_cpus_from_env()
from handrig.pose.robot_rig import load_rig
from handrig.cli.bench_bus import bench_rig
from sim.dxl_bus import SimBus
which, baud = sys.argv[1], int(sys.argv[2])
rig = load_rig("puppet_two_hands") if which == "two_hands" else bench_rig(int(which), baud)
bus = SimBus.from_rig(rig, wire_timing=True, puppet=True)
try:
    from sim.dxl_fast import PACKET_PATH
except ImportError:  # a tree from before the compiled path
    PACKET_PATH = "pure Python"
samples = []
send = bus._send
def timed(replies, frame_len, t_rx):
    samples.append(bus.clock.now() - t_rx)
    send(replies, frame_len, t_rx)
bus._send = timed
bus.start()
print("port:", bus.port_path, flush=True)
signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))
for line in sys.stdin:
    us = np.array(samples or [0.0]) * 1e6
    samples.clear()
    s = bus.stats
    print(f"  emulator: {len(us)} packets, host time per packet "
          f"p50 {np.percentile(us, 50):.0f} us, "
          f"p99 {np.percentile(us, 99):.0f} us, mean {us.mean():.0f} us, max {us.max():.0f} us; "
          f"replies late mean {s.late_mean_s * 1e6:.0f} us ({PACKET_PATH} packet path)", flush=True)
    s.late_total_s, s.replies = 0.0, 0
bus.stop()
"""


def tree_root() -> str:
    """The tree whose ``handrig`` this process imported: the emulator's child runs there
    (``python -c`` puts its working directory first on ``sys.path``, ahead of
    ``PYTHONPATH``: run from another tree, the child would import that tree's ``sim``)."""
    import handrig

    return str(Path(handrig.__file__).resolve().parents[1])


def _child(which: str, baud: int) -> tuple[subprocess.Popen[str], str]:
    from handrig.realtime import helper_env

    proc = subprocess.Popen([sys.executable, "-c", _CHILD, which, str(baud)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env=helper_env(), cwd=tree_root())
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith("port:"):
        proc.kill()
        raise SystemExit(f"the emulator did not start: {line!r}")
    return proc, line.split(":", 1)[1].strip()


def _figures(proc: subprocess.Popen[str]) -> str:
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.write("\n")
    proc.stdin.flush()
    return proc.stdout.readline().rstrip()


def main() -> None:
    from handrig.cli.bench_bus import bench_rig, run_ours, run_sdk, wire_limit_hz
    from handrig.pose.robot_rig import load_rig
    from handrig.realtime import pinned_loop

    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", "3"))
    which = os.environ.get("HANDRIG_BENCH_RIG", "20")
    baud = 4_000_000
    rig = load_rig("puppet_two_hands") if which == "two_hands" else bench_rig(int(which), baud)
    n = len(rig.servos)
    _, limit = wire_limit_hz(n, baud)
    print(f"{n} servos at {baud} baud, MuJoCo puppet on, wire limit {limit:.0f} Hz "
          f"(load {os.getloadavg()[0]:.1f})")
    proc, port = _child(which, baud)
    try:
        time.sleep(0.5)  # the puppet's first steps
        _figures(proc)
        with pinned_loop():
            ours = run_ours(port, rig, baud, seconds)
        print(f"handrig write_goals_deg + read_state: {ours.hz:.0f} cycles/s, "
              f"{ours.hz / limit:.2f} of wire, median {ours.median_s * 1e6:.0f} us, "
              f"failed {ours.failed}")
        print(_figures(proc))
        with pinned_loop():
            sdk = run_sdk(port, rig, baud, seconds, fast=True)
        print(f"plain SDK fastSyncRead: {sdk.hz:.0f} cycles/s, {sdk.hz / limit:.2f} of wire, "
              f"failed {sdk.failed}; handrig / SDK {ours.hz / max(sdk.hz, 1e-9):.2f}x")
        print(_figures(proc))
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait(timeout=10)
    _ = np  # numpy is the child's


if __name__ == "__main__":
    main()
