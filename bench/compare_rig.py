"""The rig's glove-to-servo latency, two checkouts side by side in one run.

``python bench/compare_rig.py OLD_CHECKOUT [NEW_CHECKOUT] [--rounds N] [--seconds S]
[--hz HZ] [--baud BAUD] [--old-set KEY=VALUE ...] [--new-set KEY=VALUE ...]`` runs
:func:`bench.bench_rig.run_case` (glove-triggered loop, both emulators in processes
of their own) alternately on each checkout's code, each run in a fresh interpreter
whose ``handrig`` is imported from that checkout, and prints each run and the
medians: in-process end to end, outside (the glove emulator's send to the bus
emulator's receipt of the first Sync Write that moved), compute, reads, writes
delayed, frames skipped (caught up, lost in the glove's bursts), CPU per cycle and
the hypervisor's steal share (taken around each run). NEW_CHECKOUT defaults to this
one. Each checkout runs on its own ``config/rig.toml``, set to the case's loop mode
and baud rate by this checkout's bench, the same way for both (an old checkout's own
bench may not write it right); ``--old-set`` / ``--new-set`` change a line of that side's rig file
(``--old-set catch_up=false``: one checkout against itself, a setting apart).
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


def child(root: str, rig_path: str, mode: str, hz: float, baud: int, seconds: float) -> None:
    """One run on ``root``'s code with the rig file ``rig_path``; prints one
    ``RESULT {json}`` line."""
    sys.path.insert(0, root)
    import handrig
    from bench import bench_rig as b

    if not str(Path(handrig.__file__).resolve()).startswith(str(Path(root).resolve())):
        raise SystemExit(f"handrig came from {handrig.__file__}, not {root}")
    b._rig_file = lambda *args, **kwargs: Path(rig_path)
    with tempfile.TemporaryDirectory(prefix="compare_rig_") as tmp:
        folder = Path(tmp)
        rec = b.step_recording()
        rec_path = folder / "steps.csv"
        b.write_glove_recording(rec_path, rec)
        r = b.run_case(b.Case(mode, hz, baud), seconds, folder, rec_path,
                       rec.raw[:, b.INDEX_CHANNEL].copy())
    s = r["summary"]
    print("RESULT " + json.dumps({
        "lat": s["latency_us"], "comp": s["compute_us"], "out": r["outside_us"],
        "skipped": s["frames_skipped"], "caught": s.get("frames_caught_up", 0),
        "bursts": s.get("frames_in_bursts", 0),
        "delayed": s["writes_delayed_by_reads"],
        "reads": s["reads_per_s"], "cpu": s["cpu_per_cycle_us"]}), flush=True)


def _set_lines(path: Path, settings: list[str]) -> None:
    """Give each ``KEY=VALUE`` its value in the rig file at ``path`` (the key's first
    line), or add it to ``[loop]`` when the file has no such key."""
    text = path.read_text(encoding="utf-8")
    for kv in settings:
        key, sep, value = kv.partition("=")
        if not sep or not re.fullmatch(r"\w+", key):
            raise SystemExit(f"--old-set/--new-set takes KEY=VALUE, got {kv!r}")
        text, n = re.subn(rf"(?m)^{key} = [^\s#]+", f"{key} = {value}", text, count=1)
        if not n:
            text = text.replace("[loop]\n", f"[loop]\n{key} = {value}\n", 1)
    path.write_text(text, encoding="utf-8")


def _median(runs: list[dict[str, Any]], key: str, sub: str) -> float | None:
    values = [r[key][sub] for r in runs if r[key][sub] is not None]
    return round(statistics.median(values), 1) if values else None


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "child":
        _, _, root, rig_path, mode, hz, baud, seconds = sys.argv
        child(root, rig_path, mode, float(hz), int(baud), float(seconds))
        return 0
    sys.path.insert(0, str(HERE))
    from bench.bench_rig import _rig_file
    from bench.rig_steps import cpu_times, steal_percent

    p = argparse.ArgumentParser(prog="python bench/compare_rig.py")
    p.add_argument("old")
    p.add_argument("new", nargs="?", default=str(HERE))
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--hz", type=float, default=200.0)
    p.add_argument("--baud", type=int, default=1_000_000)
    p.add_argument("--old-set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--new-set", action="append", default=[], metavar="KEY=VALUE")
    args = p.parse_args()
    checkouts = {"old": str(Path(args.old).resolve()), "new": str(Path(args.new).resolve())}
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in checkouts}
    print(f"glove-triggered rig, {args.hz:g} Hz glove, {args.baud / 1e6:g} Mbps, "
          f"{args.seconds:g} s per run, old and new alternating, {args.rounds} rounds; "
          f"old {checkouts['old']} {' '.join(args.old_set)}, new {checkouts['new']} "
          f"{' '.join(args.new_set)}", flush=True)
    rigs = tempfile.TemporaryDirectory(prefix="compare_rig_rigs_")
    # each checkout runs on its own rig.toml, written the same way for both (an old
    # checkout's own bench may not write it right)
    rig_paths = {}
    for name, root in checkouts.items():
        folder = Path(rigs.name) / name
        folder.mkdir()
        rig_paths[name] = _rig_file(folder, "glove", args.hz, args.baud,
                                    Path(root) / "config" / "rig.toml")
        _set_lines(rig_paths[name], args.old_set if name == "old" else args.new_set)
    for k in range(args.rounds):
        for name, root in checkouts.items():
            before = cpu_times()
            out = subprocess.run(
                [sys.executable, str(Path(__file__).resolve()), "child", root,
                 str(rig_paths[name]), "glove", f"{args.hz:g}", str(args.baud),
                 f"{args.seconds:g}"],
                capture_output=True, text=True, cwd=root)
            stolen = steal_percent(before, cpu_times())
            line = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
            if not line:
                print(f"round {k} {name}: failed\n{out.stderr[-2000:]}", flush=True)
                continue
            d = json.loads(line[0][len("RESULT "):])
            d["steal"] = stolen
            runs[name].append(d)
            print(f"round {k} {name}: in-process p50 {d['lat']['p50']} p99 {d['lat']['p99']} "
                  f"| outside p50 {d['out']['p50']} p99 {d['out']['p99']} | compute p50 "
                  f"{d['comp']['p50']} | reads/s {d['reads']} | delayed {d['delayed']} | "
                  f"skipped {d['skipped']} (caught up {d.get('caught', 0)}, lost in bursts "
                  f"{d.get('bursts', 0)}) | CPU/cycle "
                  f"{d['cpu']} us | steal {d['steal']} %",
                  flush=True)
    rigs.cleanup()
    print("medians (us):")
    for name, rs in runs.items():
        if rs:
            print(f"  {name}: in-process p50 {_median(rs, 'lat', 'p50')} p99 "
                  f"{_median(rs, 'lat', 'p99')} | outside p50 {_median(rs, 'out', 'p50')} p99 "
                  f"{_median(rs, 'out', 'p99')} | compute p50 {_median(rs, 'comp', 'p50')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
