"""The rig's glove-to-servo latency, two checkouts side by side in one run.

``python bench/compare_rig.py OLD_CHECKOUT [NEW_CHECKOUT] [--rounds N] [--seconds S]
[--hz HZ] [--baud BAUD]`` runs :func:`bench.bench_rig.run_case` (glove-triggered
loop, both emulators in processes of their own) alternately on each checkout's code,
each run in a fresh interpreter whose ``handrig`` is imported from that checkout,
and prints each run and the medians: in-process end to end, outside (the glove
emulator's send to the bus emulator's receipt of the first Sync Write that moved),
compute, reads, writes delayed, frames skipped, CPU per cycle and the hypervisor's
steal share. NEW_CHECKOUT defaults to this one. The rig file is written here (the
same text for both), so an old checkout whose own bench cannot write it still runs.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent


def child(root: str, mode: str, hz: float, baud: int, seconds: float) -> None:
    """One run on ``root``'s code; prints one ``RESULT {json}`` line."""
    sys.path.insert(0, root)
    import handrig
    from bench import bench_rig as b

    if not str(Path(handrig.__file__).resolve()).startswith(str(Path(root).resolve())):
        raise SystemExit(f"handrig came from {handrig.__file__}, not {root}")

    def rig_file(folder: Path, mode: str, rate_hz: float, baud: int) -> Path:
        text = (b.CONFIG_DIR / "rig.toml").read_text(encoding="utf-8")
        text = re.sub(r"(?m)^baud = \d+", f"baud = {baud}", text, count=1)
        text = re.sub(r"(?m)^rate_hz = [\d.]+", f"rate_hz = {rate_hz:g}", text, count=1)
        text, n = re.subn(r'(?m)^mode = "\w+"', f'mode = "{mode}"', text, count=1)
        if not n:
            text = text.replace("[loop]\n", f'[loop]\nmode = "{mode}"\n', 1)
        path = folder / f"rig_{mode}_{rate_hz:g}_{baud}.toml"
        path.write_text(text, encoding="utf-8")
        return path

    b._rig_file = rig_file

    def steal() -> tuple[int, int]:
        ticks = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
        return sum(ticks), ticks[7]
    with tempfile.TemporaryDirectory(prefix="compare_rig_") as tmp:
        folder = Path(tmp)
        rec = b.step_recording()
        rec_path = folder / "steps.csv"
        b.write_glove_recording(rec_path, rec)
        before = steal()
        r = b.run_case(b.Case(mode, hz, baud), seconds, folder, rec_path,
                       rec.raw[:, b.INDEX_CHANNEL].copy())
        after = steal()
    s = r["summary"]
    stolen = (round(100.0 * (after[1] - before[1]) / (after[0] - before[0]), 1)
              if after[0] > before[0] else None)
    print("RESULT " + json.dumps({
        "lat": s["latency_us"], "comp": s["compute_us"], "out": r["outside_us"],
        "skipped": s["frames_skipped"], "delayed": s["writes_delayed_by_reads"],
        "reads": s["reads_per_s"], "cpu": s["cpu_per_cycle_us"], "steal": stolen}), flush=True)


def _median(runs: list[dict[str, Any]], key: str, sub: str) -> float | None:
    values = [r[key][sub] for r in runs if r[key][sub] is not None]
    return round(statistics.median(values), 1) if values else None


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "child":
        _, _, root, mode, hz, baud, seconds = sys.argv
        child(root, mode, float(hz), int(baud), float(seconds))
        return 0
    p = argparse.ArgumentParser(prog="python bench/compare_rig.py")
    p.add_argument("old")
    p.add_argument("new", nargs="?", default=str(HERE))
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--hz", type=float, default=200.0)
    p.add_argument("--baud", type=int, default=1_000_000)
    args = p.parse_args()
    checkouts = {"old": str(Path(args.old).resolve()), "new": str(Path(args.new).resolve())}
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in checkouts}
    print(f"glove-triggered rig, {args.hz:g} Hz glove, {args.baud / 1e6:g} Mbps, "
          f"{args.seconds:g} s per run, old and new alternating, {args.rounds} rounds; "
          f"old {checkouts['old']}, new {checkouts['new']}", flush=True)
    for k in range(args.rounds):
        for name, root in checkouts.items():
            out = subprocess.run(
                [sys.executable, str(Path(__file__).resolve()), "child", root, "glove",
                 f"{args.hz:g}", str(args.baud), f"{args.seconds:g}"],
                capture_output=True, text=True, cwd=root)
            line = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
            if not line:
                print(f"round {k} {name}: failed\n{out.stderr[-2000:]}", flush=True)
                continue
            d = json.loads(line[0][len("RESULT "):])
            runs[name].append(d)
            print(f"round {k} {name}: in-process p50 {d['lat']['p50']} p99 {d['lat']['p99']} "
                  f"| outside p50 {d['out']['p50']} p99 {d['out']['p99']} | compute p50 "
                  f"{d['comp']['p50']} | reads/s {d['reads']} | delayed {d['delayed']} | "
                  f"skipped {d['skipped']} | CPU/cycle {d['cpu']} us | steal {d['steal']} %",
                  flush=True)
    print("medians (us):")
    for name, rs in runs.items():
        if rs:
            print(f"  {name}: in-process p50 {_median(rs, 'lat', 'p50')} p99 "
                  f"{_median(rs, 'lat', 'p99')} | outside p50 {_median(rs, 'out', 'p50')} p99 "
                  f"{_median(rs, 'out', 'p99')} | compute p50 {_median(rs, 'comp', 'p50')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
