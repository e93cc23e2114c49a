"""The glove firmware's own figures, measured on the emulated chip (sim/avr_glove/).

Runs the firmware ELF `make firmware` builds (and, with ``--base REF``, the firmware of
commit REF built beside it, the runs alternated) in the simavr harness, its index
channel stepping every ``STEP_S`` (every other channel constant, the forearm still and
tilted, no analog noise, so the goals hold still between steps) into the real rig
(`handrig run` with a bus emulator in its own process, kinematic servos with wire timing,
the glove's One Euro filter off), at each rate of ``--rates`` (default 200 and 500 Hz). Prints, per
firmware and rate:

* the ADC burst's span, and from its middle (the mean of its conversions' start times)
  and from the sample tick (the test point rising) to the frame's last bit on the UART,
  per frame (the harness watches the ADC, the test point and the UART from outside);
* end to end, from the burst's middle (and from the tick) of the first frame that saw a
  step to the bus emulator's receipt of the first Sync Write whose goals moved: the
  firmware's part (chip time) plus the host's part (the last byte handed to the pty to
  the receipt, both CLOCK_MONOTONIC, also printed on its own), so the emulator's own
  pacing jitter on a busy machine does not count;
* the fraction of the chip's cycles spent awake, the rig's in-process latency (frame
  arrival to Sync Write handed to the OS), flash and RAM.

``--noise`` prints instead the table the ADC settings were chosen from: for each ADC
prescaler and oversampling, the noise in the frame's counts on the emulated chip, the
burst's time and its middle to the last bit (bench/firmware_variants.py).

``HANDRIG_BENCH_SECONDS`` sets each run's length (default 20 s; ``HANDRIG_BENCH_QUICK=1``:
8 s). Needs `make firmware-deps`; prints why and returns when the toolchain is missing.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import re
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.firmware_variants import FOREARM_XYZW, base_source, noise_table
from bench.rig_steps import INDEX_CHANNEL, emulator, outside_latencies, step_recording
from handrig.app.parts import build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.config.loading import CONFIG_DIR
from handrig.devices.glove_recording import write_glove_recording
from sim.avr_glove import AvrGlove, build, build_variant, toolchain_missing


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m bench firmware",
                                description=(__doc__ or "").split("\n")[0])
    p.add_argument("--base", default=None,
                   help="also run this commit's firmware, alternated with this one's")
    p.add_argument("--variant", action="append", default=[], metavar="DEFINES",
                   help="also run this firmware built with these -D settings, e.g. "
                        "--variant=-DGLOVE_ADC_PRESCALER=64 (repeatable)")
    p.add_argument("--rates", default="200,500", help="glove rates in Hz (default 200,500)")
    p.add_argument("--rounds", type=int, default=1, help="runs of each firmware and rate")
    p.add_argument("--noise", action="store_true",
                   help="print the ADC prescaler x oversampling noise table instead")
    return p.parse_args(argv)


@dataclass
class Run:
    """One firmware at one rate: its per-frame and end-to-end times (us)."""

    label: str
    rate_hz: int
    size: str
    span: list[float]
    mid_wire: list[float]
    tick_wire: list[float]
    mid_e2e: list[float]
    tick_e2e: list[float]
    host: list[float]
    early_bytes: list[float]
    cpu_busy: list[float]
    behind_s: list[float]
    rig_p50: list[float]
    rig_p99: list[float]
    frames_ok: int = 0
    crc_errors: int = 0


def _pct(v: Sequence[float]) -> str:
    a = np.asarray(v, dtype=np.float64)
    if not len(a):
        return "none"
    return (f"min {a.min():.0f}, p50 {np.percentile(a, 50):.0f}, p90 {np.percentile(a, 90):.0f}"
            f", p99 {np.percentile(a, 99):.0f}, max {a.max():.0f} ({len(a)})")


def _glove_file(folder: Path, rate_hz: int) -> Path:
    """config/glove.toml at the run's rate, its One Euro filter off."""
    text = (CONFIG_DIR / "glove.toml").read_text(encoding="utf-8")
    text = re.sub(r"(?ms)(^\[filter\].*?^enabled = )true", r"\1false", text, count=1)
    text = re.sub(r"(?m)^rate_hz = [\d.]+", f"rate_hz = {rate_hz:.1f}", text, count=1)
    path = folder / f"glove_{rate_hz}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def run_once(run: Run, elf: Path, seconds: float) -> None:
    rec = step_recording()
    rec = dataclasses.replace(rec, quat_xyzw=np.tile(FOREARM_XYZW, (len(rec.t_s), 1)))
    values = rec.raw[:, INDEX_CHANNEL].copy()
    period_s = float(rec.t_s[-1] - rec.t_s[0] + (rec.t_s[1] - rec.t_s[0]))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rec_path = folder / "steps.csv"
        write_glove_recording(rec_path, rec)
        timing = folder / "timing.txt"
        bus_log = folder / "bus.log"
        rig_path = CONFIG_DIR / "rig.toml"
        parts = build_parts(rig_path, _glove_file(folder, run.rate_hz))
        with (emulator(["bus", "--rig", str(rig_path), "--log", str(bus_log)],
                       "the bus emulator") as bus_port,
              AvrGlove(rec_path, timing=timing, noise_mv=0.0, firmware=elf,
                       whole_frames=bool(os.environ.get("HANDRIG_BENCH_WHOLE_FRAMES"))) as chip):
            result = run_live(parts, LiveOptions(glove=chip.port, bus=bus_port,
                                                 duration_s=seconds, log=lambda s: None))
        figures = chip.figures
        frames = [line.split() for line in timing.read_text().splitlines() if line]
        writes = []
        for line in bus_log.read_text().splitlines():
            fields = line.split()
            if fields:
                writes.append((float(fields[0]), tuple(int(v) for v in fields[1:])))
    # each frame's last byte (wall time) and the recorded sample at its burst's middle
    t_rel = rec.t_s - rec.t_s[0]
    sends = [(float(f[2]), int(np.searchsorted(t_rel, float(f[6]) % period_s, side="right") - 1))
             for f in frames]
    for k in range(1, len(sends)):
        if values[sends[k][1]] != values[sends[k - 1][1]]:  # this frame carries a step
            host = outside_latencies(sends[k - 1:k + 1], values, writes)
            if host:
                run.mid_e2e.append(float(frames[k][5]) + host[0] * 1e6)
                run.tick_e2e.append(float(frames[k][3]) + host[0] * 1e6)
                run.host.append(host[0] * 1e6)
    steady = [f for f in frames if float(f[4]) >= 1.0]
    run.tick_wire += [float(f[3]) for f in steady]
    run.mid_wire += [float(f[5]) for f in steady]
    run.span += [float(f[7]) for f in steady]
    run.early_bytes += [float(f[10]) for f in steady]
    run.cpu_busy.append(figures.get("cpu_busy", float("nan")))
    run.behind_s.append(figures.get("behind_wall_s", float("nan")))
    s = result.summary
    run.rig_p50.append(float(s["latency_us"]["p50"]))
    run.rig_p99.append(float(s["latency_us"]["p99"]))
    run.frames_ok += int(s["glove"]["frames_ok"])
    run.crc_errors += int(s["glove"]["crc_errors"])


def report(runs: list[Run]) -> None:
    for r in runs:
        print(f"-- {r.label}, {r.rate_hz} Hz; {' / '.join(r.size.splitlines())}")
        print(f"   ADC burst span (first to last conversion start): {_pct(r.span)} us")
        print(f"   burst middle to last bit on the UART: {_pct(r.mid_wire)} us")
        print(f"   sample tick to last bit on the UART:  {_pct(r.tick_wire)} us")
        print(f"   frame bytes on the wire before the burst's last conversion: "
              f"median {np.median(r.early_bytes) if r.early_bytes else 0:.0f}")
        print(f"   END TO END burst middle to Sync Write received: {_pct(r.mid_e2e)} us")
        print(f"   end to end sample tick to Sync Write received:  {_pct(r.tick_e2e)} us")
        print(f"   of which the host's (last bit to Sync Write received): {_pct(r.host)} us")
        print(f"   CPU awake {100 * float(np.mean(r.cpu_busy)):.1f} %; rig in process p50 "
              f"{np.median(r.rig_p50):.0f}, p99 {np.median(r.rig_p99):.0f} us; glove frames ok "
              f"{r.frames_ok}, CRC errors {r.crc_errors}")
        print(f"   the chip behind wall time at the end of each run (s): "
              f"{', '.join(f'{b:.3f}' for b in r.behind_s)} (a starved emulator: its frames late)")


def print_noise_table() -> None:
    print(f"date {datetime.date.today().isoformat()}; 200 Hz, 2 mV input noise (the harness's "
          "default), 4 constant channels, 2 s of chip time each")
    print("prescaler  ADC clock  samples  noise (counts, 12-bit)  burst us  middle to last bit "
          "us  pinned flag held")
    for row in noise_table():
        print(f"{row.prescaler:9d}  {16000 / row.prescaler:6.0f} kHz  {row.oversample:7d}  "
              f"{row.noise_counts:22.2f}  {row.burst_us:8.0f}  {row.middle_to_last_byte_us:21.0f}"
              f"  {100 * row.pinned_held:5.0f} %")


def main() -> None:
    import sys

    args = parse_args(sys.argv[1:])
    missing = toolchain_missing()
    if missing:
        print(missing)
        return
    build()
    if args.noise:
        print_noise_table()
        return
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS")
                    or (8 if os.environ.get("HANDRIG_BENCH_QUICK") else 20))
    rates = [int(r) for r in args.rates.split(",") if r]
    sources: list[tuple[str, Path | None, list[str]]] = [("this firmware", None, [])]
    if args.base:
        base_src, sha = base_source(args.base)
        sources.insert(0, (f"base {sha}", base_src, []))
    sources += [(f"this firmware {v}", None, v.split()) for v in args.variant]
    runs: dict[tuple[int, int], Run] = {}
    elves: dict[tuple[int, int], Path] = {}
    for i, (label, src, defines) in enumerate(sources):
        for rate in rates:
            folder = f"build/fwbench/{re.sub(r'[^A-Za-z0-9_=.-]+', '-', label)}-{rate}"
            elves[i, rate], size = build_variant(folder, [f"-DGLOVE_RATE_HZ={rate}", *defines],
                                                 source=src)
            runs[i, rate] = Run(label, rate, size, [], [], [], [], [], [], [], [], [], [], [])
    print(f"date {datetime.date.today().isoformat()}, {seconds:g} s a run, {args.rounds} "
          f"round(s), alternated; load {os.getloadavg()[0]:.1f}", flush=True)
    for _ in range(args.rounds):
        for rate in rates:
            for i in range(len(sources)):
                run_once(runs[i, rate], elves[i, rate], seconds)
    report([runs[i, rate] for rate in rates for i in range(len(sources))])
    print(f"load at the end {os.getloadavg()[0]:.1f}")

