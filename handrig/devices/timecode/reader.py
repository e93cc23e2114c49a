"""Timecode as the show sees it: :class:`TimecodeReader`, the contract (where the
timecode is now, whether it is locked, what happened), and :class:`LtcReader`, LTC
decoded from an :class:`~handrig.devices.timecode.audio.AudioInput` in a thread of its
own.

The reader's thread publishes each frame it decodes as a frozen :class:`TimecodeFix`
(one reference swapped, no lock): the loop and the panel read :meth:`position`, the
timecode at a clock time, extrapolated from the newest fix at the measured speed and
never more than one frame past it, so a timecode that stops is followed within a
frame; after :data:`LOSS_FRAMES` frame periods without a frame the signal is lost.
"""

from __future__ import annotations

import math
import threading
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from types import TracebackType
from typing import Self

import numpy as np
from numpy.typing import NDArray

from handrig.clock import Clock
from handrig.devices.timecode.audio import AudioInput
from handrig.devices.timecode.ltc import RATES, FrameRate, LtcDecoder, LtcFrame, Timecode
from handrig.errors import DeviceError

LOSS_FRAMES = 3.0
"""Frame periods of audio heard without a frame after which the timecode is lost."""
STUCK_S = 1.0
"""Clock time without a frame after which the timecode is lost even if the audio has not
been heard that far (a reader starved or a card that stopped delivering)."""
SPEED_WINDOW = 50
"""Fixes the speed is measured over (two seconds at 25 fps)."""
CARD_DRIFT = 2e-4
"""How fast the anchor of a sound card's sample times may follow a late card (s/s)."""
MAX_EVENTS = 32
DAY_FRAMES = {label: Timecode(24, 0, 0, 0, r.drop).frame_number(r.nominal)
              for label, r in RATES.items()}


@dataclass(frozen=True, slots=True)
class TimecodeFix:
    """One frame read: its frame number since midnight (``fps``'s count), when its bit 0
    began and when its last bit arrived (clock time), the speed measured (timecode
    seconds per clock second; 1.0 until measured) and whether it jumped (not the frame
    after the one before, or after a loss)."""

    frame: int
    timecode: Timecode
    fps: FrameRate
    start_s: float
    arrived_s: float
    speed: float
    jumped: bool


@dataclass(frozen=True)
class TimecodeStats:
    """What the reader has seen since it started."""

    frames: int = 0
    jumps: int = 0
    losses: int = 0
    """Times the signal went away (stopped, a dropout)."""
    bad_frames: int = 0
    """Sync words with invalid fields, or frame numbers the rate does not have."""
    parity_errors: int = 0
    failure: str = ""
    finished: bool = False
    """The source has ended (a file played through)."""


class TimecodeReader(ABC):
    """Everything the show uses of a timecode source. A context manager: :meth:`start`
    and :meth:`close` (both idempotent)."""

    name: str = "timecode"

    def start(self) -> None:  # noqa: B027 - optional hook
        """Begin reading."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Stop reading and release the source."""

    @abstractmethod
    def latest(self) -> TimecodeFix | None:
        """The newest frame read (None before the first). Any thread, never blocks."""

    @abstractmethod
    def stats(self) -> TimecodeStats:
        """The counters (any thread)."""

    def drain_events(self) -> list[str]:
        """What happened since the last call (lost, back, jumped, ended), oldest first.
        Any thread."""
        return []

    def heard_s(self) -> float:
        """The clock time up to which the source's signal has been read (a reader behind
        the clock has not heard the frames that came meanwhile: not a loss yet)."""
        return -math.inf

    def fps(self) -> FrameRate | None:
        """The rate of the timecode read (None before the first frame)."""
        fix = self.latest()
        return None if fix is None else fix.fps

    def position(self, now_s: float) -> float | None:
        """The timecode at clock time ``now_s`` in frames since midnight (fractional), or
        None when no frame has come for :data:`LOSS_FRAMES` frame periods (stopped, lost)."""
        fix = self.latest()
        if fix is None:
            return None
        rate = fix.fps.rate_hz * fix.speed
        if (now_s - fix.arrived_s > STUCK_S
                or self.heard_s() - fix.arrived_s > LOSS_FRAMES / rate):
            return None
        ahead = max(now_s - fix.start_s, 0.0) * rate
        cap = (fix.arrived_s - fix.start_s) * rate + 1.0  # one frame past the newest
        return fix.frame + min(ahead, cap)

    def describe(self, now_s: float) -> str:
        """For the panel: ``01:00:00:12 @25 locked``, ``lost (last 01:00:02:09)``, ``no
        timecode``."""
        fix = self.latest()
        if fix is None:
            return "no timecode"
        pos = self.position(now_s)
        if pos is None:
            return f"lost (last {fix.timecode})"
        tc = Timecode.from_frame_number(int(pos), fix.fps)
        return f"{tc} @{fix.fps.label} locked"

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def rate_of(frame: LtcFrame, sample_rate_hz: float) -> FrameRate:
    """The rate a frame was sent at, from its bit period and drop-frame flag."""
    if frame.timecode.drop:
        return RATES["29.97"]
    hz = sample_rate_hz / (80 * frame.bit_period_samples)
    return min((RATES[k] for k in ("24", "25", "30")), key=lambda r: abs(r.rate_hz - hz))


class LtcReader(TimecodeReader):
    """LTC from ``audio``, decoded in a thread of its own (module docstring). ``fps``:
    the rate the show runs at, or None to take it from the signal."""

    def __init__(self, audio: AudioInput, clock: Clock, *, fps: FrameRate | None = None
                 ) -> None:
        self.audio = audio
        self.clock = clock
        self.name = f"LTC {audio.name}"
        self._fps = fps
        self._decoder = LtcDecoder(audio.sample_rate_hz,
                                   fps_hint=fps.rate_hz if fps is not None else None)
        self._latest: TimecodeFix | None = None
        self._recent: deque[tuple[int, float]] = deque(maxlen=SPEED_WINDOW)
        self._anchor = math.nan  # clock time of sample 0
        self._fed = 0
        self._heard_s = -math.inf
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._frames = self._jumps = self._losses = self._bad = 0
        self._failure = ""
        self._finished = False
        self._events: deque[str] = deque(maxlen=MAX_EVENTS)
        self._said_lost = False

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="ltc-reader", daemon=True)
            self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self.audio.close()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def join(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the source to end; whether it has."""
        if self._thread is not None:
            self._thread.join(timeout=timeout_s)
        return self._finished

    def heard_s(self) -> float:
        return self._heard_s

    def drain_events(self) -> list[str]:
        out = []
        while self._events:
            try:
                out.append(self._events.popleft())
            except IndexError:
                break
        return out

    @property
    def audio_start_s(self) -> float:
        """The clock time of the audio's first sample (NaN before any audio)."""
        return self._anchor

    def latest(self) -> TimecodeFix | None:
        return self._latest

    def stats(self) -> TimecodeStats:
        return TimecodeStats(self._frames, self._jumps, self._losses,
                             self._bad + self._decoder.sync_errors,
                             self._decoder.parity_errors, self._failure, self._finished)

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                got = self.audio.read()
                if got is None:
                    break
                self.feed(*got)
        except DeviceError as exc:
            self._failure = str(exc)
            self._events.append(f"timecode: {exc}")
        finally:
            self._heard_s = math.inf  # the source has ended: no frame is still to come
            self._finished = True

    def feed(self, block: NDArray[np.float32], arrived_s: float) -> None:
        """Decode a block whose last sample arrived at ``arrived_s`` (the reader's thread;
        public for a source that pushes its audio)."""
        x = np.asarray(block, dtype=np.float32)
        sr = self.audio.sample_rate_hz
        self._fed += x.size
        candidate = arrived_s - self._fed / sr
        if math.isnan(self._anchor) or candidate < self._anchor:
            self._anchor = candidate  # the early edge: a block is only ever delayed
        else:
            self._anchor = min(self._anchor + CARD_DRIFT * x.size / sr, candidate)
        for frame in self._decoder.feed(x):
            self._publish(frame, arrived_s)
        self._heard_s = self._anchor + self._fed / sr
        fix = self._latest
        if (fix is not None and not self._said_lost
                and self._heard_s - fix.arrived_s > LOSS_FRAMES / fix.fps.rate_hz):
            self._said_lost = True
            self._events.append(f"timecode stopped or lost after {fix.timecode}")

    def _publish(self, frame: LtcFrame, arrived_s: float) -> None:
        sr = self.audio.sample_rate_hz
        heard = rate_of(frame, sr)
        fps = self._fps if self._fps is not None else heard
        if (frame.timecode.frames >= fps.nominal or frame.timecode.drop != fps.drop
                or heard.nominal != fps.nominal):
            if self._bad == 0:
                self._events.append(f"timecode at {heard.label} fps, but {fps.label} fps"
                                    " was asked for ([timecode] fps, --ltc-fps): frames"
                                    " dropped" if heard.nominal != fps.nominal else
                                    f"timecode frame {frame.timecode} is not {fps.label} fps")
            self._bad += 1
            return
        n = frame.timecode.frame_number(fps.nominal)
        start_s = self._anchor + frame.start_sample / sr
        end_s = self._anchor + frame.end_sample / sr
        prev = self._latest
        lost = prev is None or end_s - prev.arrived_s > LOSS_FRAMES / fps.rate_hz
        if prev is not None and lost:
            self._losses += 1
        jumped = lost or prev is None or n != (prev.frame + 1) % DAY_FRAMES[fps.label]
        if jumped:
            self._recent.clear()
            if prev is not None and not lost:
                self._jumps += 1
                self._events.append(f"timecode jumped from {prev.timecode} to {frame.timecode}")
            elif prev is None or self._said_lost:
                self._events.append(f"timecode {'back' if prev else 'locked'} at"
                                    f" {frame.timecode} ({fps.label} fps)")
        self._said_lost = False
        self._recent.append((n, start_s))
        speed = 1.0
        n0, s0 = self._recent[0]
        if len(self._recent) >= 10 and start_s > s0:
            speed = (n - n0) / ((start_s - s0) * fps.rate_hz)
        self._frames += 1
        self._latest = TimecodeFix(n, frame.timecode, fps, start_s, end_s, speed, jumped)
