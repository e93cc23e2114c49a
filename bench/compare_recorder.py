"""The recorder's cost on the loop's thread, this tree's against an older revision's, in
one run: ``python -m bench.compare_recorder [REV]`` (default the merge before the
recorder package, 5a4d322).

The older ``handrig/outputs/recorder.py`` is read with ``git show REV:...`` and loaded
beside the current package; both record the same 60 s of a 200 Hz glove (frames with
USB jitter, a 1 s silence), interleaved in rounds so that the shared machine's noise
falls on both alike. Printed: ``add`` per frame (median, p99, max, microseconds), the
frames written and the take's length.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from handrig import hand
from handrig.outputs.recorder import Recorder, load_performance

ROOT = Path(__file__).resolve().parents[1]


def _old_module(rev: str, folder: Path) -> ModuleType:
    text = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:handrig/outputs/recorder.py"],
                          capture_output=True, text=True, check=True).stdout
    path = folder / "old_recorder.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("old_recorder", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["old_recorder"] = module
    spec.loader.exec_module(module)
    return module


def _times(seconds: float = 60.0, rate_hz: float = 200.0) -> np.ndarray:
    rng = np.random.default_rng(0)
    t = np.arange(0.0, seconds, 1.0 / rate_hz) + rng.uniform(0, 0.3 / rate_hz,
                                                             int(seconds * rate_hz))
    return t[(t < 20.0) | (t >= 21.0)]  # a 1 s glove silence


def _record(factory: Any, path: Path, t: np.ndarray, pose: np.ndarray,
            wrist: np.ndarray) -> tuple[np.ndarray, int, float]:
    rec = factory(path, rate_hz=200.0)
    dt = np.empty(len(t))
    for i in range(len(t)):
        t0 = time.perf_counter()
        rec.add(float(t[i]), pose, wrist)
        dt[i] = time.perf_counter() - t0
    rec.close()
    times = load_performance(path)[0]
    length = float(times[-1] - times[0]) + 1.0 / 200.0
    return dt, int(rec.frames_written), length


def main() -> None:
    rev = sys.argv[1] if len(sys.argv) > 1 else "5a4d322"
    rng = np.random.default_rng(1)
    lim = hand.curve_limits_deg()
    pose = rng.uniform(lim[:, 0], lim[:, 1])
    wrist = np.array([10.0, -5.0, 3.0, 2.0])
    t = _times()
    with tempfile.TemporaryDirectory(prefix="compare_recorder_") as tmp:
        folder = Path(tmp)
        old = _old_module(rev, folder)
        results: dict[tuple[str, str], list[Any]] = {}
        for rnd in range(3):
            for fmt in ("csv", "bvh"):
                for name, factory in ((rev, old.Recorder), ("this tree", Recorder)):
                    path = folder / f"{name.replace(' ', '_')}_{rnd}.{fmt}"
                    results.setdefault((name, fmt), []).append(
                        _record(factory, path, t, pose, wrist))
    span = float(t[-1] - t[0]) + 1.0 / 200.0
    print(f"recorder add() on the loop's thread: {len(t)} frames of a 200 Hz glove with"
          f" jitter and a 1 s silence ({span:.2f} s), 3 rounds interleaved")
    for fmt in ("csv", "bvh"):
        for name in (rev, "this tree"):
            runs = results[(name, fmt)]
            dt = np.concatenate([r[0] for r in runs]) * 1e6
            frames, length = runs[-1][1], runs[-1][2]
            print(f"  {fmt} {name:>9}: median {np.median(dt):5.2f} us, p99"
                  f" {np.percentile(dt, 99):6.2f} us, max {dt.max():7.0f} us;"
                  f" {frames} frames written, take {length:.2f} s")


if __name__ == "__main__":
    main()
