"""The pty's own delivery time: a request written to the servo port until the emulator can read it.

A simulated rig's driver and bus emulator talk through a pty. Linux moves the bytes
from one end to the other in a kernel worker (an ordinary, SCHED_OTHER thread),
not in the writer's ``write``: when that worker runs late (on this shared 2-core
machine, for some requests in a thousand, more as other work loads it), the
request reaches the emulator milliseconds after the driver sent it. The emulator
then times its reply from the late arrival (as it must: it cannot see when the
bytes were written), and a read whose deadline is the next goal write times out
(issue 36: each of the 16 timeouts examined in three instrumented plain runs was
a request that reached the emulator 2.0-4.3 ms after it was written, against a
p50 of 0.02 ms; the emulator's wire schedule was idle and its reply left on time).

This measures that delivery alone, with the processes set up as a run sets them
up: the writer on the loop's CPU at the loop's SCHED_FIFO priority, writing a goal
Sync Write (114 bytes) and 0.2 ms later a Fast Sync Read request (24 bytes) every
5 ms; the reader at the emulator bus thread's priority, waiting in ``poll`` with
its 2 ms idle timeout. It prints write -> readable p50 / p90 / p99 / max and how
many requests came later than the slack a half read has in ``handrig demo``
(its deadline, 4.2 ms after the request, less its 2.05 ms on the 1 Mbps wire).

``HANDRIG_BENCH_SECONDS``: the run's length (default 5 s). ``HANDRIG_BENCH_PTY_HOGS=N``:
then the same beside N busy processes at normal priority, and N at SCHED_IDLE (on
2026-12-05, load 3.5, neither moved the figures the same way twice: the late
deliveries come and go with the machine's other work).
"""

from __future__ import annotations

import bisect
import contextlib
import multiprocessing as mp
import os
import select
import time
import tty
from collections.abc import Iterator
from multiprocessing.queues import Queue

from handrig.config.rig import RigConfig
from handrig.realtime import cpu_split
from sim.dxl_line import REALTIME_PRIORITY, try_realtime

PERIOD_S = 0.005  # a 200 Hz glove: a goal write every frame
WRITE_BYTES = 114  # goal Sync Write, 20 servos (14 + 5N)
REQUEST_BYTES = 24  # Fast Sync Read request, 10 servos (14 + N)
REQUEST_AFTER_S = 0.0002  # the request goes out this long after the write (as in the demo)
POLL_MS = 2.0  # the emulator's idle wait with the puppet (sim.dxl_bus.KINEMATIC_STEP_S)
SLACK_S = 0.0042 - 0.00205  # a half read's deadline in the demo less its wire time


def _reader(fd: int, seconds: float, out: Queue[list[float]]) -> None:
    try_realtime(REALTIME_PRIORITY)
    poll = select.poll()
    poll.register(fd, select.POLLIN)
    got: list[float] = []
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        if poll.poll(POLL_MS):
            os.read(fd, 65536)
            got.append(time.perf_counter())
    out.put(got)


def _writer(path: str, seconds: float, out: Queue[list[float]]) -> None:
    loop_cpu, _ = cpu_split()
    if loop_cpu is not None:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(0, {loop_cpu})
    try_realtime(RigConfig().loop.realtime_priority)
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    sent: list[float] = []
    t = time.perf_counter() + 0.05
    end = t + seconds - 0.15
    while t < end:
        while (left := t - time.perf_counter()) > 0:
            time.sleep(max(0.0, left - 1e-4))
        os.write(fd, b"\0" * WRITE_BYTES)
        time.sleep(REQUEST_AFTER_S)
        os.write(fd, b"\0" * REQUEST_BYTES)
        sent.append(time.perf_counter())
        t += PERIOD_S
    os.close(fd)
    out.put(sent)


def delivery_ms(seconds: float) -> list[float]:
    """Write -> readable of each request, ms, sorted."""
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    path = os.ttyname(slave)
    ctx = mp.get_context("fork")
    got_q: Queue[list[float]] = ctx.Queue()
    sent_q: Queue[list[float]] = ctx.Queue()
    reader = ctx.Process(target=_reader, args=(master, seconds, got_q))
    writer = ctx.Process(target=_writer, args=(path, seconds, sent_q))
    reader.start()
    writer.start()
    got, sent = got_q.get(), sent_q.get()
    reader.join()
    writer.join()
    os.close(master)
    os.close(slave)
    out = []
    for t in sent:
        i = bisect.bisect_left(got, t)
        if i < len(got):
            out.append((got[i] - t) * 1e3)
    return sorted(out)


@contextlib.contextmanager
def _hogs(n: int, idle: bool) -> Iterator[None]:
    """``n`` busy processes (SCHED_IDLE when ``idle``) for the block."""
    procs = [mp.get_context("fork").Process(target=_spin, args=(idle,), daemon=True)
             for _ in range(n)]
    for p in procs:
        p.start()
    try:
        yield
    finally:
        for p in procs:
            p.terminate()
            p.join()


def _spin(idle: bool) -> None:
    if idle:
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    while True:
        pass


def _line(label: str, ms: list[float]) -> str:
    n = len(ms)
    if not n:
        return f"  {label:<34} no request delivered"
    late = sum(x > SLACK_S * 1e3 for x in ms)
    return (f"  {label:<34} {n:>5} {ms[n // 2]:>7.3f} {ms[int(0.9 * n)]:>7.3f} "
            f"{ms[min(n - 1, int(0.99 * n))]:>7.3f} {ms[-1]:>7.3f} {late:>6} ({late / n:.1%})")


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 5.0))
    hogs = int(os.environ.get("HANDRIG_BENCH_PTY_HOGS", 0))
    print(f"pty delivery, request written -> readable by the emulator, ms ({seconds:.0f} s, "
          f"a request every {PERIOD_S * 1e3:.0f} ms; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs):")
    print(f"  {'':<34} {'n':>5} {'p50':>7} {'p90':>7} {'p99':>7} {'max':>7} "
          f"  > {SLACK_S * 1e3:.2f} ms (a half read's slack in the demo)")
    print(_line("as is", delivery_ms(seconds)))
    if hogs:
        with _hogs(hogs, idle=False):
            print(_line(f"+ {hogs} busy processes, normal", delivery_ms(seconds)))
        with _hogs(hogs, idle=True):
            print(_line(f"+ {hogs} busy processes, SCHED_IDLE", delivery_ms(seconds)))
    print("  (a request later than the slack is a read timeout in a plain run: the kernel's "
          "pty worker ran late; see the module's docstring)")


if __name__ == "__main__":
    main()
