"""A long run of the live rig with faults on: ``python -m bench soak [--seconds S]``.

The rig as ``handrig run --bus sim`` builds it (the app factory: ``handrig
sim-bus`` with the MuJoCo puppet and wire timing, the real SerialGlove reader,
pipeline, Dynamixel driver and recorder) runs for 10 minutes by default, with:

- on the bus: 1 % of replies dropped, 0.1 % corrupted, 0.1 % with a wrong ID,
  one servo overloaded once (the driver reboots it);
- on the host: a 50 ms stall of the loop thread every minute;
- on the glove (an emulator in its own process): bursts of garbage, frames with
  a bad CRC, and dropouts longer than the glove timeout;
- a CSV recording of the full pose streamed to disk;
- VMC on: OSC bundles of the full pose to a UDP receiver in this process, counted;
- with ``--mute ID@FROM-UNTIL``: one servo stops answering (it still hears and
  obeys) from FROM to UNTIL seconds, e.g. ``--mute 7@120-240``.

It prints the cycles, the faults injected (the emulators' counts) against the
faults counted (the driver's and glove reader's), the recoveries (reads in a row
with a stale servo, ended) and their length in cycles, the goals decoded on the
bus side outside the rig's limits (must be 0), the hottest each servo got (as the
driver read it) and the servos held by the ``[silence]`` tiers, the loop process's RSS at the
start and end with its growth in MB per hour (a least-squares slope after a
warm-up; target under 5 MB/h with recording on), and whether torque was off at
the end. ``python -m bench`` alone does not run it (it is long): name it.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from handrig.app import factory as app
from handrig.app import parts as app_parts
from handrig.app.session_exit import torque_is_off
from handrig.clock import MonotonicClock
from handrig.errors import HandrigError
from handrig.realtime import pinned_loop, realtime_priority
from sim.demo_recording import DEMO_RECORDING

DEFAULT_SECONDS = 600.0
BUS_FAULTS = "drop=0.01,corrupt=0.001,wrong_id=0.001"
STALL_S = 0.05
STALL_EVERY_S = 60.0
RSS_EVERY_S = 1.0
GARBAGE_EVERY_S = 7.0
CORRUPT_EVERY_S = 11.0
DROPOUT_EVERY_S = 45.0
DROPOUT_S = 0.6  # longer than [loop] glove_timeout_s: the puppet relaxes, then resumes
OUTSIDE_LIMITS_TARGET = 0
GROWTH_TARGET_MB_H = 5.0


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m bench soak", description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=DEFAULT_SECONDS,
                   help=f"how long the rig runs (default {DEFAULT_SECONDS:g})")
    p.add_argument("--stall-every-s", type=float, default=STALL_EVERY_S,
                   help=f"a {STALL_S * 1e3:.0f} ms host stall this often "
                   f"(default {STALL_EVERY_S:g} s)")
    p.add_argument("--seed", type=int, default=1, help="fault seed (default 1)")
    p.add_argument("--record", default="", metavar="FILE.csv",
                   help="where the recording goes (default: a temporary file, removed)")
    p.add_argument("--mute", default="", metavar="ID@FROM-UNTIL",
                   help="one servo sends no reply from FROM to UNTIL seconds after the "
                   "emulated bus starts (a second or so before the run; it still hears "
                   "and obeys: a broken reply line), e.g. 7@120-240")
    p.add_argument("--glove-child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args([a for a in argv if a not in ("soak", "bench_soak")])
    if args.mute:
        m = re.fullmatch(r"(\d+)@(\d+(?:\.\d*)?)-(\d+(?:\.\d*)?)", args.mute)
        if not m or float(m.group(2)) >= float(m.group(3)):
            p.error(f"--mute must be ID@FROM-UNTIL in seconds with FROM < UNTIL, e.g. "
                    f"7@120-240; got {args.mute!r}")
    if not (np.isfinite(args.seconds) and args.seconds > 0):
        p.error(f"--seconds must be a positive number, got {args.seconds}")
    if not (np.isfinite(args.stall_every_s) and args.stall_every_s > 0):
        p.error(f"--stall-every-s must be a positive number, got {args.stall_every_s}")
    return args


# ---------------------------------------------------------------- the glove, faulty
def glove_child(seconds: float, seed: int) -> int:
    """The glove emulator with its fault schedule, in this process until SIGTERM;
    prints ``port: PATH`` first and what it injected last."""
    from handrig.devices.glove_recording import read_glove_recording
    from sim.glove_emulator import GloveEmulator

    stop = [False]

    def on_term(signum: int, frame: Any) -> None:
        stop[0] = True
    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)
    rng = random.Random(seed)
    injected: Counter[str] = Counter()
    dropout_every = min(DROPOUT_EVERY_S, max(seconds / 3.0, 2.0 * DROPOUT_S))
    with GloveEmulator(read_glove_recording(DEMO_RECORDING), "frames", rate_hz=200.0,
                       loop=True, seed=seed) as emu:
        print(f"port: {emu.port_path}", flush=True)
        t0 = time.monotonic()
        due = {"garbage": GARBAGE_EVERY_S * 0.5, "corrupt": CORRUPT_EVERY_S * 0.5,
               "dropout": dropout_every * 0.5}
        while not stop[0]:
            time.sleep(0.05)
            t = time.monotonic() - t0
            if t >= due["garbage"]:
                n = rng.randint(50, 400)
                emu.inject_garbage(n)
                injected["garbage bursts"] += 1
                injected["garbage bytes"] += n
                due["garbage"] += GARBAGE_EVERY_S
            if t >= due["corrupt"]:
                emu.corrupt_next(3)
                injected["bad-CRC frames"] += 3
                due["corrupt"] += CORRUPT_EVERY_S
            if t >= due["dropout"]:
                emu.pause()
                time.sleep(DROPOUT_S)
                emu.resume()
                injected["dropouts"] += 1
                due["dropout"] += dropout_every
    print("glove faults: " + ", ".join(f"{k} {v}" for k, v in sorted(injected.items())),
          flush=True)
    return 0


@contextlib.contextmanager
def faulty_glove(seconds: float, seed: int) -> Any:
    """The glove child process; yields (process, port)."""
    with app.port_process(["--glove-child", "--seconds", str(seconds), "--seed", str(seed)],
                      "the glove emulator", module="bench.bench_soak",
                      cwd=Path(__file__).resolve().parent.parent) as child:
        yield child


# ---------------------------------------------------------------- what is watched
def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


@dataclass
class Watch:
    """Host stalls and RSS samples (an output of the rig: called each cycle after the
    write), and the recoveries seen in the reads."""

    stall_every_s: float
    read_every: int
    stalls: int = 0
    rss: list[tuple[float, float]] = field(default_factory=list)
    recoveries: Counter[int] = field(default_factory=Counter)  # length in cycles -> count
    max_temperature_c: np.ndarray = field(default_factory=lambda: np.full(0, np.nan))
    holding: np.ndarray | None = None  # the loop's [silence] hold flags (read, never written)
    held_spans: list[tuple[int, float, float]] = field(default_factory=list)  # index, from, to
    _held_since: dict[int, float] = field(default_factory=dict)
    _next_stall_s: float = 0.0
    _next_rss_s: float = 0.0
    _stale_run: int = 0

    def __post_init__(self) -> None:
        self._next_stall_s = self.stall_every_s

    def output(self, t_s: float, pose: np.ndarray) -> None:
        if self.holding is not None:
            self._note_holds(t_s)
        if t_s >= self._next_stall_s:
            self._next_stall_s += self.stall_every_s
            self.stalls += 1
            time.sleep(STALL_S)  # the host is late: the loop thread does not run
        if t_s >= self._next_rss_s:
            self._next_rss_s += RSS_EVERY_S
            self.rss.append((t_s, rss_mb()))

    def _note_holds(self, t_s: float) -> None:
        """Each span of cycles in which the ``[silence]`` tiers held a servo's goal."""
        if self.holding is None:
            return
        since = self._held_since
        if not since and not self.holding.any():
            return
        for k in np.flatnonzero(self.holding):
            since.setdefault(int(k), t_s)
        for j in [j for j in since if not self.holding[j]]:
            self.held_spans.append((j, since.pop(j), t_s))

    def end_holds(self, t_s: float) -> None:
        for i, t0 in sorted(self._held_since.items()):
            self.held_spans.append((i, t0, t_s))
        self._held_since.clear()

    def wrap_reads(self, bus: Any) -> None:
        read: Callable[..., Any] = bus.read_state

        def read_state(deadline_s: float | None = None,
                       part: tuple[int, int] | None = None, *, patient: bool = False) -> Any:
            state = read(deadline_s, part, patient=patient)
            temps = state.temperatures_c
            if self.max_temperature_c.shape != temps.shape:
                self.max_temperature_c = np.full(temps.shape, np.nan)
            if not np.array_equal(temps, self.max_temperature_c, equal_nan=True):
                np.fmax(self.max_temperature_c, temps, out=self.max_temperature_c)
            if state.stale.any():
                self._stale_run += 1
            elif self._stale_run:
                self.recoveries[self._stale_run * self.read_every] += 1
                self._stale_run = 0
            return state
        bus.read_state = read_state

    def growth_mb_h(self) -> float:
        """Least-squares RSS slope after the first fifth of the run (imports, caches,
        the allocator's arenas filling), in MB per hour."""
        if len(self.rss) < 4:
            return float("nan")
        t, mb = np.array(self.rss).T
        keep = t >= t[-1] * 0.2
        if keep.sum() < 3:
            return float("nan")
        return float(np.polyfit(t[keep], mb[keep], 1)[0] * 3600.0)


class VmcReceiver:
    """A UDP socket on localhost that takes the VMC sender's datagrams and counts them
    (a thread drains it until :meth:`close`)."""

    def __init__(self) -> None:
        import socket
        import threading

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.address = f"127.0.0.1:{self.sock.getsockname()[1]}"
        self.datagrams = 0
        self.bytes = 0
        self._stop = False
        self._thread = threading.Thread(target=self._drain, daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        while not self._stop:
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            self.datagrams += 1
            self.bytes += len(data)

    def close(self) -> None:
        self._stop = True
        self._thread.join(timeout=1.0)
        self.sock.close()


def _counts(text: str, key: str) -> dict[str, int]:
    """``key: name N, name N`` from an emulator's last lines."""
    m = re.search(rf"{key}: ([^;\n]*)", text)
    out: dict[str, int] = {}
    if m:
        for part in m.group(1).split(","):
            words = part.strip().rsplit(" ", 1)
            if len(words) == 2 and words[1].isdigit():
                out[words[0]] = int(words[1])
    return out


# ---------------------------------------------------------------- the run
def soak(seconds: float, stall_every_s: float, seed: int, record: str,
         mute: str = "") -> dict[str, Any]:
    """One soak run; returns its figures (what :func:`report` prints). ``mute``:
    ``ID@FROM-UNTIL``, a servo that does not answer for that window."""
    clock = MonotonicClock()
    parts = app_parts.build_parts()
    rig_cfg = parts.rig_config
    overload_id = rig_cfg.servos[len(rig_cfg.servos) // 2].id
    faults = f"{BUS_FAULTS},overload={overload_id}@{seconds * 0.4:.1f},seed={seed}"
    if mute:
        faults += f",mute={mute}"
    watch = Watch(stall_every_s, rig_cfg.bus.read_every)
    lines: list[str] = []
    out: dict[str, Any] = {"seconds": seconds, "faults": faults, "error": "", "mute": mute,
                           "servo_names": [f"{c.id} {c.joint} {c.model}"
                                           for c in rig_cfg.servos]}
    tmp = None
    if not record:
        tmp = tempfile.TemporaryDirectory(prefix="handrig-soak-")
        record = str(Path(tmp.name) / "soak.csv")
    out["rss_before_mb"] = rss_mb()
    opened: app.OpenedBus | None = None
    glove_proc: subprocess.Popen[str] | None = None
    vmc = VmcReceiver()
    try:
        with contextlib.ExitStack() as stack:
            stack.callback(vmc.close)
            glove_proc, glove_port = stack.enter_context(faulty_glove(seconds, seed))
            opened = stack.enter_context(app.servo_bus(
                "sim", parts, clock, wire_timing=True, faults=faults, log=lines.append))
            bus = opened.bus
            bus_started = time.monotonic()
            glove = app.open_glove(glove_port, parts.glove_config, clock)
            stack.enter_context(glove)
            bus.connect()
            outs = app.outputs(stack, rig_cfg, clock, vmc=vmc.address, record=record,
                               log=lines.append)
            rig = app.build_rig(parts, glove, bus, clock, outputs=[*outs, watch.output],
                                log=lines.append)
            watch.wrap_reads(bus)
            watch.holding = rig.cycle.silence.holding
            rig.prepare()
            out["run_after_bus_s"] = time.monotonic() - bus_started
            try:
                with bus.torque(handle_signals=False), \
                        pinned_loop(rig_cfg.loop.pin_cpu, lines.append), \
                        realtime_priority(rig_cfg.loop.realtime_priority, lines.append,
                                          short_slice_instead=True):
                    rig.run(duration_s=seconds)
            except HandrigError as exc:
                out["error"] = str(exc)
            watch.end_holds(rig.stats.duration_s)
            out["torque_off"] = torque_is_off(bus)
            out["stats"] = rig.stats
            out["bus"] = bus.stats.copy()
            out["glove"] = glove.stats()
    except HandrigError as exc:
        out["error"] = out["error"] or str(exc)
    finally:
        import gc

        gc.unfreeze()
    out["emulator"] = opened.emulator_output() if opened is not None else ""
    glove_out = ""
    if glove_proc is not None and glove_proc.stdout is not None:
        with contextlib.suppress(OSError, ValueError):
            glove_out = glove_proc.stdout.read() or ""
    out["glove_injected"] = _counts(glove_out, "glove faults")
    out["record_bytes"] = os.path.getsize(record) if os.path.exists(record) else 0
    if tmp is not None:
        tmp.cleanup()
    out["watch"] = watch
    out["lines"] = lines
    out["vmc"] = (vmc.address, vmc.datagrams, vmc.bytes)
    return out


def report(r: dict[str, Any]) -> None:
    """Print the figures of a soak run."""
    watch: Watch = r["watch"]
    print(f"soak: {r['seconds']:g} s of the live rig on the emulated bus (handrig sim-bus, "
          f"MuJoCo puppet, wire timing), recording on, VMC on"
          + (f", servo {r['mute'].replace('@', ' muted from ').replace('-', ' s to ')} s"
             if r["mute"] else "")
          + (f" of the emulator's time (the run starts {r['run_after_bus_s']:.1f} s after it)"
             if r["mute"] and "run_after_bus_s" in r else ""))
    print(f"  bus faults      {r['faults']}; a {STALL_S * 1e3:.0f} ms host stall every "
          f"{watch.stall_every_s:g} s ({watch.stalls} made)")
    if "stats" not in r:
        print(f"  did not run: {r['error']}")
        return
    s, b, g = r["stats"], r["bus"], r["glove"]
    print(f"  cycles          {s.frames} in {s.duration_s:.1f} s ({s.rate_hz:.1f} Hz), "
          f"overruns {s.overruns} (max {s.overrun_max_s * 1e3:.1f} ms), missed cycles "
          f"{s.missed_cycles}; latency p50 {s.latency_us(50):.0f} us, "
          f"p99 {s.latency_us(99):.0f} us")
    injected = _counts(r["emulator"], "faults")
    print("  bus injected    " + (", ".join(f"{k} {v}" for k, v in sorted(injected.items()))
                                  or "(no count from the emulator)"))
    print(f"  bus counted     timeouts {b.timeouts}, crc errors {b.crc_errors}, malformed "
          f"{b.malformed}, late replies {b.late_replies}, retries {b.retries}, hardware "
          f"errors {int(b.hardware_errors.sum())}, reboots {int(b.reboots.sum())}, late reads "
          f"{b.late_reads}, watchdog gaps {b.watchdog_gaps}, watchdog trips "
          f"{b.watchdog_trips}")
    gi = r["glove_injected"]
    print("  glove injected  " + (", ".join(f"{k} {v}" for k, v in sorted(gi.items()))
                                  or "(no count from the glove emulator)"))
    print(f"  glove counted   crc errors {g.crc_errors}, decode errors {g.decode_errors}, "
          f"resyncs {g.resyncs}, garbage bytes {g.garbage_bytes}, channel errors "
          f"{g.channel_errors}, disconnects {g.disconnects}; relax events {s.relax_events}, "
          f"resumes {s.resumes}")
    rec = watch.recoveries
    lengths = sorted(rec.elements())
    if lengths:
        print(f"  recoveries      {len(lengths)} runs of reads with a stale servo, ended; "
              f"length in cycles: median {int(np.median(lengths))}, max {lengths[-1]}; "
              f"stale reads {s.stale_reads}/{s.reads}")
    else:
        print(f"  recoveries      none (stale reads {s.stale_reads}/{s.reads})")
    print(f"  silences        {s.servo_silences} servos past the [silence] warning, "
          f"{s.servos_held} held, {s.servo_recoveries} answered again (longest "
          f"{s.servo_recovery_reads_max} reads)")
    names = r["servo_names"]
    spans = watch.held_spans
    by_servo: dict[int, list[tuple[float, float]]] = {}
    for i, t0, t1 in spans:
        by_servo.setdefault(i, []).append((t0, t1))
    if not by_servo:
        print("  held            no servo's goal was held")
    for i, runs in sorted(by_servo.items()):
        total = sum(t1 - t0 for t0, t1 in runs)
        longest = max(runs, key=lambda r: r[1] - r[0])
        print(f"  held            servo {names[i]}: {len(runs)} times, {total:.2f} s in all, "
              f"longest {longest[1] - longest[0]:.2f} s from {longest[0]:.1f} s (run time)")
    starts = sorted({round(t0, 1) for _, t0, _ in spans})
    if starts:
        print(f"  holds began at  {', '.join(f'{t:g}' for t in starts[:20])} s (run time)"
              + (f" and {len(starts) - 20} more" if len(starts) > 20 else ""))
    if r["mute"]:
        muted_id, window = r["mute"].split("@")
        lo, hi = (float(x) - r.get("run_after_bus_s", 0.0) for x in window.split("-"))
        others = sorted({names[i] for i, t0, t1 in spans
                         if names[i].split()[0] != muted_id and t0 < hi and t1 > lo})
        print(f"  while muted     {lo:.1f}-{hi:.1f} s (run time): other servos held: "
              + (", ".join(others) if others else "none"))
    temps = watch.max_temperature_c
    if temps.size == len(names) and np.isfinite(temps).any():
        hottest = int(np.nanargmax(temps))
        print(f"  temperature     max {temps[hottest]:.0f} C at servo {names[hottest]}; per "
              "servo (ID: max C) " + ", ".join(
                  f"{n.split()[0]}: {t:.0f}" for n, t in zip(names, temps, strict=True)))
    else:
        print("  temperature     (never read)")
    address, datagrams, size = r["vmc"]
    print(f"  vmc             {datagrams} datagrams ({size / 1e6:.1f} MB) received at {address}")
    m = re.search(r"goals: (\d+) decoded, (\d+) outside", r["emulator"])
    goals = f"{m.group(2)} of {m.group(1)} decoded" if m else "(no count from the emulator)"
    print(f"  goals outside   {goals} on the bus side outside the rig's limits "
          f"(must be {OUTSIDE_LIMITS_TARGET})")
    rss = watch.rss
    if rss:
        print(f"  rss             {rss[0][1]:.1f} MB at the start, {rss[-1][1]:.1f} MB at the "
              f"end; growth {watch.growth_mb_h():.2f} MB/h (target < {GROWTH_TARGET_MB_H:g}); "
              f"recording {r['record_bytes'] / 1e6:.1f} MB on disk")
    print(f"  stopped         {s.stop_reason or '-'}" + (f"; error: {r['error']}" if r["error"]
                                                          else ""))
    print(f"  torque off      {r['torque_off']}")
    silence_events = [e for e in s.events if "reply" in e or "answers again" in e
                      or "holding" in e]
    for e in silence_events[:5]:
        print(f"  event           {e}")


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.glove_child:
        sys.exit(glove_child(args.seconds, args.seed))
    report(soak(args.seconds, args.stall_every_s, args.seed, args.record, args.mute))


if __name__ == "__main__":
    main()
