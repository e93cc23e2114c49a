"""A read timeout while the host's tasks waited for a CPU is the host's
(``BusStats.host_timeouts``), though this process woke on time: the reply's writer (an
emulator, an adapter driver's work) was the one held. The host's CPU pressure is Linux
PSI's ``some`` total (``handrig.realtime.CpuPressure``), looked at when a request goes
out and when its reply is found missing.

The real driver on the in-process emulator through a fake transport, on a FakeClock,
with the pressure read from a file laid out as /proc/pressure/cpu that the test
rewrites; and the real /proc/pressure/cpu under contention."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from handrig.clock import FakeClock
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.link import HOST_STALL_S
from handrig.realtime import PSI_CPU, CpuPressure
from tests.handrig.devices.servo.servo_fakes import EmulatorTransport, PeerBus
from tests.helpers.servos import BAUD, small_rig


def _psi(total_us: int) -> str:
    return (f"some avg10=0.00 avg60=0.00 avg300=0.00 total={total_us}\n"
            "full avg10=0.00 avg60=0.00 avg300=0.00 total=0\n")


class PressedTransport(EmulatorTransport):
    """A wait that finds no reply adds ``pressed_us`` to the host's pressure file (other
    tasks waited for a CPU meanwhile); this process still wakes at the deadline."""

    pressed_us = 0
    psi_file: Path | None = None

    def _receive(self, deadline_s: float, spin_from_s: float | None,
                 spin_until_s: float) -> bytes:
        got = super()._receive(deadline_s, spin_from_s, spin_until_s)
        if not got and self.pressed_us and self.psi_file is not None:
            total = int(self.psi_file.read_text().split("total=")[1].split()[0])
            with open(self.psi_file, "r+") as f:  # in place: the reader's descriptor sees it
                f.write(_psi(total + self.pressed_us))
        return got


def test_a_timeout_while_the_hosts_tasks_waited_for_a_cpu_is_the_hosts(
        tmp_path: Path, request: pytest.FixtureRequest) -> None:
    psi = tmp_path / "cpu"
    psi.write_text(_psi(5_000_000))
    rig = small_rig()
    clock = FakeClock(100.0)
    peer = PeerBus(rig, None)
    transport = PressedTransport(peer, clock, BAUD)
    transport.psi_file = psi
    bus = DynamixelBus("fake:emulator", rig, baud=BAUD, clock=clock, transport=transport)
    assert bus.link.pressure is None  # a fake clock's run looks at no host
    bus.link.pressure = CpuPressure(str(psi))
    request.addfinalizer(bus.link.pressure.close)
    bus.connect()
    assert bus.read_state().all_fresh
    for servo in peer.servos:
        servo.silent_until = math.inf  # nobody answers
    bus.read_state()  # no pressure: the bus's silence
    timeouts = bus.stats.timeouts
    assert timeouts >= 1 and bus.stats.host_timeouts == 0
    transport.pressed_us = int(HOST_STALL_S * 1e6) + 500  # 1.5 ms of tasks waiting
    bus.read_state()
    assert bus.stats.timeouts > timeouts
    assert bus.stats.host_timeouts == bus.stats.timeouts - timeouts
    transport.pressed_us = int(0.8 * HOST_STALL_S * 1e6)  # a little: not a stall
    before, timeouts = bus.stats.host_timeouts, bus.stats.timeouts
    bus.read_state()
    assert bus.stats.timeouts > timeouts and bus.stats.host_timeouts == before


def test_a_missing_or_unreadable_pressure_file_reads_none(tmp_path: Path) -> None:
    assert CpuPressure(str(tmp_path / "none")).total_us() is None
    (tmp_path / "bad").write_text("some avg10=0.00\n")
    bad = CpuPressure(str(tmp_path / "bad"))
    try:
        assert bad.total_us() is None
    finally:
        bad.close()
    assert bad.total_us() is None  # closed: nothing to read


def test_the_hosts_pressure_grows_while_more_processes_spin_than_it_has_cpus() -> None:
    quota = Path("/sys/fs/cgroup/cpu.max")
    if quota.exists() and not quota.read_text().startswith("max"):
        pytest.skip("a CPU quota throttles spinners instead of making them wait")
    pressure = CpuPressure()
    before = pressure.total_us()
    if before is None:
        pytest.skip(f"no {PSI_CPU} here (not Linux, or psi=0)")
    # at nice 19 (the other test lanes' work goes first), one more than the CPUs here
    n = len(os.sched_getaffinity(0)) + 1
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                                 preexec_fn=lambda: os.nice(19)) for _ in range(n)]
    try:
        time.sleep(0.3)
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    after = pressure.total_us()
    pressure.close()
    assert after is not None and after - before >= 20_000  # 20 ms of 0.3 s at least
