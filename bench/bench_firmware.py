"""The glove firmware's own figures, measured on the emulated chip (sim/avr_glove/).

Runs the firmware ELF `make firmware` builds in the simavr harness, its index
channel stepping every ``STEP_S`` (every other channel constant, the IMU level),
(no analog noise, so the goals hold still between steps) into the real rig
(`handrig run` with a bus emulator in its own process,
kinematic servos with wire timing, the glove's One Euro filter off). Prints:

* sample tick to the frame's last bit on the UART, per frame (the harness watches the
  firmware's test point and its UART from outside the firmware);
* the fraction of the chip's cycles spent awake at the frame rate (after 1 s);
* end to end, from the ADC sample tick of the first frame that saw a step to the bus
  emulator's receipt of the first Sync Write whose goals moved: the firmware's part
  (tick to last bit, chip time) plus the host's part (the last byte handed to the pty
  to the receipt, both CLOCK_MONOTONIC), so the emulator's own pacing jitter on a
  busy machine does not count;
* the rig's in-process latency (frame arrival to Sync Write handed to the OS).

``HANDRIG_BENCH_SECONDS`` sets the run's length (default 20 s; ``HANDRIG_BENCH_QUICK=1``:
8 s). Needs `make firmware-deps`; prints why and returns when the toolchain is missing.
"""

from __future__ import annotations

import datetime
import os
import tempfile
from pathlib import Path

import numpy as np

from bench.bench_rig import (
    INDEX_CHANNEL,
    _glove_file,
    emulator,
    outside_latencies,
    step_recording,
)
from handrig.app.parts import build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.config.loading import CONFIG_DIR
from handrig.devices.glove_recording import write_glove_recording
from sim.avr_glove import AvrGlove, build, toolchain_missing


def _pct(v: np.ndarray) -> str:
    return (f"min {v.min():.0f}, p10 {np.percentile(v, 10):.0f}, p50 {np.percentile(v, 50):.0f}"
            f", p90 {np.percentile(v, 90):.0f}, p99 {np.percentile(v, 99):.0f}, max {v.max():.0f}"
            f" us ({len(v)})")


def main() -> None:
    missing = toolchain_missing()
    if missing:
        print(missing)
        return
    build()
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS")
                    or (8 if os.environ.get("HANDRIG_BENCH_QUICK") else 20))
    rec = step_recording()
    values = rec.raw[:, INDEX_CHANNEL].copy()
    period_s = float(rec.t_s[-1] - rec.t_s[0] + (rec.t_s[1] - rec.t_s[0]))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rec_path = folder / "steps.csv"
        write_glove_recording(rec_path, rec)
        timing = folder / "timing.txt"
        bus_log = folder / "bus.log"
        rig_path = CONFIG_DIR / "rig.toml"
        parts = build_parts(rig_path, _glove_file(folder))
        with (emulator(["bus", "--rig", str(rig_path), "--log", str(bus_log)],
                       "the bus emulator") as bus_port,
              AvrGlove(rec_path, timing=timing, noise_mv=0.0,
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
    # each frame's last byte (wall time), its tick-to-last-bit (chip time) and the
    # recorded sample its ADC burst read
    t_rel = rec.t_s - rec.t_s[0]
    sends = [(float(f[2]), int(np.searchsorted(t_rel, float(f[4]) % period_s, side="right") - 1))
             for f in frames]
    e2e_us = []
    for k in range(1, len(sends)):
        if values[sends[k][1]] != values[sends[k - 1][1]]:  # this frame carries a step
            host = outside_latencies(sends[k - 1:k + 1], values, writes)
            if host:
                e2e_us.append(float(frames[k][3]) + host[0] * 1e6)
    e2e = np.array(e2e_us)
    to_wire = np.array([float(f[3]) for f in frames if float(f[4]) >= 1.0])
    s = result.summary
    lat = s["latency_us"]
    print(f"date {datetime.date.today().isoformat()}, {seconds:g} s, glove 200 Hz at "
          f"{figures.get('frames', 0):.0f} frames from the emulated ATmega328P")
    print(f"sample tick to last bit on the UART: {_pct(to_wire)}")
    print(f"CPU awake at 200 Hz: {100 * figures.get('cpu_busy', float('nan')):.1f} %")
    if len(e2e):
        print(f"end to end, ADC sample tick to Sync Write received by the bus: {_pct(e2e)}"
              f" over {len(e2e)} steps")
    else:
        print("end to end: no step reached the bus (is the rig running?)")
    print(f"rig in process, frame arrival to Sync Write handed to the OS: p50 {lat['p50']}, "
          f"p99 {lat['p99']}, max {lat['max']} us; glove frames ok {s['glove']['frames_ok']}, "
          f"CRC errors {s['glove']['crc_errors']}")
    print(f"chip behind wall time at the end: {figures.get('behind_wall_s', float('nan')):.3f} s")
