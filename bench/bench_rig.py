"""Glove frame to servo command, as the puppeteer feels it: fixed-rate loop vs glove-triggered.

Each case runs the real rig (SerialGlove reader, pipeline, Dynamixel driver) between
two emulators in processes of their own (:mod:`bench.latency_emulators`): a glove
streaming a recording whose index channel steps every ``STEP_S`` (all other
channels constant; the glove's One Euro filter off so a step moves the goals in the
very next write) and 20 emulated servos with wire timing at 1 or 4 Mbps (moving
kinematically: no physics thread in the bus emulator's process to hold up its
receipt stamps). For each
of fixed-rate (at the glove's rate) and glove-triggered loops, at 200 and 500 Hz
gloves, it reports:

* in process: end-to-end latency (a frame's arrival at the host to its Sync Write
  handed to the OS) and its compute part, p50/p99/max;
* from outside: the glove emulator's send time of the frame carrying a step to the
  bus emulator's receipt of the first Sync Write whose goals moved (both
  CLOCK_MONOTONIC; only steps that found the goals settled count);
* writes and reads per second, writes delayed by reads, glove frames the loop
  skipped, overruns, CPU of the loop's thread per cycle.

Then the two-hand cases (:mod:`bench.bench_rig_hands`): two gloves at 200 Hz and
40 servos, on one bus at 4 Mbps and on two buses at 1 Mbps each, latency and frames
lost per hand.

``HANDRIG_BENCH_SECONDS`` sets each case's length (default 60 s;
``HANDRIG_BENCH_QUICK=1``: 10 s); ``HANDRIG_BENCH_CASES`` picks cases, as
``MODE/GLOVE_HZ/MBPS`` separated by commas (``glove/500/4,glove/200/4``), and
``hands/1`` (one bus) and ``hands/2`` (two buses) for the two-hand ones (default all
eight and both two-hand cases); ``HANDRIG_BENCH_APPEND=1`` also appends the table as
a dated section to ``docs/measurements-history.md`` (docs/measurements.md keeps the
current figures).
"""

from __future__ import annotations

import datetime
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.bench_rig_hands import HANDS_HEADER, hands_rows, parse_hands_cases, run_hands_case
from bench.rig_steps import (
    INDEX_CHANNEL,
    ROOT,
    STEP_S,
    _glove_file,
    cpu_times,
    emulator,
    outside_latencies,
    steal_percent,
    step_recording,
)
from handrig.app.parts import build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.config.loading import CONFIG_DIR
from handrig.devices.glove_recording import write_glove_recording


def _rig_file(folder: Path, mode: str, rate_hz: float, baud: int,
              source: Path | None = None) -> Path:
    """A copy of ``source`` (default: the installed ``config/rig.toml``) with the case's
    loop mode, fixed rate and baud rate."""
    text = (source or CONFIG_DIR / "rig.toml").read_text(encoding="utf-8")
    text = re.sub(r"(?m)^baud = \d+", f"baud = {baud}", text, count=1)
    text = re.sub(r"(?m)^rate_hz = [\d.]+", f"rate_hz = {rate_hz:g}", text, count=1)
    text, n = re.subn(r'(?m)^mode = "\w+"', f'mode = "{mode}"', text, count=1)
    if not n:
        text = text.replace("[loop]\n", f'[loop]\nmode = "{mode}"\n', 1)
    path = folder / f"rig_{mode}_{rate_hz:g}_{baud}.toml"
    path.write_text(text, encoding="utf-8")
    return path


@dataclass
class Case:
    mode: str
    glove_hz: float
    baud: int


def run_case(case: Case, seconds: float, folder: Path, rec_path: Path,
             values: np.ndarray, layering: Any = None) -> dict[str, Any]:
    tag = f"{case.mode}_{case.glove_hz:g}_{case.baud}"
    rig_path = _rig_file(folder, case.mode, case.glove_hz, case.baud)
    glove_log, bus_log = folder / f"glove_{tag}.log", folder / f"bus_{tag}.log"
    parts = build_parts(rig_path, _glove_file(folder))
    with (emulator(["bus", "--rig", str(rig_path), "--log", str(bus_log)],
                   "the bus emulator") as bus_port,
          emulator(["glove", str(rec_path), "--rate", f"{case.glove_hz:g}",
                    "--log", str(glove_log)], "the glove emulator") as glove_port):
        before = cpu_times()
        result = run_live(parts, LiveOptions(glove=glove_port, bus=bus_port,
                                             duration_s=seconds, log=lambda s: None,
                                             profile=bool(os.environ.get("HANDRIG_BENCH_PROFILE")),
                                             layering=layering))
        steal = steal_percent(before, cpu_times())
    sends = [(float(a), int(c)) for a, _, c in
             (line.split() for line in glove_log.read_text().splitlines() if line)]
    writes = []
    for line in bus_log.read_text().splitlines():
        fields = line.split()
        if fields:
            writes.append((float(fields[0]), tuple(int(v) for v in fields[1:])))
    lat = np.array(outside_latencies(sends, values, writes)) * 1e6
    s = result.summary
    outside = ({"p50": round(float(np.percentile(lat, 50)), 1),
                "p99": round(float(np.percentile(lat, 99)), 1),
                "max": round(float(lat.max()), 1), "n": len(lat)}
               if len(lat) else {"p50": None, "p99": None, "max": None, "n": 0})
    return {"case": case, "summary": s, "outside_us": outside, "steal_pct": steal}


def run_step_case(case: Case, seconds: float, folder: Path,
                  layering: Any = None) -> dict[str, Any]:
    """:func:`run_case` on the stepping recording, written into ``folder`` (``layering``:
    takes layered under the glove, :class:`handrig.app.layering.LayerOptions`)."""
    rec = step_recording()
    rec_path = folder / "steps.csv"
    write_glove_recording(rec_path, rec)
    return run_case(case, seconds, folder, rec_path, rec.raw[:, INDEX_CHANNEL].copy(),
                    layering)


def _row(r: dict[str, Any]) -> str:
    c, s, o = r["case"], r["summary"], r["outside_us"]
    lat, comp = s["latency_us"], s["compute_us"]
    err = f" error: {s['error']}" if "error" in s else ""
    return (f"| {c.mode} | {c.glove_hz:g} | {c.baud // 1_000_000} | "
            f"{lat['p50']} / {lat['p99']} / {lat['max']} | {comp['p50']} / {comp['p99']} | "
            f"{o['p50']} / {o['p99']} / {o['max']} ({o['n']}) | {s['writes_per_s']} | "
            f"{s['reads_per_s']} | {s['writes_delayed_by_reads']} | {s['frames_skipped']} "
            f"({s.get('frames_caught_up', 0)}; {s.get('frames_in_bursts', 0)}) | "
            f"{s['overruns']} | {s['cpu_per_cycle_us']} | {r.get('steal_pct')} |{err}")


HEADER = ("| loop | glove Hz | Mbps | in-process end to end p50 / p99 / max (us) | "
          "compute p50 / p99 (us) | outside p50 / p99 / max (us) (steps) | writes/s | "
          "reads/s | writes delayed by reads | frames skipped by the loop (caught up; in "
          "the glove's bursts) | overruns | "
          "CPU/cycle (us) | CPU stolen by the hypervisor (%) |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def parse_cases(text: str) -> list[Case]:
    """``MODE/GLOVE_HZ/MBPS,...`` as cases (empty: all eight, fixed and glove-triggered
    at 200 and 500 Hz, 1 and 4 Mbps); the two-hand cases (``hands/N``) are left out."""
    if not text.strip():
        return [Case(mode, hz, baud) for hz in (200.0, 500.0)
                for baud in (1_000_000, 4_000_000) for mode in ("fixed", "glove")]
    cases = []
    for item in text.split(","):
        if item.strip().startswith("hands/"):
            continue
        parts = item.strip().split("/")
        if (len(parts) != 3 or parts[0] not in ("fixed", "glove")
                or not parts[1].replace(".", "", 1).isdigit() or not parts[2].isdigit()):
            raise SystemExit(f"HANDRIG_BENCH_CASES: {item!r} is not MODE/GLOVE_HZ/MBPS "
                             "(MODE fixed or glove), e.g. glove/500/4")
        cases.append(Case(parts[0], float(parts[1]), int(parts[2]) * 1_000_000))
    return cases


def main() -> None:
    quick = bool(os.environ.get("HANDRIG_BENCH_QUICK"))
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 10.0 if quick else 60.0))
    text = os.environ.get("HANDRIG_BENCH_CASES", "")
    only_hands = bool(text.strip()) and all(
        item.strip().startswith("hands/") for item in text.split(",") if item.strip())
    cases = [] if only_hands else parse_cases(text)
    hands_cases = parse_hands_cases(text)
    rows = []
    hand_rows: list[str] = []
    with tempfile.TemporaryDirectory(prefix="bench_rig_") as tmp:
        folder = Path(tmp)
        rec = step_recording()
        rec_path = folder / "steps.csv"
        write_glove_recording(rec_path, rec)
        values = rec.raw[:, INDEX_CHANNEL].copy()
        if cases:
            print(f"rig loop, 20 emulated servos with wire timing, {seconds:g} s per case; "
                  f"index channel steps every {STEP_S:g} s", flush=True)
            print(HEADER, flush=True)
        for case in cases:
            r = run_case(case, seconds, folder, rec_path, values)
            rows.append(r)
            print(_row(r), flush=True)
        if hands_cases:
            print(f"\ntwo hands: two gloves at 200 Hz, 40 emulated servos with wire timing, "
                  f"{seconds:g} s per case", flush=True)
            print(HANDS_HEADER, flush=True)
            for hc in hands_cases:
                for line in hands_rows(run_hands_case(hc, seconds, folder)):
                    hand_rows.append(line)
                    print(line, flush=True)
    if os.environ.get("HANDRIG_BENCH_APPEND"):
        env = " ".join(f"{k}={os.environ[k]}" for k in ("HANDRIG_BENCH_SECONDS",)
                       if k in os.environ)
        day = datetime.datetime.now(datetime.UTC).date().isoformat()
        text = (f"\n### Glove frame to servo command, fixed-rate vs glove-triggered ({day})\n\n"
                f"`{(env + ' ') if env else ''}HANDRIG_BENCH_APPEND=1 python -m bench rig` "
                f"({seconds:g} s per case, 20 emulated servos with wire timing, the glove "
                "emulator and the bus emulator in processes of their own, 2-core VM shared "
                "with other jobs). Fixed-rate runs at the glove's rate. In process: from a "
                "frame's arrival (stamped by the loop blocking on the port) to the Sync "
                "Write handed to the OS; outside: glove emulator send time to the bus "
                "emulator's receipt of the first Sync Write that moved, CLOCK_MONOTONIC.\n\n"
                + HEADER + "\n" + "\n".join(_row(r) for r in rows) + "\n"
                + (("\nTwo hands (two gloves at 200 Hz, 40 servos):\n\n" + HANDS_HEADER + "\n"
                    + "\n".join(hand_rows) + "\n") if hand_rows else ""))
        with (ROOT / "docs" / "measurements-history.md").open("a", encoding="utf-8") as f:
            f.write(text)


if __name__ == "__main__":
    main()
