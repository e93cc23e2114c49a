"""Timecode in a live run: ``--ltc SOURCE`` (the reader, the panel's timecode, a take's
frames stamped) and ``play --chase-ltc SOURCE`` (a take played locked to the incoming
timecode: :class:`ChaseGlove`).

The chase: the take's time 0 is at a timecode (``--chase-at HH:MM:SS:FF``, or the take's
own stamps from the run that recorded it with ``--ltc``). Each cycle the chase asks the
reader where the timecode is now and hands the loop the take's frame at that time:
it starts when the timecode enters the take's range (until then the puppet holds the
take's first frame), stops when the timecode stops or is lost (the puppet holds the
frame it was at), jumps when the timecode jumps, and holds the last frame once the
timecode has run past the take's end.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from firmware_protocol.glove import BUTTON_RELAX
from handrig.app.takes import PlayTake
from handrig.clock import Clock, MonotonicClock
from handrig.devices.glove import GloveSample, GloveSource, GloveStats
from handrig.devices.timecode.audio import WavAudio, open_audio
from handrig.devices.timecode.ltc import Timecode, frame_rate
from handrig.devices.timecode.reader import LtcReader, TimecodeReader
from handrig.errors import ConfigError, DataError
from handrig.outputs.recorder import load_performance
from handrig.outputs.recorder.formats import format_of
from handrig.outputs.timecode_stamp import TimecodeStamp, read_stamps, stamp_path

CHASE_LOG = 4096
"""Served frames the chase keeps (time, timecode, take time) for its figures."""
MIN_RATE_HZ = 50.0
MAX_RATE_HZ = 200.0


def open_reader(source: str, clock: Clock, *, fps: str = "auto",
                key: str = "--ltc") -> LtcReader:
    """An LTC reader on ``source`` (a .wav file or ``alsa:DEVICE``), not started; ``fps``
    24, 25, 29.97, 30 or "auto" (from the signal). ConfigError naming ``key``."""
    rate = None if fps == "auto" else frame_rate(fps, key="[timecode] fps")
    return LtcReader(open_audio(source, clock, key=key), clock, fps=rate)


def stamp_output(stack: contextlib.ExitStack, reader: TimecodeReader, clock: Clock,
                 record: str | None, log: Callable[[str], None]) -> TimecodeStamp:
    """The run's timecode output (the panel's timecode; with ``record``, the take's stamps
    in its side file), the reader started; both closed when ``stack`` unwinds."""
    stack.enter_context(reader)
    stamp = TimecodeStamp(reader, clock, stamp_path(record) if record else None,
                          take=Path(record).name if record else "")

    def close() -> None:
        said = stamp.close()
        if said:
            log(f"timecode stamps: {said}")

    stack.callback(close)
    return stamp


def check_stamp_path(record: str | None) -> None:
    """Before the bus opens: the side file of ``--record``'s take must be new."""
    if record:
        from handrig.outputs.recorder import check_new_take

        try:
            check_new_take(stamp_path(record))
        except DataError as exc:
            raise ConfigError(str(exc), key="--record", value=record,
                              allowed="a take whose .timecode.csv does not exist yet"
                              ) from None


def chase_start_frame(take: PlayTake, at: str | None) -> float | Timecode:
    """Where the take's window starts on the timecode: from ``at`` (``--chase-at``, the
    take's time 0; a :class:`Timecode`, made a frame number once the rate is known) or the
    take's stamps (a fractional frame number); ConfigError naming what to give."""
    if at is not None:
        return Timecode.parse(at, key="--chase-at")
    side = stamp_path(take.path)
    if not side.exists():
        raise ConfigError(f"{take.path} has no timecode stamps ({side} is missing)",
                          key="--chase-at", value="(none)",
                          allowed="the timecode the take starts at, HH:MM:SS:FF")
    stamps = read_stamps(side)
    origin = stamps.frame_at_take_start()
    if origin is None or stamps.fps is None:
        raise ConfigError(f"{side}: no frame of the take was stamped (no timecode came)",
                          key="--chase-at", value="(none)",
                          allowed="the timecode the take starts at, HH:MM:SS:FF")
    first_s = stamps.t_s[0]
    if take.kind == "performance" and format_of(take.path) == "csv":  # rows keep run time
        first_s = float(load_performance(take.path)[0][0])
    return origin + (first_s + take.start_s) * stamps.fps.rate_hz


class ChaseGlove(GloveSource):
    """A take's frames at the incoming timecode (module docstring), as the loop's glove:
    a frame for every cycle (the loop's floor rate), the take's frame at the timecode's
    position then. Starts and closes ``reader``."""

    def __init__(self, take: PlayTake, reader: TimecodeReader, clock: Clock,
                 start: float | Timecode) -> None:
        super().__init__()
        self.play_take = take
        self.reader = reader
        self.clock = clock
        self._start = start
        self.start_frame = math.nan if isinstance(start, Timecode) else float(start)
        """The timecode at the take window's start, frames (NaN until the rate is known)."""
        self._t = take.recording.t_s - take.recording.t_s[0]
        gap = float(np.median(np.diff(self._t))) if len(self._t) > 1 else 0.01
        self.period_s = min(max(gap, 1.0 / MAX_RATE_HZ), 1.0 / MIN_RATE_HZ)
        """How often the loop gets a frame: the take's own period, within 50..200 Hz."""
        self._due_s: float | None = None
        self._held = 0
        self._count = 0
        self.state = "waiting"
        """waiting (no timecode yet), before, playing, after (the take's range), stopped."""
        self.starts = 0
        self.stops = 0
        self.jumps = 0
        self._seen_jumps = 0
        self.started_at = ""
        self.log: deque[tuple[float, float, float]] = deque(maxlen=CHASE_LOG)
        """(clock time, timecode frame, take time served) of recent frames while playing."""

    @property
    def name(self) -> str:
        return f"chase {self.reader.name}"

    def start(self) -> None:
        self.reader.start()

    def close(self) -> None:
        self.reader.close()

    def has_new(self) -> bool:
        return self._due_s is None or self.clock.now() >= self._due_s

    def next_due_s(self) -> float:
        now = self.clock.now()
        return now if self._due_s is None or self._due_s < now else self._due_s

    def latest(self) -> GloveSample | None:
        now = self.clock.now()
        if not self.has_new():
            return None
        due = now if self._due_s is None else self._due_s
        self._due_s = due + self.period_s if now - due < self.period_s else now + self.period_s
        pos = self.reader.position(now)
        fps = self.reader.fps()
        state, i = "stopped", self._held
        if fps is not None and isinstance(self._start, Timecode) and math.isnan(self.start_frame):
            self.start_frame = (self._start.frame_number(fps.nominal)
                                + self.play_take.start_s * fps.rate_hz)
        if pos is not None and fps is not None:
            take_s = (pos - self.start_frame) / fps.rate_hz
            if take_s < 0.0:
                state, i = "before", 0
            elif take_s > self._t[-1]:
                state, i = "after", len(self._t) - 1
            else:
                state = "playing"
                i = int(np.searchsorted(self._t, take_s, side="right")) - 1
                self.log.append((now, pos, float(self._t[i])))
                if not self.started_at:
                    self.started_at = str(Timecode.from_frame_number(int(pos), fps))
        elif self.state == "waiting":
            state = "waiting"
        jumps = self.reader.stats().jumps
        if state == "playing" and self.state != "playing":
            self.starts += 1
        if self.state == "playing" and state == "stopped":
            self.stops += 1
        if jumps != self._seen_jumps and state == "playing":
            self.jumps += jumps - self._seen_jumps
        self._seen_jumps = jumps
        self.state = state
        self._held = i
        return self._serve(i, now)

    def _serve(self, i: int, now: float) -> GloveSample:
        rec = self.play_take.recording
        q = None if rec.quat_xyzw is None else rec.quat_xyzw[i]
        if q is not None and np.isnan(q).any():
            q = None
        b = int(rec.buttons[i])
        self._count += 1
        sample = GloveSample(raw=rec.raw[i], quat=q, buttons=b, estop=bool(b & BUTTON_RELAX),
                             seq=(self._count - 1) & 0xFFFF, sensor_time_us=0,
                             host_time_s=now, count=self._count)
        self._arrived(sample)
        self._taken = self._count
        return sample

    def drain_events(self) -> list[str]:
        return super().drain_events() + self.reader.drain_events()

    def stats(self) -> GloveStats:
        return GloveStats(frames_ok=self._count, time_since_last_good_s=0.0
                          if self._count else math.inf)

    def figures(self) -> dict[str, Any]:
        """The chase's part of the run summary."""
        st = self.reader.stats()
        lag_ms = [(pos - self.start_frame) * 1000.0 / fps - take_s * 1000.0
                  for _, pos, take_s in self.log
                  for fps in (self._rate_hz(),) if fps]
        return {"source": self.reader.name, "starts": self.starts, "stops": self.stops,
                "jumps": self.jumps, "started_at": self.started_at, "state": self.state,
                "take_starts_at_frame": None if math.isnan(self.start_frame)
                else round(self.start_frame, 3),
                "ltc_frames": st.frames, "ltc_losses": st.losses,
                "frame_behind_ms_max": round(max(lag_ms), 3) if lag_ms else None,
                "failure": st.failure}

    def _rate_hz(self) -> float:
        fps = self.reader.fps()
        return fps.rate_hz if fps is not None else 0.0


@dataclass
class ChaseSetup:
    """``play --chase-ltc``: the reader (not started), the take, where it starts on the
    timecode, how long the run lasts (a WAV source: until it has played; a sound card:
    until stopped) and, once the session made it, the chase."""

    reader: LtcReader
    take: PlayTake
    start: float | Timecode
    duration_s: float | None
    chase: ChaseGlove | None = None

    def glove(self, clock: Clock) -> ChaseGlove:
        self.chase = ChaseGlove(self.take, self.reader, clock, self.start)
        return self.chase

    def report(self, summary: dict[str, Any], *, as_json: bool) -> None:
        """The chase's figures into the run summary (and a line for a person)."""
        if self.chase is None:
            return
        figures = self.chase.figures()
        summary["chase"] = figures
        if not as_json:
            print(f"chase: {figures['starts']} start(s)"
                  + (f" at {figures['started_at']}" if figures["started_at"] else "")
                  + f", {figures['stops']} stop(s), {figures['jumps']} jump(s) followed,"
                  f" {figures['ltc_frames']} LTC frames read from {figures['source']}",
                  file=sys.stderr, flush=True)


def chase_setup(args: argparse.Namespace, take: PlayTake) -> ChaseSetup:
    """``play --chase-ltc`` checked and its reader opened, before the bus opens."""
    if args.speed != 1.0:
        raise ConfigError("the timecode sets the speed of a chased take", key="--speed",
                          value=args.speed, allowed="1 (leave it out) with --chase-ltc")
    if args.loop:
        raise ConfigError("a chased take follows the timecode", key="--loop", value=True,
                          allowed="leave --loop out with --chase-ltc")
    reader = open_reader(args.chase_ltc, MonotonicClock(), fps=args.ltc_fps or "auto",
                         key="--chase-ltc")
    start = chase_start_frame(take, args.chase_at)
    audio = reader.audio
    duration = (round(audio.duration_s + 0.3, 3) if isinstance(audio, WavAudio) else None)
    return ChaseSetup(reader, take, start, duration)
