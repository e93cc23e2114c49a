"""What the glove trigger's spin window and rehearsal buy: four variants side by side.

``python -m bench trigger_mechanisms [--seconds 60] [--rounds 3] [--cases 200/1,500/4]``
runs the glove-triggered rig of ``python -m bench rig`` (:func:`bench.bench_rig.run_case`:
the real rig between the glove emulator and the bus emulator, each in a process of its
own, 20 servos with wire timing, the index channel stepping every 0.25 s) in four
variants, each run in a fresh interpreter:

* ``shipped``: as configured (``spin_us = 500``, the rehearsal on);
* ``spin only``: the spin window polls the port but rehearses nothing (the rig's
  rehearsal replaced by one that does nothing);
* ``rehearsal only``: ``spin_us = 0`` (the loop sleeps on the port and rehearses once,
  ``WARM_S`` before the predicted frame);
* ``neither``: ``spin_us = 0`` and no rehearsal (the loop sleeps on the port).

``--seconds`` is each variant's total per case, split into ``--rounds`` runs; within a
round the cases follow each other and the variants run in an order that rotates from
round to round, so the host's load drifts over all of them alike. Per case and variant,
pooled over the rounds:

* glove frame sent (the glove emulator's stamp) to its Sync Write handed to the OS
  (``os.write`` returned), every frame written, joined by the frame's sequence number;
* in process: the frame's arrival stamp to the same write (the loop's own figure);
* outside: the send of a frame carrying a step to the bus emulator's receipt of the
  first Sync Write that moved (as ``python -m bench rig``; 4 steps a second);
* frames lost (superseded without a write of their own: skipped by the loop plus lost
  in the glove's bursts; caught up in brackets), overruns;
* CPU of the loop's process (all its threads, not the emulators') per second of the
  run, and of the loop's thread per cycle; the hypervisor's steal share.

All times are CLOCK_MONOTONIC, so the emulators' stamps compare with the loop's.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench import bench_rig as b

VARIANTS = ("shipped", "spin only", "rehearsal only", "neither")
ROOT = Path(__file__).resolve().parent.parent


class NoRehearsal:
    """A rehearsal that rehearses nothing: the spin window then only polls the port."""

    def __init__(self) -> None:
        self.sample: Any = None
        self.angles: tuple[float, float] = (0.0, 0.0)

    def __call__(self, now_s: float) -> None:
        pass

    def steps(self, now_s: float) -> Iterator[None]:
        return iter(())


def _adjust(rig: Any, variant: str, record: dict[str, Any]) -> None:
    """Turn the variant's mechanisms off on a built rig, and record what the run needs:
    each written frame's (seq, write time) and the process's CPU over ``rig.run``."""
    if variant == "spin only":
        rig.rehearsal = NoRehearsal()
    elif variant == "neither":
        rig.rehearsal = None
    spin_expected = 0.0 if variant in ("rehearsal only", "neither") else 0.0005
    if abs(rig.trigger.spin_s - spin_expected) > 1e-9:
        raise SystemExit(f"{variant}: the trigger's spin_s is {rig.trigger.spin_s}, "
                         f"expected {spin_expected}")
    writes: list[tuple[int, float]] = []
    record["writes"] = writes
    cycle = rig.cycle
    after_write = cycle._after_write
    stats = rig.stats

    def recording_after_write(tick: Any, sample: Any, *args: Any) -> None:
        n = stats.latency.count
        after_write(tick, sample, *args)
        if sample is not None and stats.latency.count > n:
            writes.append((int(sample.seq), float(sample.host_time_s)))
            record.setdefault("lat", []).append(stats.latencies_s[-1])

    cycle._after_write = recording_after_write
    run = rig.run

    def timed_run(*args: Any, **kwargs: Any) -> Any:
        cpu0, wall0 = time.process_time(), time.perf_counter()
        try:
            return run(*args, **kwargs)
        finally:
            record["process_cpu_s"] = time.process_time() - cpu0
            record["wall_s"] = time.perf_counter() - wall0

    rig.run = timed_run


def send_to_write(sends: Sequence[tuple[float, int]],
                  writes: Sequence[tuple[int, float]]) -> list[float]:
    """For each written frame (seq, write time), the time from the glove emulator's send
    of that seq (the latest send of it before the write: seq wraps at 65536)."""
    by_seq: dict[int, list[float]] = {}
    for t, seq in sends:
        by_seq.setdefault(seq, []).append(t)
    out = []
    for seq, t_write in writes:
        times = [t for t in by_seq.get(seq, ()) if t <= t_write]
        if times:
            out.append(t_write - max(times))
    return out


def child(variant: str, hz: float, baud: int, seconds: float) -> None:
    """One run; prints one ``RESULT {json}`` line."""
    import handrig.app.factory as factory

    record: dict[str, Any] = {}
    build_rig = factory.build_rig

    def build(*args: Any, **kwargs: Any) -> Any:
        rig = build_rig(*args, **kwargs)
        _adjust(rig, variant, record)
        return rig

    factory.build_rig = build
    with tempfile.TemporaryDirectory(prefix="bench_trigger_") as tmp:
        folder = Path(tmp)
        rig_path = b._rig_file(folder, "glove", hz, baud)
        if variant in ("rehearsal only", "neither"):
            text = rig_path.read_text(encoding="utf-8")
            rig_path.write_text(text.replace("spin_us = 500.0", "spin_us = 0.0", 1),
                                encoding="utf-8")
        b._rig_file = lambda *args, **kwargs: rig_path
        r = b.run_step_case(b.Case("glove", hz, baud), seconds, folder)
        tag = f"glove_{hz:g}_{baud}"
        logged = [line.split() for line in
                  (folder / f"glove_{tag}.log").read_text().splitlines() if line]
        sends = [(float(t), int(seq)) for t, seq, _ in logged]
        bus_writes = []
        for line in (folder / f"bus_{tag}.log").read_text().splitlines():
            fields = line.split()
            if fields:
                bus_writes.append((float(fields[0]), tuple(int(v) for v in fields[1:])))
        values = b.step_recording().raw[:, b.INDEX_CHANNEL].copy()
        outside = b.outside_latencies([(float(t), int(i)) for t, _, i in logged], values,
                                      bus_writes)
    # the write time of each frame: its arrival stamp plus the in-process latency
    writes = [(seq, t + lat) for (seq, t), lat in
              zip(record.get("writes", []), record.get("lat", []), strict=True)]
    s = r["summary"]
    print("RESULT " + json.dumps({
        "error": s.get("error"),
        "send_to_write_us": [round(x * 1e6, 1) for x in send_to_write(sends, writes)],
        "in_process_us": [round(x * 1e6, 1) for x in record.get("lat", [])],
        "frames": s["frames"], "skipped": s["frames_skipped"],
        "bursts": s.get("frames_in_bursts", 0), "caught": s.get("frames_caught_up", 0),
        "overruns": s["overruns"], "cpu_per_cycle_us": s["cpu_per_cycle_us"],
        "process_cpu_s": record.get("process_cpu_s"), "wall_s": record.get("wall_s"),
        "outside_raw_us": [round(x * 1e6, 1) for x in outside],
    }), flush=True)


def _pct(values: Sequence[float], q: float) -> float | None:
    return round(float(np.percentile(values, q)), 1) if len(values) else None


def _triple(values: Sequence[float]) -> str:
    if not len(values):
        return "-"
    return f"{_pct(values, 50):.0f} / {_pct(values, 99):.0f} / {max(values):.0f}"


HEADER = ("| glove Hz / Mbps | variant | frame sent to its Sync Write p50 / p99 / max (us) | "
          "in process p50 / p99 / max (us) | outside, steps p50 / p99 (us) (n) | "
          "frames lost (caught up) / written | overruns | loop process CPU (ms per s) | "
          "loop thread CPU per cycle (us) | steal (%) |\n"
          "|---|---|---|---|---|---|---|---|---|---|")


def row(case: tuple[float, int], variant: str, runs: list[dict[str, Any]]) -> str:
    pooled = {k: [x for r in runs for x in r[k]] for k in
              ("send_to_write_us", "in_process_us", "outside_raw_us")}
    out = pooled["outside_raw_us"]
    lost = sum(r["skipped"] + r["bursts"] for r in runs)
    caught = sum(r["caught"] for r in runs)
    frames = sum(r["frames"] for r in runs)
    cpu = sum(r["process_cpu_s"] or 0.0 for r in runs)
    wall = sum(r["wall_s"] or 0.0 for r in runs)
    per_cycle = [r["cpu_per_cycle_us"] for r in runs if r["cpu_per_cycle_us"] is not None]
    steal = [r["steal"] for r in runs if r.get("steal") is not None]
    errors = "; ".join(r["error"] for r in runs if r.get("error"))
    outside = (f"{_pct(out, 50):.0f} / {_pct(out, 99):.0f} ({len(out)})" if out else "-")
    return (f"| {case[0]:g} / {case[1] // 1_000_000} | {variant} | "
            f"{_triple(pooled['send_to_write_us'])} | {_triple(pooled['in_process_us'])} | "
            f"{outside} | {lost} ({caught}) / {frames} | "
            f"{sum(r['overruns'] for r in runs)} | "
            f"{1e3 * cpu / wall if wall > 0 else math.nan:.0f} | "
            f"{np.median(per_cycle) if per_cycle else math.nan:.0f} | "
            f"{min(steal) if steal else '-'}-{max(steal) if steal else '-'} |"
            + (f" error: {errors}" if errors else ""))


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m bench trigger_mechanisms",
                                description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=60.0,
                   help="each variant's total per case (default 60)")
    p.add_argument("--rounds", type=int, default=3,
                   help="runs the seconds are split into, alternating (default 3)")
    p.add_argument("--cases", default="200/1,500/4",
                   help="GLOVE_HZ/MBPS,... (default 200/1,500/4)")
    p.add_argument("--variants", default=",".join(VARIANTS))
    names = ("trigger_mechanisms", "bench_trigger_mechanisms")
    return p.parse_args([a for a in argv if a not in names])


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["child"]:
        _, variant, hz, baud, seconds = argv
        child(variant, float(hz), int(baud), float(seconds))
        return
    args = parse_args(argv)
    cases = []
    for item in args.cases.split(","):
        hz, _, mbps = item.strip().partition("/")
        cases.append((float(hz), int(float(mbps) * 1_000_000)))
    variants = [v.strip() for v in args.variants.split(",")]
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"unknown variants {unknown}: pick from {', '.join(VARIANTS)}")
    each = args.seconds / args.rounds
    print(f"glove-triggered rig, 20 emulated servos with wire timing; per case and variant "
          f"{args.rounds} runs of {each:g} s, alternating (variant order rotating per "
          "round), pooled; each run a fresh interpreter", flush=True)
    runs: dict[tuple[tuple[float, int], str], list[dict[str, Any]]] = {}
    for k in range(args.rounds):
        for case in cases:
            order = variants[k % len(variants):] + variants[:k % len(variants)]
            for variant in order:
                before = b.cpu_times()
                t0 = time.strftime("%H:%M:%S", time.gmtime())
                out = subprocess.run(
                    [sys.executable, "-m", "bench.bench_trigger_mechanisms", "child", variant,
                     f"{case[0]:g}", str(case[1]), f"{each:g}"],
                    capture_output=True, text=True, cwd=ROOT)
                steal = b.steal_percent(before, b.cpu_times())
                line = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
                if not line:
                    print(f"round {k} {case} {variant}: failed\n{out.stderr[-3000:]}",
                          flush=True)
                    continue
                d = json.loads(line[0][len("RESULT "):])
                d["steal"] = steal
                runs.setdefault((case, variant), []).append(d)
                sw = d["send_to_write_us"]
                print(f"  round {k} {t0} UTC {case[0]:g} Hz {case[1] // 1_000_000} Mbps "
                      f"{variant}: sent->write p50 {_pct(sw, 50)} p99 {_pct(sw, 99)}, in "
                      f"process p50 {_pct(d['in_process_us'], 50)} p99 "
                      f"{_pct(d['in_process_us'], 99)}, lost {d['skipped'] + d['bursts']}, "
                      f"CPU {1e3 * (d['process_cpu_s'] or 0) / (d['wall_s'] or 1):.0f} ms/s, "
                      f"steal {steal} %" + (f", error: {d['error']}" if d.get("error") else ""),
                      flush=True)
    print(HEADER)
    for case in cases:
        for variant in variants:
            if (case, variant) in runs:
                print(row(case, variant, runs[(case, variant)]))


if __name__ == "__main__":
    main()
