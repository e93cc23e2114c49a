"""Each frame of a take stamped with the timecode it was performed at:
:class:`TimecodeStamp`, and the side file it writes (:func:`stamp_path`,
:func:`read_stamps`).

A take recorded with ``--ltc`` gets a side file beside it, ``<take stem>.timecode.csv``
(the take itself, CSV or BVH, is unchanged, so every reader of takes reads it as
before)::

    # handrig timecode stamps 1: take.csv, source LTC ltc.wav
    t_s,timecode,frame,fps
    0.004000,01:00:00:00,90000.100,25
    0.014000,,,

``t_s`` is the take's own time of the frame (a CSV take's ``t_s`` column; a BVH take's
frame k is at the first row's ``t_s`` plus k over its frame rate), ``timecode`` the
frame the timecode was in, ``frame`` the timecode as a fractional frame number since
midnight (the rate's count; drop-frame numbers skipped are not counted), ``fps`` the
rate (24, 25, 29.97 or 30). A frame performed while the timecode was stopped or lost
has the last three fields empty. Rows go to disk every half second while the show runs.
"""

from __future__ import annotations

import math
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from handrig.clock import Clock
from handrig.config import bounded
from handrig.devices.timecode.ltc import RATES, FrameRate, Timecode
from handrig.devices.timecode.reader import TimecodeReader
from handrig.errors import DataError
from handrig.outputs.base import FloatArray, Output, OutputStatus, PanelCell
from handrig.outputs.recorder.formats import check_new_take, datasync

MAGIC = "# handrig timecode stamps 1"
HEADER = "t_s,timecode,frame,fps"
FLUSH_S = 0.5


def stamp_path(take: str | Path) -> Path:
    """The side file of a take: ``<stem>.timecode.csv`` beside it."""
    p = Path(take)
    return p.with_name(f"{p.stem}.timecode.csv")


class TimecodeStatus(OutputStatus):
    """The stamps' status; on the panel: "TC", the timecode and its lock (yellow when
    not locked), why the stamps stopped."""

    def cell(self) -> PanelCell:
        return PanelCell("TC", self.name, ok=self.name.endswith("locked"),
                         alert=self.stopped_reason)


class TimecodeStamp(Output):
    """The timecode for the panel (its :meth:`status` names it) and, with ``path``, each
    frame's timecode to the side file (module docstring). The loop's call formats a line
    and appends it to a list; a thread writes the list every :data:`FLUSH_S`."""

    def __init__(self, reader: TimecodeReader, clock: Clock, path: str | Path | None = None,
                 *, take: str = "") -> None:
        self.reader = reader
        self.clock = clock
        self.path = Path(path) if path is not None else None
        self._offset_s = math.nan  # clock time less the loop's t_s
        self._pending: list[bytes] = []
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed = False
        self.frames = 0
        self.frames_locked = 0
        self.first: str = ""
        self.last: str = ""
        self.error = ""
        self._fd = -1
        self._tc_frame = -1
        self._tc_fps: FrameRate | None = None
        self._tc = ""
        self._tc_bytes = b""
        self._thread: threading.Thread | None = None
        if self.path is not None:
            check_new_take(self.path)
            try:
                self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except OSError as exc:
                raise DataError(f"{self.path}: cannot create the timecode stamps"
                                f" ({exc.strerror}); check the directory") from None
            head = f"{MAGIC}: {take}, source {reader.name}\n{HEADER}\n"
            self._pending.append(head.encode())
            self._thread = threading.Thread(target=self._write_loop, name="timecode-stamps",
                                            daemon=True)
            self._thread.start()

    def __call__(self, t_s: float, pose_deg: FloatArray) -> None:
        if math.isnan(self._offset_s):
            self._offset_s = self.clock.now() - t_s
        self.frames += 1
        if self.path is None:
            return
        pos = self.reader.position(t_s + self._offset_s)
        fps = self.reader.fps()
        if pos is None or fps is None:
            line = b"%.6f,,,\n" % t_s
        else:
            n = int(pos)
            if n != self._tc_frame or fps is not self._tc_fps:  # a new frame: its words
                self._tc_frame, self._tc_fps = n, fps
                self._tc = str(Timecode.from_frame_number(n, fps))
                self._tc_bytes = b"%s,%%.3f,%s\n" % (self._tc.encode(), fps.label.encode())
            line = b"%.6f," % t_s + self._tc_bytes % pos
            self.frames_locked += 1
            self.last = self._tc
            if not self.first:
                self.first = self._tc
        with self._lock:
            self._pending.append(line)

    def _write_loop(self) -> None:
        while not self._closed:
            self._wake.wait(FLUSH_S)
            self._flush()

    def _flush(self) -> None:
        with self._lock:
            lines, self._pending = self._pending, []
        if not lines or self._fd < 0 or self.error:
            return
        try:
            os.write(self._fd, b"".join(lines))
            datasync(self._fd)
        except OSError as exc:
            self.error = f"timecode stamps stopped: {exc.strerror}"

    def status(self) -> OutputStatus:
        # its name: the timecode and its lock, "01:00:00:12 @25 locked", "lost (...)"
        return TimecodeStatus("timecode", self.reader.describe(self.clock.now()),
                              path=str(self.path or ""), frames_written=self.frames_locked,
                              stopped_reason=self.error)

    def close(self) -> str:
        if not self._closed:
            self._closed = True
            self._wake.set()
            if self._thread is not None:
                self._thread.join(timeout=5.0)
            self._flush()
            if self._fd >= 0:
                os.close(self._fd)
        if self.path is None:
            return ""
        return (f"{self.path}: {self.frames_locked} of {self.frames} frames stamped"
                + (f", {self.first} .. {self.last}" if self.first else ""))

    def summary(self, duration_s: float) -> tuple[str, dict[str, Any]]:
        st = self.reader.stats()
        stamps, failure = str(self.path or ""), st.failure or self.error
        said = (f"timecode {self.reader.name}: {st.frames} LTC frames, {st.jumps} jumps,"
                f" {st.losses} losses"
                + (f", {self.frames_locked} of {self.frames} frames stamped in {stamps}"
                   if stamps else "")
                + (f", {self.first} .. {self.last}" if self.first else "")
                + (f" ({failure})" if failure else ""))
        return "timecode", {
            "source": self.reader.name, "stamps": stamps,
            "frames": self.frames, "frames_stamped": self.frames_locked,
            "first": self.first, "last": self.last, "ltc_frames": st.frames,
            "jumps": st.jumps, "losses": st.losses, "bad_frames": st.bad_frames,
            "failure": failure, "said": said}


@dataclass(frozen=True)
class Stamps:
    """A side file read back: each row's take time, its timecode as a fractional frame
    number (NaN where there was none) and the rate (None when no row had one)."""

    t_s: NDArray[np.float64]
    frame: NDArray[np.float64]
    fps: FrameRate | None

    def frame_at_take_start(self) -> float | None:
        """The timecode (fractional frame) at the take's time 0, from the first stamped
        row, or None when no row has a timecode."""
        ok = np.flatnonzero(np.isfinite(self.frame))
        if ok.size == 0 or self.fps is None:
            return None
        i = int(ok[0])
        return float(self.frame[i] - self.t_s[i] * self.fps.rate_hz)


def read_stamps(path: str | Path) -> Stamps:
    """A side file (module docstring); DataError naming the file and line at fault."""
    p = Path(path)
    t: list[float] = []
    frames: list[float] = []
    fps: FrameRate | None = None
    try:
        with p.open("rb") as f:
            lines = bounded.lines(f, p, "a handrig timecode stamps file")
            first = next(lines, None)
            if first is None or not first[1].startswith(MAGIC):
                raise DataError(f"{p}: not a handrig timecode stamps file (its first line"
                                f" must start with {MAGIC!r})")
            second = next(lines, None)
            if second is None or second[1].strip() != HEADER:
                raise DataError(f"{p}: line 2: expected the header {HEADER!r}")
            for n, line in lines:
                if not line.strip():
                    continue
                fields = line.strip().split(",")
                try:
                    if len(fields) != 4:
                        raise ValueError
                    t.append(float(fields[0]))
                    frames.append(float(fields[2]) if fields[2] else math.nan)
                    if fields[3]:
                        fps = RATES[fields[3]]
                except (ValueError, KeyError):
                    raise DataError(f"{p}: line {n}: expected t_s,timecode,frame,fps, found"
                                    f" {bounded.excerpt(line.strip())}") from None
    except FileNotFoundError:
        raise DataError(f"{p}: timecode stamps not found") from None
    except OSError as exc:
        raise DataError(f"{p}: cannot read the timecode stamps: {exc.strerror}") from None
    return Stamps(np.array(t), np.array(frames), fps)
