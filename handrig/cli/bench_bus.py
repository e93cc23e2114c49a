"""``handrig bench bus``: goal Sync Write + Fast Sync Read cycles against the emulator.

Runs the emulated bus (``sim.dxl_bus.SimBus``, wire timing on) in a separate
process, so its host time does not share this process's interpreter, then runs
the same cycle five ways on it: :class:`~handrig.devices.servo.DynamixelBus` as the loop
calls it (``write_goals_deg`` + ``read_state``), with ``write_and_read``, and
without its reply poll (``spin_s=0``: always asleep until the reply); the plain way
most projects write it
(dynamixel-sdk ``GroupSyncWrite`` + ``GroupSyncRead`` with the SDK's default
timeouts); and the SDK's own Fast Sync Read. Prints cycles per second, the
wire-time limit for that baud and servo count (REFERENCE.md section 3), their
ratio, the median cycle, and host CPU time
per cycle (``time.process_time`` of this process only); then the same cycle with
wire timing off, which is the host's share (driver, emulator, pty wake-ups).

It names the vendor and its SDK on purpose (tests/test_boundaries.py lists it): the
vendor's own way is what it measures the driver against. It stays a command, not in
``bench/``, because ``bench/`` is not installed and users run it on their own machine
(README); nor in ``devices/servo/``, which would then start ``sim/``'s emulator.
"""

from __future__ import annotations

import argparse
import dataclasses
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from handrig.cli._numbers import positive_float, positive_int
from handrig.config.rig import RigConfig, load_rig_config
from handrig.config.rig_files import SHIPPED_RIG
from handrig.devices.servo.models import BAUD_RATES
from handrig.devices.servo.positions import deg_to_ticks
from handrig.devices.servo.wire import goal_write_bytes, read_bytes
from handrig.errors import ConfigError, DeviceError
from handrig.realtime import cpus_awake_around_frames, helper_env, pinned_loop

PLAIN_TIMEOUT_NOTE = "SDK default timeouts"
TARGET_RATIO = 0.92  # the driver's target (issue 36): at least 92 % of the wire-limited rate


def bench_rig(n_servos: int, baud: int, base: RigConfig | None = None) -> RigConfig:
    """The first ``n_servos`` servos of the rig file (at most as many as it has)."""
    rig = base or load_rig_config(SHIPPED_RIG)
    if not 1 <= n_servos <= len(rig.servos):
        raise ConfigError(
            "servo count out of range", key="--servos", value=n_servos,
            allowed=f"1..{len(rig.servos)} (the servos of config/rig.toml)",
        )
    return dataclasses.replace(
        rig, servos=rig.servos[:n_servos], bus=dataclasses.replace(rig.bus, baud=baud)
    )


_EMULATOR = """
import signal, sys
from handrig.realtime import apply_cpus_from_env
apply_cpus_from_env()  # off the driver's CPU, as real servos would be
from handrig.cli.bench_bus import bench_rig
from sim.dxl_bus import SimBus
rig = bench_rig(int(sys.argv[1]), int(sys.argv[2]))
bus = SimBus.from_rig(rig, wire_timing=sys.argv[3] == "1", puppet=sys.argv[4] == "1").start()
print("port:", bus.port_path, flush=True)
signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))
try:
    sys.stdin.read()
finally:
    s = bus.stats
    print(f"emulator: {s.packets} packets, {s.overhead_line()}, "
          f"puppet {'on' if bus.puppet is not None else 'off'}; "
          f"reply late mean {s.late_mean_s * 1e6:.0f} us max {s.late_max_s * 1e6:.0f} us"
          + (f"; STOPPED: {bus.error!r}" if bus.error is not None else ""), flush=True)
    bus.stop()
"""


class EmulatorProcess:
    """The emulated bus in a child process; ``port`` is its pty path."""

    def __init__(
        self, n_servos: int, baud: int, wire_timing: bool = True, puppet: bool = False
    ) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _EMULATOR, str(n_servos), str(baud), str(int(wire_timing)),
             str(int(puppet))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=helper_env(),
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line.startswith("port:"):
            self.proc.kill()
            raise DeviceError(f"the bus emulator did not start (said {line.strip()!r})")
        self.port = line.split(":", 1)[1].strip()

    def close(self) -> str:
        """Stop the emulator; returns its closing line (host overhead figures)."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.close()
        try:
            out = self.proc.stdout.read()
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out = ""
        return out.strip()


@dataclass
class Result:
    name: str
    cycles: int
    wall_s: float
    cpu_s: float
    failed: int  # cycles whose read did not return every servo
    median_s: float  # median cycle time

    @property
    def hz(self) -> float:
        return self.cycles / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def cpu_us(self) -> float:
        return self.cpu_s / self.cycles * 1e6 if self.cycles else float("nan")


def _goals(rig: RigConfig, k: int) -> np.ndarray:
    lo = np.array([s.min_deg for s in rig.servos])
    hi = np.array([s.max_deg for s in rig.servos])
    return lo + (hi - lo) * (0.5 + 0.4 * np.sin(0.01 * k))


def run_ours(
    port: str, rig: RigConfig, baud: int, seconds: float, combined: bool = False,
    spin_s: float | None = None,
) -> Result:
    """``write_goals_deg`` + ``read_state`` per cycle (``combined``: ``write_and_read``);
    ``spin_s``: the driver's reply poll lead (:class:`~handrig.devices.servo.DynamixelBus`;
    None: its default)."""
    from handrig.devices.servo import DynamixelBus

    bus = (DynamixelBus(port, rig, baud=baud, read_fields="position") if spin_s is None
           else DynamixelBus(port, rig, baud=baud, read_fields="position", spin_s=spin_s))
    bus.connect()
    try:
        goals = [_goals(rig, k) for k in range(64)]
        failed = 0
        cycles = 0
        stamps = np.zeros(int(seconds * 20_000) + 64)
        t_end = time.perf_counter() + seconds
        c0 = time.process_time()
        t0 = time.perf_counter()
        while True:
            if combined:
                _, state = bus.write_and_read(goals[cycles & 63])
            else:
                bus.write_goals_deg(goals[cycles & 63])
                state = bus.read_state()
            failed += bool(state.stale.any())
            stamps[cycles] = time.perf_counter()
            cycles += 1
            if cycles & 15 == 0 and (stamps[cycles - 1] >= t_end or cycles >= len(stamps) - 16):
                break
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
    finally:
        bus.close()
    name = "handrig write_and_read (one port write)" if combined else (
        "handrig write_goals_deg + read_state (FSR)")
    if spin_s is not None:
        name = ("handrig write_goals_deg + read_state, no poll" if not spin_s
                else f"handrig write_goals_deg + read_state, poll {spin_s * 1e6:.0f} us")
    return Result(name, cycles, wall, cpu, failed,
                  float(np.median(np.diff(stamps[:cycles]))))


def run_sdk(port: str, rig: RigConfig, baud: int, seconds: float, fast: bool) -> Result:
    """The plain way: SDK GroupSyncWrite + GroupSyncRead, default timeouts."""
    import dynamixel_sdk as sdk

    ph = sdk.PortHandler(port)
    if not ph.openPort() or not ph.setBaudRate(baud):
        raise DeviceError(f"dynamixel-sdk cannot open {port} at {baud} baud")
    pk = sdk.PacketHandler(2.0)
    writer = sdk.GroupSyncWrite(ph, pk, 116, 4)
    reader = sdk.GroupSyncRead(ph, pk, 132, 4)
    ids = [s.id for s in rig.servos]
    cals = rig.servos
    for sid in ids:
        writer.addParam(sid, [0, 8, 0, 0])
        reader.addParam(sid)
    goals = [_goals(rig, k) for k in range(64)]
    failed = 0
    cycles = 0
    stamps = np.zeros(int(seconds * 20_000) + 64)
    t_end = time.perf_counter() + seconds
    c0 = time.process_time()
    t0 = time.perf_counter()
    try:
        while True:
            g = goals[cycles & 63]
            for sid, cal, deg in zip(ids, cals, g, strict=True):
                ticks = deg_to_ticks(cal, float(deg))
                writer.changeParam(sid, [ticks & 0xFF, ticks >> 8 & 0xFF, 0, 0])
            writer.txPacket()
            result = reader.fastSyncRead() if fast else reader.txRxPacket()
            if result != sdk.COMM_SUCCESS:
                failed += 1
            else:
                for sid in ids:
                    reader.getData(sid, 132, 4)
            stamps[cycles] = time.perf_counter()
            cycles += 1
            if cycles & 15 == 0 and (stamps[cycles - 1] >= t_end or cycles >= len(stamps) - 16):
                break
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
    finally:
        ph.closePort()
    name = "plain SDK GroupSyncWrite + " + (
        "GroupSyncRead.fastSyncRead" if fast else "GroupSyncRead (Sync Read)"
    )
    return Result(name, cycles, wall, cpu, failed, float(np.median(np.diff(stamps[:cycles]))))


def wire_limit_hz(n_servos: int, baud: int) -> tuple[int, float]:
    """(bytes per cycle, cycles per second the wire allows) for write + Fast Sync Read."""
    from handrig.devices.servo import cycle_bytes, wire_time_s

    nbytes = cycle_bytes(n_servos, 4)
    return nbytes, 1.0 / wire_time_s(nbytes, baud)


def bench(n_servos: int, baud: int, seconds: float, *, plain: bool = True,
          puppet: bool = False, out: Any = None, keep_cpus_awake: bool = True) -> list[Result]:
    """Run the comparison and print a table; returns the results (ours first).
    ``keep_cpus_awake``: idle CPUs poll instead of halting for the whole bench (the
    request the rig holds around each frame, :class:`handrig.realtime.CpuWake`): every
    way, handrig's and the SDK's, gets it alike."""
    write = (out or sys.stdout).write
    said: list[str] = []
    with cpus_awake_around_frames(keep_cpus_awake, said.append) as wake:
        wake.hold()
        write("CPUs kept awake for every way (a CPU latency request of 0, as the rig holds "
              "around each frame): " + ("yes" if wake.held else
                                        "no" + (f" ({said[0]})" if said else "")) + "\n")
        return _bench(n_servos, baud, seconds, plain=plain, puppet=puppet, write=write)


def _bench(n_servos: int, baud: int, seconds: float, *, plain: bool, puppet: bool,
           write: Any) -> list[Result]:
    rig = bench_rig(n_servos, baud)
    nbytes, limit = wire_limit_hz(n_servos, baud)
    write(
        f"{n_servos} servos at {baud} baud: {nbytes} bytes per cycle (Sync Write "
        f"{goal_write_bytes(n_servos)} + Fast Sync Read and its reply "
        f"{read_bytes(n_servos, 4, True)}) "
        "-> wire limit "
        f"{limit:.0f} Hz ({1e6 / limit:.0f} us per cycle); emulated servos "
        f"{'drive the MuJoCo puppet' if puppet else 'move kinematically'}\n"
    )
    emu = EmulatorProcess(n_servos, baud, puppet=puppet)
    results: list[Result] = []
    try:
        with pinned_loop():  # the driver on its own CPU, the emulator on the others
            results.append(run_ours(emu.port, rig, baud, seconds))
            results.append(run_ours(emu.port, rig, baud, seconds, combined=True))
            results.append(run_ours(emu.port, rig, baud, seconds, spin_s=0.0))
            if plain:
                results.append(run_sdk(emu.port, rig, baud, seconds, fast=False))
                results.append(run_sdk(emu.port, rig, baud, seconds, fast=True))
    finally:
        closing = emu.close()
    write(f"{'way (wire timing on)':<52} {'cycles/s':>9} {'of wire':>8} {'median us':>10} "
          f"{'CPU us/cycle':>13} {'failed':>7}\n")
    for r in results:
        write(f"{r.name:<52} {r.hz:>9.0f} {r.hz / limit:>8.2f} {r.median_s * 1e6:>10.0f} "
              f"{r.cpu_us:>13.0f} {r.failed:>7}\n")
    if plain:
        write("(plain ways run after handrig commissioned the servos: Return Delay Time 0; "
              f"{PLAIN_TIMEOUT_NOTE}; Sync Read's replies are 15N bytes, not in the limit)\n")
        best = max(results[:3], key=lambda r: r.hz)
        sdk = results[-1]
        if sdk.hz > 0 and best.cpu_us > 0:
            write(f"handrig's best way against the SDK's Fast Sync Read: {best.hz / sdk.hz:.2f}x "
                  f"the cycles/s (the wire caps it at {limit / sdk.hz:.2f}x: the SDK reaches "
                  f"{sdk.hz / limit:.2f} of the wire) and {sdk.cpu_us / best.cpu_us:.1f}x less "
                  "CPU a cycle\n")
    if closing:
        write(closing + "\n")
    wire_us = 1e6 / limit
    mean_us = results[0].wall_s / max(results[0].cycles, 1) * 1e6
    write(f"host share: handrig's median cycle is {(results[0].median_s * 1e6 - wire_us):.0f} us "
          f"and its mean (which sets cycles/s) {mean_us - wire_us:.0f} us "
          f"over the wire's {wire_us:.0f} us; {TARGET_RATIO:.2f} of wire allows at most "
          f"{wire_us * (1 / TARGET_RATIO - 1):.0f} us per cycle for the driver, the emulator "
          "and both pty hand-overs\n")
    # where the time goes: the same cycle with the wire taking no time
    emu = EmulatorProcess(n_servos, baud, wire_timing=False, puppet=puppet)
    try:
        with pinned_loop():
            host = run_ours(emu.port, rig, baud, min(seconds, 1.0))
    finally:
        closing = emu.close()
    write(f"host round trip, wire timing off: handrig cycle median {host.median_s * 1e6:.0f} us "
          f"(this process {host.cpu_us:.0f} us CPU/cycle; the rest is the emulator and pty "
          f"wake-ups); {closing}\n")
    return results


def register(sub: Any) -> None:
    bench_parser = sub.choices.get("bench")
    if bench_parser is None:
        bench_parser = sub.add_parser("bench", help="benchmarks against the emulators")
        bench_parser.set_defaults(func=lambda args: (bench_parser.print_help(), 2)[1])
        bench_sub = bench_parser.add_subparsers(dest="bench_command", metavar="BENCH")
        bench_parser.handrig_subparsers = bench_sub  # shared with other bench commands
    else:
        bench_sub = bench_parser.handrig_subparsers
    p: argparse.ArgumentParser = bench_sub.add_parser(
        "bus", help="servo bus cycle rate vs the wire-time limit, against the emulator"
    )
    p.add_argument("--servos", type=positive_int, default=20, help="servos on the bus (default 20)")
    p.add_argument("--baud", type=positive_int, default=4_000_000,
                   help="baud rate (default 4000000)")
    p.add_argument("--seconds", type=positive_float, default=3.0,
                   help="seconds per way (default 3)")
    p.add_argument("--no-plain", action="store_true", help="skip the plain SDK ways")
    p.add_argument("--puppet", action="store_true",
                   help="servos drive the MuJoCo puppet (default: they move kinematically)")
    p.add_argument("--keep-cpus-awake", action=argparse.BooleanOptionalAction, default=True,
                   help="idle CPUs poll instead of halting during the bench, as the rig "
                        "keeps them around each frame (default: on)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.baud not in BAUD_RATES:
        raise ConfigError("unsupported baud rate", key="--baud", value=args.baud,
                          allowed=", ".join(str(b) for b in BAUD_RATES))
    if not 0.1 <= args.seconds <= 600:
        raise ConfigError("out of range", key="--seconds", value=args.seconds,
                          allowed="0.1..600")
    bench(args.servos, args.baud, args.seconds, plain=not args.no_plain, puppet=args.puppet,
          keep_cpus_awake=args.keep_cpus_awake)
    return 0
