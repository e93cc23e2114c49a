"""SMPTE linear timecode (LTC): the timecode values and a streaming decoder, pure.

Facts (SMPTE 12M): a frame's codeword is 80 bits sent least significant bit first, in
biphase mark: the level changes at the start of every bit and once more in the middle
of a 1. Bits 0-3 frame units, 8-9 frame tens, 10 the drop-frame flag, 11 colour frame,
16-19 seconds units, 24-26 seconds tens, 32-35 minutes units, 40-42 minutes tens,
48-51 hours units, 56-57 hours tens, BCD; the eight 4-bit user groups at 4, 12, 20,
28, 36, 44, 52, 60; the polarity correction bit (27, or 59 at 25 fps) makes the count
of zeros in the codeword even, so each frame starts on the same edge; bits 64-79 are
the sync word 0011 1111 1111 1101. Bit 0 begins with the frame it names. Drop-frame
numbering (29.97 fps) skips frame numbers 0 and 1 at the start of every minute but
each tenth.

:class:`LtcDecoder` takes audio samples in blocks of any size and returns the frames
whose sync word ended in them, each with the sample index where its bit 0 began.
No I/O, no clock: :mod:`handrig.devices.timecode.reader` runs it on an audio input.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

from handrig.errors import ConfigError

SYNC_WORD = 0xBFFC
"""Bits 64-79 read as a number with bit 64 the least significant (0011 1111 1111 1101
in the order sent)."""
BITS = 80


@dataclass(frozen=True)
class FrameRate:
    """A timecode rate: ``label`` as people write it, frames counted per second
    (``nominal``: 24, 25 or 30), the real rate (30000/1001 for 29.97) and drop-frame."""

    label: str
    nominal: int
    rate: Fraction
    drop: bool

    @property
    def rate_hz(self) -> float:
        return float(self.rate)


RATES: dict[str, FrameRate] = {
    "24": FrameRate("24", 24, Fraction(24), False),
    "25": FrameRate("25", 25, Fraction(25), False),
    "29.97": FrameRate("29.97", 30, Fraction(30000, 1001), True),
    "30": FrameRate("30", 30, Fraction(30), False),
}
"""The rates the decoder reads (29.97 is drop-frame)."""


def frame_rate(label: str | float, key: str = "fps") -> FrameRate:
    """The :class:`FrameRate` called ``label`` (24, 25, 29.97 or 30); ConfigError naming
    ``key`` otherwise."""
    text = f"{label:g}" if isinstance(label, float | int) else str(label).strip()
    if text == "29.97df":
        text = "29.97"
    if text not in RATES:
        raise ConfigError("not a timecode rate", key=key, value=label,
                          allowed="24, 25, 29.97 (drop-frame) or 30")
    return RATES[text]


@dataclass(frozen=True, order=True)
class Timecode:
    """HH:MM:SS:FF (drop-frame written HH:MM:SS;FF)."""

    hours: int
    minutes: int
    seconds: int
    frames: int
    drop: bool = False

    def __str__(self) -> str:
        sep = ";" if self.drop else ":"
        return f"{self.hours:02d}:{self.minutes:02d}:{self.seconds:02d}{sep}{self.frames:02d}"

    def frame_number(self, nominal: int) -> int:
        """Frames since 00:00:00:00 at ``nominal`` frames a second (drop-frame: the
        numbers skipped are not counted)."""
        total_min = 60 * self.hours + self.minutes
        n = ((total_min * 60) + self.seconds) * nominal + self.frames
        if self.drop:
            n -= 2 * (total_min - total_min // 10)
        return n

    @classmethod
    def from_frame_number(cls, n: int, fps: FrameRate) -> Timecode:
        """The timecode of frame ``n`` since midnight (wrapping at 24 h)."""
        nominal = fps.nominal
        if fps.drop:
            per_10min = 10 * 60 * nominal - 9 * 2
            per_min = 60 * nominal - 2
            n %= 24 * 6 * per_10min
            tens, rem = divmod(n, per_10min)
            if rem >= 2:
                n += 2 * 9 * tens + 2 * ((rem - 2) // per_min)
            else:
                n += 2 * 9 * tens
        else:
            n %= 24 * 3600 * nominal
        frames = n % nominal
        s = n // nominal
        return cls(s // 3600, (s // 60) % 60, s % 60, frames, fps.drop)

    @classmethod
    def parse(cls, text: str, key: str = "timecode") -> Timecode:
        """``HH:MM:SS:FF`` (or ``HH:MM:SS;FF``, drop-frame); ConfigError naming ``key``."""
        t = text.strip()
        drop = ";" in t
        parts = t.replace(";", ":").split(":")
        try:
            hh, mm, ss, ff = (int(p) for p in parts)
            if len(parts) != 4 or not (0 <= hh < 24 and 0 <= mm < 60 and 0 <= ss < 60
                                       and 0 <= ff < 30):
                raise ValueError
        except ValueError:
            raise ConfigError("not a timecode", key=key, value=text,
                              allowed="HH:MM:SS:FF, e.g. 01:00:00:00 (HH:MM:SS;FF:"
                              " drop-frame)") from None
        return cls(hh, mm, ss, ff, drop)


def _bcd(word: int, at: int, width: int) -> int:
    return (word >> at) & ((1 << width) - 1)


def pack(tc: Timecode, *, user_bits: int = 0, fps25: bool = False) -> int:
    """The 80-bit codeword of ``tc`` (bit k = the k-th bit sent), polarity bit set."""
    w = 0

    def put(value: int, at: int, width: int) -> None:
        nonlocal w
        w |= (value & ((1 << width) - 1)) << at

    put(tc.frames % 10, 0, 4)
    put(tc.frames // 10, 8, 2)
    put(int(tc.drop), 10, 1)
    put(tc.seconds % 10, 16, 4)
    put(tc.seconds // 10, 24, 3)
    put(tc.minutes % 10, 32, 4)
    put(tc.minutes // 10, 40, 3)
    put(tc.hours % 10, 48, 4)
    put(tc.hours // 10, 56, 2)
    for g in range(8):
        put(user_bits >> (4 * g), 4 + 8 * g, 4)
    w |= SYNC_WORD << 64
    zeros = BITS - bin(w).count("1")
    if zeros % 2:
        w |= 1 << (59 if fps25 else 27)
    return w


def unpack(word: int) -> tuple[Timecode, int] | None:
    """(timecode, user bits) of a codeword, or None when a BCD field is out of range."""
    fu, ft = _bcd(word, 0, 4), _bcd(word, 8, 2)
    su, st = _bcd(word, 16, 4), _bcd(word, 24, 3)
    mu, mt = _bcd(word, 32, 4), _bcd(word, 40, 3)
    hu, ht = _bcd(word, 48, 4), _bcd(word, 56, 2)
    if max(fu, su, mu, hu) > 9 or st > 5 or mt > 5:
        return None
    tc = Timecode(10 * ht + hu, 10 * mt + mu, 10 * st + su, 10 * ft + fu,
                  bool((word >> 10) & 1))
    if tc.hours > 23 or tc.frames > 29:
        return None
    user = 0
    for g in range(8):
        user |= _bcd(word, 4 + 8 * g, 4) << (4 * g)
    return tc, user


@dataclass(frozen=True)
class LtcFrame:
    """A decoded frame: its timecode, user bits, the sample index (since the decoder
    began) where its bit 0 began and where its last bit ended, and the bit period
    measured over it (samples)."""

    timecode: Timecode
    user_bits: int
    start_sample: int
    end_sample: int
    bit_period_samples: float


class LtcDecoder:
    """Biphase-mark LTC from audio samples, fed in blocks (see the module docstring).

    Edges are found with hysteresis at ``hysteresis`` times the recent peak (a signal
    under ``min_level`` full scale is silence). Intervals between edges are sorted into
    half and whole bits against a bit period that follows the signal (so a rate 10 %
    off or drifting slowly still reads); a gap longer than 1.6 bits resets the bit
    register (a stop, a dropout). ``fps_hint`` sets the first bit period (25 fps when
    None: 24 to 30 fps read from it alike).
    """

    def __init__(self, sample_rate_hz: float, *, fps_hint: float | None = None,
                 hysteresis: float = 0.25, min_level: float = 0.01) -> None:
        if not sample_rate_hz >= 8000:
            raise ConfigError("sample rate too low for LTC", key="sample_rate_hz",
                              value=sample_rate_hz, allowed="8000 Hz or more")
        self.sample_rate_hz = float(sample_rate_hz)
        self._nominal_period = self.sample_rate_hz / (BITS * (fps_hint or 25.0))
        self._period = self._nominal_period
        self._hyst = hysteresis
        self._min_level = min_level
        self._peak = 0.0
        self._level = 0  # +1 high, -1 low, 0 not yet known
        self._pos = 0  # samples fed so far
        self._last_edge = -1
        self._half_start = -1  # edge that began a bit whose first half was seen
        self._word = 0
        self._n_bits = 0
        self._starts = np.zeros(BITS, dtype=np.int64)  # ring: each bit's first edge
        self.frames_decoded = 0
        self.sync_errors = 0
        """Sync words whose fields were not valid BCD."""
        self.parity_errors = 0
        """Frames with an odd count of zeros (a bit misread, or a generator that leaves the
        polarity bit alone): decoded all the same."""

    @property
    def bit_period_samples(self) -> float:
        return self._period

    def feed(self, samples: NDArray[np.floating]) -> list[LtcFrame]:
        """Decode a block; the frames whose sync word ended in it."""
        x = np.asarray(samples, dtype=np.float64)
        if x.ndim != 1:
            raise ValueError("feed() takes one channel")
        base = self._pos
        self._pos += x.size
        if x.size == 0:
            return []
        self._peak = max(float(np.abs(x).max()), self._peak * 0.5)
        if self._peak < self._min_level:
            self._gap()
            self._level = 0
            return []
        h = self._hyst * self._peak
        marks = np.where(x > h, 1, np.where(x < -h, -1, 0))
        idx = np.flatnonzero(marks)
        if idx.size == 0:
            return []
        levels = marks[idx]
        change = np.flatnonzero(np.diff(levels)) + 1
        edges = idx[change]
        # out of silence (level unknown), the first swing is an edge: bit 0 of a frame
        first_is_edge = levels[0] != self._level
        self._level = int(levels[-1])
        if first_is_edge:
            edges = np.concatenate(([idx[0]], edges))
        out: list[LtcFrame] = []
        for e in (edges + base).tolist():
            self._edge(e, out)
        if self._last_edge >= 0 and self._pos - self._last_edge > 1.6 * self._period:
            self._gap()
        return out

    def _gap(self) -> None:
        self._n_bits = 0
        self._half_start = -1
        self._last_edge = -1

    def _edge(self, e: int, out: list[LtcFrame]) -> None:
        prev = self._last_edge
        self._last_edge = e
        if prev < 0:
            return
        d = e - prev
        p = self._period
        if d > 1.6 * p:  # a dropout or the signal starting: nothing before counts
            self._n_bits = 0
            self._half_start = -1
            if d > 8 * p:  # long enough for the next signal to run at another rate
                self._period = self._nominal_period
            return
        if d >= 0.75 * p:  # a whole bit: 0
            if self._half_start >= 0:  # a lone half bit: out of step, start again here
                self._n_bits = 0
                self._half_start = -1
            self._period = p + 0.1 * (d - p)
            self._push(0, prev, e, out)
        elif self._half_start < 0:
            self._half_start = prev
        else:
            start = self._half_start
            self._half_start = -1
            self._period = p + 0.1 * ((e - start) - p)
            self._push(1, start, e, out)

    def _push(self, bit: int, start: int, end: int, out: list[LtcFrame]) -> None:
        self._word = (self._word >> 1) | (bit << (BITS - 1))
        self._starts[self._n_bits % BITS] = start
        self._n_bits += 1
        if self._n_bits < BITS or (self._word >> 64) != SYNC_WORD:
            return
        first = int(self._starts[self._n_bits % BITS])  # the oldest of the last 80
        got = unpack(self._word)
        if got is None:
            self.sync_errors += 1
            return
        if (BITS - bin(self._word).count("1")) % 2:
            self.parity_errors += 1
        self.frames_decoded += 1
        out.append(LtcFrame(got[0], got[1], first, end,
                            (end - first) / BITS))
