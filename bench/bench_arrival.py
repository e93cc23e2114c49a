"""Where a glove frame's time goes before its cycle starts.

Runs the glove-triggered rig of :mod:`bench.bench_rig` (200 Hz glove, 1 Mbps bus,
both emulators in processes of their own; the rig's own ``[loop]`` settings: its poll
window and warm-up as shipped),
and for every frame the rig decoded joins three times on CLOCK_MONOTONIC:

* the glove emulator's send time (from its log, by sequence number);
* the frame's arrival stamp (``host_time_s``: what the latency figures start from);
* the time the frame was decoded into a sample (the end of the port read).

It prints send -> stamp (how far the stamp is from the send: the wake-up of a
sleeping loop, or a few microseconds when polling), send -> decoded (what the
puppeteer's frame really waited before the cycle could start) and the cases'
end-to-end figures. The decode time is taken by wrapping
``SerialGlove._frame_sample`` in this process: nothing in the product changes.

``HANDRIG_BENCH_SECONDS`` sets each run's length (default 10 s);
``HANDRIG_BENCH_ROUNDS`` the number of runs (default 2).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench import bench_rig
from handrig.devices import glove as glove_module


def _run(seconds: float) -> dict[str, Any]:
    decoded: list[tuple[int, float, float]] = []
    original = glove_module.SerialGlove._frame_sample

    def frame_sample(fr: Any, now: float, count: int) -> Any:
        if count:  # count 0: the warm-up's rehearsal decoding the last bytes again
            decoded.append((int(fr.seq), now, time.perf_counter()))
        return original(fr, now, count)

    glove_module.SerialGlove._frame_sample = staticmethod(frame_sample)  # type: ignore[method-assign]
    try:
        with tempfile.TemporaryDirectory(prefix="bench_arrival_") as tmp:
            folder = Path(tmp)
            case = bench_rig.Case("glove", 200.0, 1_000_000)
            result = bench_rig.run_step_case(case, seconds, folder)
            sends: dict[int, float] = {}
            log = folder / "glove_glove_200_1000000.log"
            for line in log.read_text().splitlines():
                t_s, seq, _ = line.split()
                sends[int(seq)] = float(t_s)  # no wrap in a run this short
    finally:
        glove_module.SerialGlove._frame_sample = staticmethod(original)  # type: ignore[method-assign]
    rows = np.array([(sends[seq], stamp, done) for seq, stamp, done in decoded
                     if seq in sends and sends[seq] <= done])
    return {"summary": result["summary"], "outside": result["outside_us"],
            "stamp_us": (rows[:, 1] - rows[:, 0]) * 1e6,
            "decoded_us": (rows[:, 2] - rows[:, 0]) * 1e6}


def _pct(values: np.ndarray) -> str:
    p10, p50, p90 = np.percentile(values, [10, 50, 90])
    return f"{p10:.0f} / {p50:.0f} / {p90:.0f}"


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 10.0))
    rounds = int(os.environ.get("HANDRIG_BENCH_ROUNDS", 2))
    print(f"glove-triggered rig, 200 Hz glove, 1 Mbps, 20 emulated servos, {seconds:g} s "
          f"per run, {rounds} runs", flush=True)
    print("| run | send -> stamp p10 / p50 / p90 (us) | send -> decoded p10 / p50 / p90 "
          "(us) | in-process end to end p50 / p99 (us) | outside p50 / p99 (us) | "
          "CPU/cycle (us) |\n|---|---|---|---|---|---|", flush=True)
    for k in range(rounds):
        r = _run(seconds)
        s, o = r["summary"], r["outside"]
        print(f"| {k + 1} | {_pct(r['stamp_us'])} | {_pct(r['decoded_us'])} | "
              f"{s['latency_us']['p50']} / {s['latency_us']['p99']} | "
              f"{o['p50']} / {o['p99']} | {s['cpu_per_cycle_us']} |", flush=True)


if __name__ == "__main__":
    main()
