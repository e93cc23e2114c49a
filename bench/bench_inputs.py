"""Huge files given to handrig's readers: seconds, peak memory and message length each.

Each reader gets a file of ``HANDRIG_BENCH_MB`` megabytes (default 10) of NULs (sparse),
of one long line and of random bytes, in a fresh interpreter of its own; printed: the
seconds until it refused (or read) the file, the process's peak resident memory less
that of an interpreter that only imported the readers, and the characters of the
message. ``python -m bench.compare --base COMMIT --benches inputs`` prints old->new.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHILD = r"""
import json, resource, sys, time
from handrig.config.rig import load_rig_config
from handrig.devices.glove_recording import read_glove_recording
from handrig.offline.bvh import read_bvh
from handrig.outputs.recorder import load_performance
from handrig.pose.maps import LinearMap
from handrig.pose.sag import SagGrid
readers = {"take csv": load_performance, "take bvh": load_performance,
           "glove take": read_glove_recording, "mocap bvh": read_bvh,
           "rig toml": load_rig_config, "map toml": LinearMap.load, "grid npz": SagGrid.load}
name, path = sys.argv[1], sys.argv[2]
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
try:
    readers[name](path)
    message = ""
except Exception as exc:
    message = str(exc)
took = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"s": took, "mb": (peak - base) / 1024, "chars": len(message)}))
"""

SUFFIX = {"take csv": ".csv", "take bvh": ".bvh", "glove take": ".csv", "mocap bvh": ".bvh",
          "rig toml": ".toml", "map toml": ".toml", "grid npz": ".npz"}


def _files(folder: Path, size: int) -> dict[str, Path]:
    nuls = folder / "nuls"
    with nuls.open("wb") as f:
        f.truncate(size)
    line = folder / "line"
    line.write_bytes(b"7" * size)
    noise = folder / "noise"
    noise.write_bytes(np.random.default_rng(41).bytes(size))
    return {"NULs": nuls, "one line": line, "random": noise}


def main() -> None:
    mb = float(os.environ.get("HANDRIG_BENCH_MB", "10"))
    size = int(mb * 1e6)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        files = _files(folder, size)
        print(f"readers given {mb:g} MB files (seconds, peak MB over an idle interpreter,"
              " message characters):")
        print(f"  {'reader':<11} {'content':<9} {'s':>7} {'MB':>7} {'chars':>9}")
        for reader, suffix in SUFFIX.items():
            for content, src in files.items():
                path = folder / f"{reader.replace(' ', '_')}_{content.replace(' ', '_')}{suffix}"
                path.symlink_to(src)
                out = subprocess.run([sys.executable, "-c", CHILD, reader, str(path)],
                                     capture_output=True, text=True, timeout=600)
                try:
                    got = json.loads(out.stdout.strip().splitlines()[-1])
                except (IndexError, ValueError):
                    print(f"  {reader:<11} {content:<9} failed: {out.stderr.strip()[-200:]}")
                    continue
                print(f"  {reader:<11} {content:<9} {got['s']:7.3f} {got['mb']:7.1f}"
                      f" {got['chars'] - len(str(path)):9d}")


if __name__ == "__main__":
    main()
