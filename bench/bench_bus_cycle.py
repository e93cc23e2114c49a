"""Where a bus cycle's time goes beyond the wire: the driver against the emulator, traced.

The driver (goal Sync Write + Fast Sync Read, as ``handrig bench bus`` runs it) and
the emulated bus (``sim.dxl_bus.SimBus``, wire timing on, in a child process as
``handrig sim-bus`` runs it) each stamp their events on CLOCK_MONOTONIC
(``time.perf_counter`` on Linux, one time line for both processes):

- the driver: each request's ``os.write`` returned, each reply's last bytes read;
- the emulator: each request read off the pty (``t_rx``), each reply's wire
  instant (what the wire model allows) and its ``os.write`` returned.

Per cycle (median and mean over the run, microseconds: the mean sets cycles/s)::

    to emulator   request written -> the emulator has read it (the pty hop, its wake-up)
    wire          the emulator's t_rx -> the reply's wire instant (the wire model's time)
    late          the reply's wire instant -> written to the pty
    to driver     written -> the driver has read the reply's last bytes
    driver        the reply read -> the next Sync Write written (decode, loop, encode)

and the CPU each process spent per cycle (``/proc/PID/stat``: utime + stime). The
timing wraps methods every version has (``SimBus._send``, ``SimBus._emit``, the
transport's ``write`` and ``_receive``), so ``PYTHONPATH=/tmp/base python
bench/bench_bus_cycle.py`` traces an older tree. Tracing adds a few microseconds
per event on both sides; it logs into arrays allocated once, so the garbage collector
does not run in the timed loop (printed: ``gc``), as it does not in ``handrig bench
bus``'s (a first version logged tuples to lists: 7 collections, 32 ms, in 1.5 s).

HANDRIG_BENCH_SECONDS (default 3) seconds a way; HANDRIG_BENCH_SPIN_US: the
driver's reply poll leads to run (default ``default,0``); HANDRIG_BENCH_PUPPET=1:
the MuJoCo puppet drives the servos (default: kinematic).

Then one pty hop alone (``HANDRIG_BENCH_HOPS``, default 3000; 0: skipped): a writer
process (the emulator's place: the other CPU, SCHED_FIFO where allowed) writes 168
bytes every 0.8 ms; the reader (the driver's place, this CPU) either sleeps in
``select`` until they are readable or polls with non-blocking reads; printed: write ->
read p50 / p90 / p99 for each. (A poll does not starve the kernel worker that carries
the bytes over: n_tty's read waits for it when it is queued.)
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_CHILD = """
import json, signal, sys, time
import numpy as np
from handrig.realtime import apply_cpus_from_env
apply_cpus_from_env()
from handrig.cli.bench_bus import bench_rig
from sim.dxl_bus import SimBus
from sim.dxl_line import BITS_PER_BYTE
n, baud, puppet = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3] == "1"
bus = SimBus.from_rig(bench_rig(n, baud), wire_timing=True, puppet=puppet)
# (t_rx, frame_len, wire instant of the first reply or 0, emitted or 0), in an array
# allocated once: a list of tuples would wake the garbage collector for pauses of ms
events = np.zeros((400_000, 4))
count = [0]
send, emit = bus._send, bus._emit
emitted = [0.0]
def traced_send(replies, frame_len, t_rx):
    free = bus._bus_free_at
    emitted[0] = 0.0
    send(replies, frame_len, t_rx)
    byte_s = BITS_PER_BYTE / (bus._line_baud or bus.baud())
    wire = 0.0
    if replies:
        r = replies[0]
        wire = (max(t_rx, free) + frame_len * byte_s + r.return_delay_s + r.fault_delay_s
                + len(r.data) * byte_s)
    k = count[0] % len(events)
    events[k, 0], events[k, 1], events[k, 2], events[k, 3] = t_rx, frame_len, wire, emitted[0]
    count[0] += 1
def traced_emit(data):
    emit(data)
    if not emitted[0]:
        emitted[0] = time.perf_counter()
bus._send, bus._emit = traced_send, traced_emit
bus.start()
print("port:", bus.port_path, flush=True)
signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))
for line in sys.stdin:
    print(json.dumps(events[: min(count[0], len(events))].tolist()), flush=True)
    count[0] = 0
bus.stop()
"""


@dataclass
class Run:
    cycles: int
    wall_s: float
    cpu_driver_s: float
    cpu_emulator_s: float
    writes: np.ndarray  # (written at, bytes)
    reads: np.ndarray  # (read at, bytes)
    events: list[list[float]]
    collections: int  # garbage collections in the driver's timed loop


def tree_root() -> str:
    """The tree whose ``handrig`` this process imported: the emulator's child runs there
    (``python -c`` puts its working directory first on ``sys.path``, ahead of
    ``PYTHONPATH``: run from another tree, the child would import that tree's ``sim``)."""
    import handrig

    return str(Path(handrig.__file__).resolve().parents[1])


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class _Log:
    """(clock time, bytes) rows in an array allocated once (no garbage to collect)."""

    def __init__(self, rows: int) -> None:
        self.rows = np.zeros((rows, 2))
        self.n = 0

    def add(self, t: float, nbytes: int) -> None:
        if self.n < len(self.rows):
            self.rows[self.n, 0] = t
            self.rows[self.n, 1] = nbytes
            self.n += 1

    def taken(self) -> np.ndarray:
        return self.rows[: self.n]


def _trace_driver(bus: object, rows: int) -> tuple[_Log, _Log]:
    """Wrap the driver's transport: its writes and reads, logged."""
    t = bus.transport  # type: ignore[attr-defined]
    writes, reads = _Log(rows), _Log(rows)
    write, receive = t.write, t._receive
    clock = time.perf_counter

    def traced_write(data: bytes) -> None:
        write(data)
        writes.add(clock(), len(data))

    def traced_receive(*args: object, **kw: object) -> bytes:
        chunk = receive(*args, **kw)
        reads.add(clock(), len(chunk))
        return chunk

    t.write, t._receive = traced_write, traced_receive
    return writes, reads


def _run(port: str, proc: subprocess.Popen[str], n: int, baud: int, seconds: float,
         spin_s: float | None) -> Run:
    from handrig.cli.bench_bus import _goals, bench_rig
    from handrig.devices.servo import DynamixelBus
    from handrig.realtime import pinned_loop

    rig = bench_rig(n, baud)
    kw = {} if spin_s is None else {"spin_s": spin_s}
    bus = DynamixelBus(port, rig, baud=baud, read_fields="position", **kw)  # type: ignore[arg-type]
    bus.connect()
    goals = [_goals(rig, k) for k in range(64)]
    assert proc.stdin is not None and proc.stdout is not None
    try:
        proc.stdin.write("\n")  # drop commissioning's events
        proc.stdin.flush()
        proc.stdout.readline()
        writes, reads = _trace_driver(bus, int(seconds * 8000) + 1000)
        cycles = 0
        collections = [0]  # the garbage collector's runs in the timed loop (this process)

        def counted(phase: str, info: dict[str, int]) -> None:
            collections[0] += phase == "stop"

        gc.callbacks.append(counted)
        with pinned_loop():
            c_me, c_emu = time.process_time(), _cpu_s(proc.pid)
            t0 = time.perf_counter()
            t_end = t0 + seconds
            while True:
                bus.write_goals_deg(goals[cycles & 63])
                bus.read_state()
                cycles += 1
                if cycles & 15 == 0 and time.perf_counter() >= t_end:
                    break
            wall = time.perf_counter() - t0
            c_me, c_emu = time.process_time() - c_me, _cpu_s(proc.pid) - c_emu
        gc.callbacks.remove(counted)
        proc.stdin.write("\n")
        proc.stdin.flush()
        events = json.loads(proc.stdout.readline())
    finally:
        bus.close()
    return Run(cycles, wall, c_me, c_emu, writes.taken(), reads.taken(), events,
               collections[0])


def _breakdown(run: Run, sw_len: int) -> dict[str, np.ndarray]:
    """Per cycle: the five parts, microseconds (cycles whose events all matched)."""
    writes, reads = run.writes, run.reads
    ev = np.array(run.events)
    sw_w = writes[writes[:, 1] == sw_len, 0]  # the goal Sync Writes, written at
    sw_rx = ev[(ev[:, 1] == sw_len) & (ev[:, 2] == 0), 0]
    fsr = ev[ev[:, 2] > 0]
    parts: dict[str, list[float]] = {k: [] for k in
                                     ("to emulator", "wire", "late", "to driver", "driver",
                                      "cycle")}
    j = k = r = 0
    for i in range(len(sw_w) - 1):
        t_w = sw_w[i]
        while j < len(sw_rx) and sw_rx[j] < t_w:
            j += 1
        if j >= len(sw_rx):
            break
        while k < len(fsr) and fsr[k, 0] < sw_rx[j]:
            k += 1
        if k >= len(fsr):
            break
        _, _, wire_at, emit_at = fsr[k]
        while r < len(reads) and reads[r, 0] < emit_at:
            r += 1
        # the reply's last bytes: the last read before the next Sync Write
        last = r
        while last + 1 < len(reads) and reads[last + 1, 0] < sw_w[i + 1]:
            last += 1
        if last >= len(reads) or not emit_at or reads[last, 0] > sw_w[i + 1]:
            continue
        got = reads[last, 0]
        parts["to emulator"].append(sw_rx[j] - t_w)
        parts["wire"].append(wire_at - sw_rx[j])
        parts["late"].append(emit_at - wire_at)
        parts["to driver"].append(got - emit_at)
        parts["driver"].append(sw_w[i + 1] - got)
        parts["cycle"].append(sw_w[i + 1] - t_w)
    return {k: np.array(v) * 1e6 for k, v in parts.items()}


def _hop(polled: bool, count: int) -> np.ndarray:
    """Write -> read of one pty hop, ``count`` times, microseconds (see the module doc)."""
    import select
    import tty

    from handrig.realtime import cpu_split
    from sim.dxl_line import REALTIME_PRIORITY, try_realtime

    loop_cpu, others = cpu_split()
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    os.set_blocking(slave, False)
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the writer: the emulator's place
        try:
            if others:
                os.sched_setaffinity(0, others)
            try_realtime(REALTIME_PRIORITY)
            stamps = np.zeros(count)
            for i in range(count):
                t_next = time.perf_counter() + 0.0008
                while time.perf_counter() < t_next:
                    pass
                stamps[i] = time.perf_counter()
                os.write(master, bytes(168))
                select.select([master], [], [], 0.1)  # the reader's acknowledgement
                os.read(master, 64)
            os.write(w, stamps.tobytes())
        finally:
            os._exit(0)
    before = os.sched_getaffinity(0)
    if loop_cpu is not None:
        os.sched_setaffinity(0, {loop_cpu})
    got = np.zeros(count)
    try:
        for i in range(count):
            while True:
                if not polled:
                    select.select([slave], [], [], 1.0)
                try:
                    if os.read(slave, 4096):
                        break
                except BlockingIOError:
                    pass
            got[i] = time.perf_counter()
            os.write(slave, b"a")
        raw = b""
        while len(raw) < 8 * count:
            raw += os.read(r, 1 << 20)
    finally:
        os.waitpid(pid, 0)
        os.sched_setaffinity(0, before)
        for fd in (master, slave, r, w):
            os.close(fd)
    return (got - np.frombuffer(raw, np.float64)) * 1e6


def main() -> None:
    from handrig.cli.bench_bus import wire_limit_hz
    from handrig.devices.servo.wire import goal_write_bytes
    from handrig.realtime import helper_env

    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", "3"))
    spins = os.environ.get("HANDRIG_BENCH_SPIN_US", "default,0").split(",")
    puppet = os.environ.get("HANDRIG_BENCH_PUPPET", "0") == "1"
    n, baud = 20, 4_000_000
    _, limit = wire_limit_hz(n, baud)
    print(f"{n} servos at {baud} baud, wire limit {limit:.0f} Hz ({1e6 / limit:.0f} us a "
          f"cycle), puppet {'on' if puppet else 'off'}, load {os.getloadavg()[0]:.1f}")
    print(f"{'driver poll lead':<18} {'cycles/s':>8} {'of wire':>7} | median / mean us: "
          f"{'to emulator':>11} {'wire':>9} {'late':>7} {'to driver':>9} {'driver':>9} "
          f"{'cycle':>9} | CPU us/cycle driver, emulator")
    for spin in spins:
        spin_s = None if spin.strip() == "default" else float(spin) * 1e-6
        proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(n), str(baud),
                                 str(int(puppet))], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True, env=helper_env(),
                                cwd=tree_root())
        assert proc.stdout is not None and proc.stdin is not None
        line = proc.stdout.readline()
        if not line.startswith("port:"):
            proc.kill()
            raise SystemExit(f"the emulator did not start: {line!r}")
        try:
            run = _run(line.split(":", 1)[1].strip(), proc, n, baud, seconds, spin_s)
        finally:
            proc.stdin.close()
            proc.wait(timeout=10)
        parts = _breakdown(run, goal_write_bytes(n))
        hz = run.cycles / run.wall_s
        cells = " ".join(
            f"{np.median(v):>4.0f} / {np.mean(v):<4.0f}" if len(v) else "   -   "
            for k, v in parts.items())
        print(f"{spin:<18} {hz:>8.0f} {hz / limit:>7.2f} | {cells} | "
              f"{run.cpu_driver_s / run.cycles * 1e6:.0f}, "
              f"{run.cpu_emulator_s / run.cycles * 1e6:.0f}; gc {run.collections}")
    hops = int(os.environ.get("HANDRIG_BENCH_HOPS", "3000"))
    for polled in (False, True) if hops else ():
        us = _hop(polled, hops)
        print(f"one pty hop, the reader {'polling' if polled else 'asleep in select'}: "
              f"p50 {np.median(us):.0f} us, p90 {np.percentile(us, 90):.0f} us, "
              f"p99 {np.percentile(us, 99):.0f} us")


if __name__ == "__main__":
    main()
