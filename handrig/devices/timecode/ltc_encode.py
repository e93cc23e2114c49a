"""LTC written from the SMPTE 12M facts (:mod:`handrig.devices.timecode.ltc`): audio
for the tests, the benchmark and a rehearsal without a timecode generator.

:func:`render` turns a list of :class:`Segment` (timecode running from a start for a
number of frames at a speed, or silence) into samples, and gives the time each
frame's bit 0 began: what a decoder must find.
"""

from __future__ import annotations

import wave
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig.devices.timecode.ltc import BITS, FrameRate, Timecode, pack

RISE_S = 25e-6
"""The rise and fall time of the edges (SMPTE 12M: 25 us +- 5 us)."""


@dataclass(frozen=True)
class Segment:
    """``frames`` frames of timecode from ``start`` at ``fps``, played ``speed`` times as
    fast as real time (1.001: 0.1 % fast); ``start=None``: ``silence_s`` of silence."""

    start: Timecode | None
    frames: int = 0
    fps: FrameRate | None = None
    speed: float = 1.0
    silence_s: float = 0.0


@dataclass(frozen=True)
class Rendered:
    """Samples (float32, -1..1), their rate, and each frame written: its timecode and
    the time (s from the first sample) its bit 0 began."""

    samples: NDArray[np.float32]
    sample_rate_hz: int
    timecodes: tuple[Timecode, ...]
    starts_s: NDArray[np.float64]
    stretches: tuple[tuple[float, float, int, float], ...] = ()
    """Each run of timecode: (from_s, to_s, its first frame number, frames a second)."""

    def frame_at(self, t_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """The true timecode (fractional frame number) at audio times ``t_s``: NaN before
        the first frame, held at a stretch's end until the next begins (a stop)."""
        t = np.asarray(t_s, dtype=np.float64)
        out = np.full(t.shape, np.nan)
        for k, (a, b, n0, rate) in enumerate(self.stretches):
            end = self.stretches[k + 1][0] if k + 1 < len(self.stretches) else np.inf
            inside = (t >= a) & (t < end)
            out[inside] = n0 + (np.minimum(t[inside], b) - a) * rate
        return out


def render(segments: list[Segment], sample_rate_hz: int = 48000, *,
           amplitude: float = 0.5, lead_s: float = 0.05) -> Rendered:
    """The audio of ``segments`` after ``lead_s`` of silence (see :class:`Segment`)."""
    edges: list[NDArray[np.float64]] = []
    bit_periods: list[float] = []
    stretches: list[tuple[float, float, int, float]] = []
    tcs: list[Timecode] = []
    starts: list[float] = []
    t = lead_s
    for seg in segments:
        if seg.start is None or seg.fps is None:
            t += seg.silence_s
            continue
        bit_s = 1.0 / (seg.fps.rate_hz * seg.speed * BITS)
        first = seg.start.frame_number(seg.fps.nominal)
        words = []
        for k in range(seg.frames):
            tc = Timecode.from_frame_number(first + k, seg.fps)
            tcs.append(tc)
            starts.append(t + k * BITS * bit_s)
            words.append(pack(tc, fps25=seg.fps.nominal == 25))
        stretches.append((t, t + seg.frames * BITS * bit_s, first, seg.fps.rate_hz * seg.speed))
        bits = np.array([(w >> i) & 1 for w in words for i in range(BITS)], dtype=np.int64)
        at = t + np.arange(bits.size) * bit_s
        mids = at[bits == 1] + bit_s / 2
        # the level changes at every bit's start, a 1 also in its middle, and once at the end
        bit_periods.append(bit_s)
        edges.append(np.sort(np.concatenate((at, mids, [t + bits.size * bit_s]))))
        t += (bits.size + 1) * bit_s
    n = int(np.ceil((t + lead_s) * sample_rate_hz))
    times = (np.arange(n) + 0.5) / sample_rate_hz
    all_edges = np.concatenate(edges) if edges else np.zeros(0)
    level = np.where(np.searchsorted(all_edges, times) % 2 == 1, 1.0, -1.0)
    width = max(1, round(RISE_S * sample_rate_hz))
    if width > 1:
        level = np.convolve(level, np.ones(width) / width, mode="same")
    quiet = np.ones(n, dtype=bool)  # outside a segment (and a bit after it) the line is silent
    for e, bit_s in zip(edges, bit_periods, strict=True):
        quiet[int(e[0] * sample_rate_hz):int(np.ceil((e[-1] + bit_s) * sample_rate_hz))] = False
    level[quiet] = 0.0
    return Rendered((amplitude * level).astype(np.float32), sample_rate_hz, tuple(tcs),
                    np.array(starts), tuple(stretches))


def write_wav(path: str | Path, samples: NDArray[np.floating], sample_rate_hz: int) -> None:
    """16-bit mono PCM WAV."""
    pcm = np.clip(np.round(np.asarray(samples) * 32767), -32768, 32767).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(sample_rate_hz)
        w.writeframes(pcm.tobytes())
