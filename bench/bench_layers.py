"""Takes layered under the glove: the loop's cycle with 0, 1 and 3 layers, side by side.

Two parts, each alternating the layer counts round by round in the one run (so a
load that comes and goes on a shared machine falls on every count alike):

* the pose work of a cycle that layering touches, in process on the one-glove rig's
  real pipeline: the layers' advance, the servo step, the layers' blend and slew, the
  full pose and the layers' blend into it; median and p99 in microseconds over
  ``FRAMES`` cycles a round;
* the whole loop end to end (:mod:`bench.bench_rig`'s glove-triggered case: a 200 Hz
  glove emulator and 20 servos at 1 Mbps, each in a process of its own): the frame's
  arrival to its Sync Write handed to the OS (latency) and the cycle's compute part,
  p50 and p99 in microseconds, per layer count.

The layers are three synthetic performances (2 s, looped) on the index, the middle
finger and the thumb. ``HANDRIG_BENCH_SECONDS`` sets each end-to-end run's length
(default 5 s), ``HANDRIG_BENCH_ROUNDS`` the rounds (default 3).
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.bench_rig import Case, run_step_case
from handrig import hand
from handrig.app.layering import LayerControl, LayerOptions, LayerSpec
from handrig.app.parts import build_parts
from handrig.loop.layers import LayerMixer
from handrig.outputs.recorder import csv_header
from handrig.pose.pipeline import PosePipeline

FRAMES = 5000
GROUPS = ("index", "middle", "thumb")
COUNTS = (0, 1, 3)


def write_take(path: Path, seed: int, seconds: float = 2.0, rate_hz: float = 200.0) -> Path:
    """A performance CSV: every curve a slow sine about 20 deg (the recorder's columns)."""
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi, len(hand.CURVE_NAMES))
    poses = 20.0 + 15.0 * np.sin(2 * np.pi * t[:, None] / seconds + phase[None, :])
    header = ",".join(csv_header(False))
    np.savetxt(path, np.column_stack([t, poses]), delimiter=",", header=header,
               comments="", fmt="%.4f")
    return path


def _mixer(pipeline: PosePipeline, takes: list[Path], count: int) -> LayerMixer:
    mixer = LayerMixer(pipeline)
    control = LayerControl([pipeline])
    for take, group in list(zip(takes, GROUPS, strict=True))[:count]:
        for command in control._plans(str(take), group, loop=True, fade_s=0.5, key="bench",
                                      at_start=True):
            if command is not None:
                mixer.post(command)
    mixer.start(0.0)
    return mixer


def pose_work(pipeline: PosePipeline, mixer: LayerMixer) -> tuple[float, float]:
    """Median and p99 (us) of the layered part of a cycle, ``FRAMES`` cycles."""
    rng = np.random.default_rng(0)
    controls = pipeline.control_means_deg + rng.normal(0.0, 5.0, (64, len(
        pipeline.control_means_deg)))
    sent = pipeline.targets.copy()
    times = np.empty(FRAMES)
    clock = time.perf_counter_ns
    dt = 0.005
    for i in range(FRAMES + 500):
        c = controls[i % 64]
        t0 = clock()
        mixer.advance(i * dt)
        goals = pipeline.servo_targets(c, -90.0, 0.0, dt)
        if mixer.active:
            mixer.mix_goals(pipeline.raw_targets, sent, goals, 720.0 * dt)
        pose = pipeline.account(c, -90.0, 0.0)
        mixer.mix_pose(pose)
        t1 = clock()
        sent[:] = goals
        if i >= 500:
            times[i - 500] = t1 - t0
    return float(np.median(times)) / 1e3, float(np.percentile(times, 99)) / 1e3


def _end_to_end(count: int, takes: list[Path], seconds: float, folder: Path) -> dict[str, Any]:
    layers = tuple(LayerSpec(str(take), group)
                   for take, group in list(zip(takes, GROUPS, strict=True))[:count])
    return run_step_case(Case("glove", 200.0, 1_000_000), seconds, folder,
                         layering=LayerOptions(layers=layers))


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", "5"))
    rounds = int(os.environ.get("HANDRIG_BENCH_ROUNDS", "3"))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        takes = [write_take(folder / f"take{i}.csv", i) for i in range(3)]
        pipeline = build_parts().pipeline
        pipeline.seed(pipeline.targets)
        work: dict[int, list[tuple[float, float]]] = {n: [] for n in COUNTS}
        for r in range(rounds * 3):
            for n in (COUNTS if r % 2 == 0 else COUNTS[::-1]):
                work[n].append(pose_work(pipeline, _mixer(pipeline, takes, n)))
        print(f"layered pose work of a cycle (one-glove rig, {len(pipeline.servo_joints)} "
              f"servos), {FRAMES} cycles x {rounds * 3} rounds, median of rounds:")
        print("| layers | median us | p99 us |")
        print("|---|---|---|")
        for n in COUNTS:
            med = statistics.median(m for m, _ in work[n])
            p99 = statistics.median(p for _, p in work[n])
            print(f"| {n} | {med:.1f} | {p99:.1f} |")
        e2e: dict[int, list[dict[str, Any]]] = {0: [], 3: []}
        for r in range(rounds):
            for n in ((0, 3) if r % 2 == 0 else (3, 0)):
                e2e[n].append(_end_to_end(n, takes, seconds, folder)["summary"])
        print(f"\nthe whole loop, glove-triggered, 200 Hz glove, 20 servos at 1 Mbps, "
              f"{seconds:g} s x {rounds} rounds, median of rounds (min..max):")
        print("| layers | latency p50 us | latency p99 us | compute p50 us | compute p99 us |"
              " frames skipped |")
        print("|---|---|---|---|---|---|")
        for n, runs in e2e.items():
            errors = [s["error"] for s in runs if "error" in s]
            if errors:
                print(f"| {n} | error: {errors[0]} |")
                continue
            cells = [_spread([s[part][q] for s in runs])
                     for part in ("latency_us", "compute_us") for q in ("p50", "p99")]
            skipped = _spread([s["frames_skipped"] for s in runs])
            print(f"| {n} | {' | '.join(cells)} | {skipped} |")
        print(f"load: {' '.join(f'{x:.2f}' for x in os.getloadavg())} (1/5/15 min)")


def _spread(values: list[float]) -> str:
    return f"{statistics.median(values):g} ({min(values):g}..{max(values):g})"


if __name__ == "__main__":
    main()
