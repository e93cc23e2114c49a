"""Two hands, a glove each: glove frame to servo command for each hand.

The two-hand cases of ``python -m bench rig``: two gloves at 200 Hz (each an
emulator in a process of its own streaming the stepping recording of
:mod:`bench.bench_rig`, the left one half a step later, so that each glove's steps
find the goals settled) and 40 emulated servos with wire timing, on one bus at
4 Mbps (``config/rigs/puppet_two_hands.toml``: the hands share the wire) or on two
buses at 1 Mbps each (``config/rigs/puppet_two_buses.toml``: a bus and a writer per
hand), both hands' loops in the one ``handrig`` process. For each hand:

* in process: from a glove frame's arrival (stamped by that hand's loop blocking on
  its glove's port) to the Sync Write carrying it handed to the OS, p50/p99/max;
* from outside: that glove emulator's send time of a frame carrying a step to the
  bus emulator's receipt of the first Sync Write whose goals for that hand's servos
  moved;
* frames lost (skipped by the loop, left waiting by host stalls, lost in the glove's
  bursts), overruns, writes and reads per second.

Targets on the project's 2-core machine: p50 at most 400 us and p99 at most 1.5 ms
for each hand, no frame lost.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.rig_steps import (
    INDEX_CHANNEL,
    STEP_S,
    _glove_file,
    cpu_times,
    emulator,
    outside_latencies,
    steal_percent,
    step_recording,
)
from handrig.app.hands import build_session_parts
from handrig.app.session import LiveOptions, run_live
from handrig.config.loading import CONFIG_DIR
from handrig.devices.glove_recording import GloveRecording, write_glove_recording

GLOVE_HZ = 200.0
HANDS = (("ri", "right"), ("le", "left"))


@dataclass
class HandsCase:
    buses: int  # 1: both hands on one bus; 2: a bus per hand
    mbps: int

    @property
    def preset(self) -> str:
        return "puppet_two_hands" if self.buses == 1 else "puppet_two_buses"

    @property
    def label(self) -> str:
        return (f"two hands, one bus at {self.mbps} Mbps" if self.buses == 1
                else f"two hands, two buses at {self.mbps} Mbps each")


CASES = (HandsCase(1, 4), HandsCase(2, 1))


def _rig_file(folder: Path, case: HandsCase) -> Path:
    """The preset, ``glove`` loop mode, at the case's baud on every bus."""
    text = (CONFIG_DIR / "rigs" / f"{case.preset}.toml").read_text(encoding="utf-8")
    text = re.sub(r"(?m)^baud = \d+", f"baud = {case.mbps * 1_000_000}", text)
    path = folder / f"{case.preset}_{case.mbps}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _shifted(rec: GloveRecording, by_s: float) -> GloveRecording:
    k = round(by_s * rec.rate_hz)
    return GloveRecording(t_s=rec.t_s, raw=np.roll(rec.raw, k, axis=0), buttons=rec.buttons,
                          channel_names=rec.channel_names, quat_xyzw=rec.quat_xyzw,
                          rate_hz=rec.rate_hz)


def _sends(log: Path) -> list[tuple[float, int]]:
    return [(float(a), int(c)) for a, _, c in
            (line.split() for line in log.read_text().splitlines() if line)]


def _writes(log: Path, columns: slice) -> list[tuple[float, tuple[int, ...]]]:
    out = []
    for line in log.read_text().splitlines():
        fields = line.split()
        if fields:
            out.append((float(fields[0]), tuple(int(v) for v in fields[1:])[columns]))
    return out


def _outside(lat_s: list[float]) -> dict[str, Any]:
    lat = np.array(lat_s) * 1e6
    if not len(lat):
        return {"p50": None, "p99": None, "max": None, "n": 0}
    return {"p50": round(float(np.percentile(lat, 50)), 1),
            "p99": round(float(np.percentile(lat, 99)), 1),
            "max": round(float(lat.max()), 1), "n": len(lat)}


@contextlib.contextmanager
def _buses(case: HandsCase, rig: Path, folder: Path) -> Iterator[dict[str, tuple[str, Path]]]:
    """The bus emulator(s): hand -> (port, its write log)."""
    with contextlib.ExitStack() as stack:
        if case.buses == 1:
            log = folder / "bus_hands_one.log"
            port = stack.enter_context(emulator(["bus", "--rig", str(rig), "--log", str(log)],
                                                "the bus emulator"))
            yield {"ri": (port, log), "le": (port, log)}
            return
        out = {}
        for h, _ in HANDS:
            log = folder / f"bus_hands_{h}.log"
            out[h] = (stack.enter_context(emulator(
                ["bus", "--rig", str(rig), "--hand", h, "--log", str(log)],
                f"the {h} bus emulator")), log)
        yield out


def run_hands_case(case: HandsCase, seconds: float, folder: Path) -> dict[str, Any]:
    rig = _rig_file(folder, case)
    glove_cfg = _glove_file(folder)
    parts = build_session_parts(rig, glove_cfg, glove_cfg, glove_per_hand=True)
    rec = step_recording()
    recs = {"ri": rec, "le": _shifted(rec, STEP_S / 2)}
    paths = {}
    for h, _ in HANDS:
        paths[h] = folder / f"steps_{h}.csv"
        write_glove_recording(paths[h], recs[h])
    glove_logs = {h: folder / f"glove_hands_{h}.log" for h, _ in HANDS}
    with _buses(case, rig, folder) as buses, contextlib.ExitStack() as gloves:
        ports = {h: gloves.enter_context(emulator(
            ["glove", str(paths[h]), "--rate", f"{GLOVE_HZ:g}", "--log", str(glove_logs[h])],
            f"the {name} glove emulator")) for h, name in HANDS}
        before = cpu_times()
        result = run_live(parts, LiveOptions(
            glove=ports["ri"], glove_left=ports["le"], bus=buses["ri"][0],
            bus_left=buses["le"][0], duration_s=seconds, log=lambda s: None))
        steal = steal_percent(before, cpu_times())
    n_right = len(parts.hands[0].rig_config.servos)
    hands = {}
    for h, name in HANDS:
        columns = (slice(0, n_right) if h == "ri" else slice(n_right, None)) \
            if case.buses == 1 else slice(None)
        values = recs[h].raw[:, INDEX_CHANNEL].copy()
        lat = outside_latencies(_sends(glove_logs[h]), values, _writes(buses[h][1], columns))
        hands[name] = {"summary": result.summary.get("hands", {}).get(name, {}),
                       "outside_us": _outside(lat)}
    return {"case": case, "hands": hands, "error": result.summary.get("error"),
            "torque_off": result.summary.get("torque_off"), "steal_pct": steal}


HANDS_HEADER = (
    "| case | hand | in-process end to end p50 / p99 / max (us) | outside p50 / p99 / max "
    "(us) (steps) | frames lost (skipped; host stalls; glove bursts) | caught up | "
    "overruns | writes/s | reads/s | CPU stolen (%) |\n"
    "|---|---|---|---|---|---|---|---|---|---|")


def hands_rows(r: dict[str, Any]) -> list[str]:
    rows = []
    for name, part in r["hands"].items():
        s, o = part["summary"], part["outside_us"]
        lat = s.get("latency_us") or {}
        lost = (s.get("frames_skipped", 0) + s.get("frames_in_host_stalls", 0)
                + s.get("frames_in_bursts", 0))
        err = f" error: {r['error']}" if r.get("error") else ""
        rows.append(
            f"| {r['case'].label} | {name} | {lat.get('p50')} / {lat.get('p99')} / "
            f"{lat.get('max')} | {o['p50']} / {o['p99']} / {o['max']} ({o['n']}) | {lost} "
            f"({s.get('frames_skipped', 0)}; {s.get('frames_in_host_stalls', 0)}; "
            f"{s.get('frames_in_bursts', 0)}) | {s.get('frames_caught_up', 0)} | "
            f"{s.get('overruns')} | {s.get('writes_per_s')} | {s.get('reads_per_s')} | "
            f"{r.get('steal_pct')} |{err}")
    return rows


def parse_hands_cases(text: str) -> list[Any]:
    """The two-hand cases ``hands/1`` and ``hands/2`` in ``text`` (empty: both)."""
    if not text.strip():
        return list(CASES)
    wanted = [item.strip() for item in text.split(",") if item.strip().startswith("hands/")]
    by_name = {f"hands/{c.buses}": c for c in CASES}
    unknown = [w for w in wanted if w not in by_name]
    if unknown:
        raise SystemExit(f"HANDRIG_BENCH_CASES: {unknown[0]!r} is not hands/1 (one bus) or "
                         "hands/2 (two buses)")
    return [by_name[w] for w in wanted]


def main() -> None:
    """The two-hand cases alone (``python -m bench rig_hands``; ``python -m bench rig``
    runs them after the one-hand cases): ``HANDRIG_BENCH_SECONDS`` each (default 60 s;
    ``HANDRIG_BENCH_QUICK=1``: 10 s), ``HANDRIG_BENCH_CASES`` ``hands/1``, ``hands/2``."""
    quick = bool(os.environ.get("HANDRIG_BENCH_QUICK"))
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 10.0 if quick else 60.0))
    print(f"two hands: two gloves at {GLOVE_HZ:g} Hz, 40 emulated servos with wire timing, "
          f"{seconds:g} s per case", flush=True)
    print(HANDS_HEADER, flush=True)
    with tempfile.TemporaryDirectory(prefix="bench_rig_hands_") as tmp:
        for case in parse_hands_cases(os.environ.get("HANDRIG_BENCH_CASES", "")):
            for line in hands_rows(run_hands_case(case, seconds, Path(tmp))):
                print(line, flush=True)


if __name__ == "__main__":
    main()
