"""What the rig benchmarks share: the stepping glove recording, the outside latency
of a step, the emulators in processes of their own, the hypervisor's steal share.

:mod:`bench.bench_rig` (one hand) and :mod:`bench.bench_rig_hands` (two hands) both
import this module; neither imports the other back.
"""

from __future__ import annotations

import bisect
import contextlib
import re
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from handrig.app.factory import port_process
from handrig.config.loading import CONFIG_DIR
from handrig.devices.glove_recording import GloveRecording

STEP_S = 0.25  # the index channel steps this often (the goals settle well within it)
INDEX_CHANNEL = 3  # riIndexMCPy in config/glove.toml
RAW_LOW, RAW_HIGH = 1800.0, 2200.0  # the step: about 18 deg of index MCP flexion
SETTLE_WINDOW_S = 0.05  # how far after a step its first moving write is looked for
ROOT = Path(__file__).resolve().parent.parent


def step_recording(channels: int = 5) -> GloveRecording:
    """A looping 2 * STEP_S recording at 1 kHz: constant channels, the index stepping."""
    t = np.arange(0.0, 2 * STEP_S, 0.001)
    raw = np.full((len(t), channels), 2000.0)
    raw[:, INDEX_CHANNEL] = np.where(t < STEP_S, RAW_LOW, RAW_HIGH)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
    return GloveRecording(t_s=t, raw=raw, buttons=np.zeros(len(t), dtype=np.int64),
                          channel_names=tuple(f"ch{k}" for k in range(channels)),
                          quat_xyzw=quat, rate_hz=1000.0)


def outside_latencies(sends: Sequence[tuple[float, int]], values: np.ndarray,
                      writes: Sequence[tuple[float, tuple[int, ...]]]) -> list[float]:
    """Send time of each frame that carries a step (``values[index]`` differs from the
    previous frame's) to the receipt of the first write whose goals differ from the
    settled goals before it. ``sends``: (time, sample index); ``writes``: (time, goal
    ticks), both sorted by time. Steps whose goals had not settled (the two writes
    before the step differ) are left out."""
    times = [t for t, _ in writes]
    out: list[float] = []
    previous = None
    for t_send, index in sends:
        v = values[index]
        if previous is not None and v != previous:
            j = bisect.bisect_right(times, t_send)
            if j >= 2 and writes[j - 1][1] == writes[j - 2][1]:
                settled = writes[j - 1][1]
                for k in range(j, len(writes)):
                    t_k, goals = writes[k]
                    if t_k - t_send > SETTLE_WINDOW_S:
                        break
                    if goals != settled:
                        out.append(t_k - t_send)
                        break
        previous = v
    return out


@contextlib.contextmanager
def emulator(argv: list[str], what: str) -> Iterator[str]:
    """``python -m bench.latency_emulators ARGV`` (off the loop's CPU); yields its port."""
    with port_process(argv, what, module="bench.latency_emulators", cwd=ROOT) as (_, port):
        yield port


def _glove_file(folder: Path) -> Path:
    text = (CONFIG_DIR / "glove.toml").read_text(encoding="utf-8")
    text = re.sub(r"(?ms)(^\[filter\].*?^enabled = )true", r"\1false", text, count=1)
    path = folder / "glove_unfiltered.toml"
    path.write_text(text, encoding="utf-8")
    return path


def cpu_times() -> tuple[int, int]:
    """(all, steal) jiffies of every CPU so far (``/proc/stat``; (0, 0) elsewhere)."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
    except OSError:
        return 0, 0
    ticks = [int(v) for v in fields]
    return sum(ticks[:8]), ticks[7] if len(ticks) > 7 else 0


def steal_percent(before: tuple[int, int], after: tuple[int, int]) -> float | None:
    """The share of CPU time the hypervisor gave to other guests between two samples."""
    total = after[0] - before[0]
    return round(100.0 * (after[1] - before[1]) / total, 1) if total > 0 else None
