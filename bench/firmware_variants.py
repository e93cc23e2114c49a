"""Firmware variants for ``python -m bench firmware``: an older commit's firmware built
beside this one, and the ADC's noise and burst time for each ADC clock and oversampling.

The noise is measured on the emulated chip: four channels held at constant levels (at
different places between two ADC codes) with the harness's input noise, the forearm's
IMU still, the frames read
from the chip's pty and decoded, the standard deviation of each channel over the run in
the frame's counts (12-bit scale: 4 counts are one 10-bit ADC step). simavr converts
the input at the conversion's start, exactly, whatever the ADC clock: it shows what
averaging buys against input noise and what each clock costs in time, not what a fast
ADC clock costs a real chip in accuracy (the datasheet's part).
"""

from __future__ import annotations

import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_protocol.glove import FLAG_SENSOR_RAIL
from handrig.devices.glove_recording import GloveRecording, write_glove_recording
from sim.avr_glove import ROOT, AvrGlove, build_variant

# raw 12-bit levels of channels 0..3 (each a different fraction of an ADC step); channel
# 4 is pinned at full scale, where the firmware must raise "sensor pinned"
NOISE_LEVELS = (1000.3, 1700.55, 2400.8, 3100.05)
WARMUP_S = 0.7  # the pinned flag needs half a second at the rail
# a forearm tilted about all three axes: no zero byte in its Q14 quaternion, as with a
# worn glove's IMU (a level one's zeros would end the frame's head later, so more of the
# frame would go out during the burst than it does on an arm)
FOREARM_XYZW = (0.1, -0.3, 0.2, float(np.sqrt(1 - 0.01 - 0.09 - 0.04)))


def base_source(ref: str) -> tuple[Path, str]:
    """``firmware/glove`` of commit ``ref``, exported with ``git archive`` into
    ``build/fwbase-SHA/src`` (once), to build with this Makefile (``FW_SRC``); and the
    commit's short hash."""
    from bench.compare import resolve_commit

    sha = resolve_commit(ref)
    root = ROOT / "build" / f"fwbase-{sha[:12]}" / "src"
    src = root / "firmware" / "glove"
    if not (src / "glove.ino").is_file():
        root.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "archive", sha, "firmware/glove"], cwd=ROOT,
                                 capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", str(root)], input=archive.stdout, check=True)
    return src, sha[:7]


def constant_recording(path: Path) -> None:
    t = np.arange(0.0, 1.0, 0.001)
    raw = np.empty((len(t), 5))
    raw[:, :4] = NOISE_LEVELS
    raw[:, 4] = 4095.0
    write_glove_recording(path, GloveRecording(
        t_s=t, raw=raw, buttons=np.zeros(len(t), dtype=np.int64),
        channel_names=tuple(f"ch{k}" for k in range(5)),
        quat_xyzw=np.tile(FOREARM_XYZW, (len(t), 1)), rate_hz=1000.0))


@dataclass(frozen=True)
class NoiseRow:
    prescaler: int
    oversample: int
    noise_counts: float   # RMS over channels 0..3 of each one's standard deviation
    burst_us: float       # first to last conversion start, plus one conversion
    middle_to_last_byte_us: float
    pinned_held: float    # share of frames after the warm-up flagged "sensor pinned"
    frames: int


def noise_row(prescaler: int, os_log2: int, rate_hz: int, seconds: float,
              noise_mv: float, folder: Path) -> NoiseRow:
    defines = [f"-DGLOVE_ADC_PRESCALER={prescaler}", f"-DGLOVE_OVERSAMPLE_LOG2={os_log2}",
               f"-DGLOVE_RATE_HZ={rate_hz}"]
    elf, _ = build_variant(f"build/fwnoise/{rate_hz}_ps{prescaler}_os{os_log2}", defines)
    rec = folder / "constant.csv"
    if not rec.is_file():
        constant_recording(rec)
    chip = AvrGlove(rec, seconds=seconds, noise_mv=noise_mv, firmware=elf, whole_frames=True)
    with chip:
        frames = chip.read_frames()
    figures = chip.figures
    t0 = frames[0].timestamp_us if frames else 0
    steady = [f for f in frames if (f.timestamp_us - t0) / 1e6 >= WARMUP_S]
    raw = np.array([f.channels for f in steady], dtype=np.float64)
    noise = float(np.sqrt(np.mean(np.var(raw[:, :4], axis=0)))) if len(raw) > 2 else float("nan")
    conversion_us = 13 * prescaler / 16.0
    pinned = float(np.mean([bool(f.status & FLAG_SENSOR_RAIL) for f in steady])) if steady else 0.0
    return NoiseRow(prescaler, 1 << os_log2, noise,
                    figures.get("burst_span_us", float("nan")) + conversion_us,
                    figures.get("burst_middle_to_last_byte_us_mean", float("nan")),
                    pinned, len(steady))


def noise_table(prescalers: tuple[int, ...] = (128, 64, 32, 16),
                os_log2s: tuple[int, ...] = (0, 1, 2, 3), rate_hz: int = 200,
                seconds: float = 2.0, noise_mv: float = 2.0) -> list[NoiseRow]:
    with tempfile.TemporaryDirectory() as tmp:
        return [noise_row(ps, os_log2, rate_hz, seconds, noise_mv, Path(tmp))
                for ps in prescalers for os_log2 in os_log2s]
