"""Record what the glove sent, with its arrival times: :class:`GloveTake`.

A glove take is a glove recording (:mod:`handrig.devices.glove_recording`): a row per
good frame the glove sent, its raw channel counts, the forearm quaternion (empty cells
when the frame had none) and its buttons, at ``t_s``, the time the frame's last byte
arrived (the sample's ``host_time_s``) less the first frame's. It is what
``--glove replay:TAKE`` plays back through the whole pipeline at those times.

The glove hands every sample to :meth:`GloveTake.tap` as it arrives (in the thread
that reads the port: the tap only appends it to a deque). The text is made after the
servo write, when the loop calls the take as one of its outputs (``take(t_s, pose)``:
the pose is not used), or by whoever drives the glove (``handrig record glove``) with
:meth:`GloveTake.format_pending`; a writer thread writes it to ``<path>.partial`` every
``flush_s`` seconds and :meth:`GloveTake.close` renames it to ``path``. A take is never
replaced (:func:`~handrig.outputs.recorder.formats.check_new_take`).

Two frames read in one go share their arrival time; the later is written 1 us after
the earlier (the file's resolution), since a recording's times strictly increase.
"""

from __future__ import annotations

import math
import os
import threading
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from handrig.devices.glove import GloveSample
from handrig.devices.glove_recording import MAGIC, QUAT_COLUMNS
from handrig.errors import DataError
from handrig.outputs.base import FloatArray, Output, OutputStatus, PanelCell
from handrig.outputs.recorder.formats import check_new_take, datasync, partial_path

TIME_STEP_S = 1e-6  # the file's time resolution (6 decimals)


class GloveTakeStatus(OutputStatus):
    """The glove take's status; on the panel: its file, its frames, why it stopped."""

    def cell(self) -> PanelCell:
        return PanelCell("glove", self.path, frames=self.frames_written,
                         alert=self.stopped_reason)


class GloveTake(Output):
    """Stream the glove's frames to a glove recording (see the module docstring).

    ``channel_names``: the header's name for each raw channel (missing ones are
    ``ch<i>``); ``rate_hz``: the glove's nominal rate, written as ``# rate_hz``;
    ``meta``: more ``# key: value`` lines (the source, for a person). A frame with another
    channel count than the first is not written (counted in :attr:`frames_dropped`).
    ``from_first_output``: the take starts at the newest frame queued when the loop first
    calls it (the frame its first cycle used); the frames before it are the backlog the
    glove sent while the rig commissioned, read in one go at the loop's start, and are
    left out (:attr:`backlog_left_out`).
    """

    def __init__(self, path: str | Path, *, channel_names: Sequence[str] = (),
                 rate_hz: float = 0.0, meta: dict[str, str] | None = None,
                 flush_s: float = 0.5, sync: bool = True,
                 log: Callable[[str], None] | None = None,
                 from_first_output: bool = False) -> None:
        self.path = Path(path)
        self._skip_backlog = from_first_output
        self.backlog_left_out = 0
        if self.path.suffix.lower() not in (".csv", ".txt"):
            raise DataError(f"{self.path}: a glove take is a CSV file; name it *.csv")
        check_new_take(self.path)
        self.channel_names = tuple(channel_names)
        self.rate_hz = float(rate_hz) if math.isfinite(rate_hz) and rate_hz > 0 else 0.0
        self.meta = dict(meta or {})
        self.flush_s = float(flush_s)
        self.sync = sync
        self.log = log
        self._tmp = partial_path(self.path)
        try:
            self._fd = os.open(self._tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as exc:
            raise DataError(f"{self.path}: cannot create the glove take ({exc.strerror});"
                            " check that the directory exists and is writable") from None
        self._samples: deque[GloveSample] = deque()
        self._pending: list[tuple[bytes, float]] = []  # (row, its t_s); a row is a frame
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = False
        self._width = -1  # raw channels per row, from the first frame
        self._t0 = math.nan
        self._t_last = -math.inf
        self._t_written = 0.0  # the last frame on disk
        self.frames_formatted = 0
        """Frames turned into rows (written, or lost when the disk filled)."""
        self.frames_written = 0
        """Frames on disk: a whole row each, synced (with ``sync``); the take holds these."""
        self.frames_dropped = 0
        self.bytes_written = 0
        self.error = ""
        self._closed = False
        self._thread = threading.Thread(target=self._writer, name=f"glove take:{self.path.name}",
                                        daemon=True)
        self._thread.start()

    # -- on the glove's thread -------------------------------------------------------------
    def tap(self, sample: GloveSample) -> None:
        """A sample arrived (:meth:`GloveSource.add_tap`): queue it, nothing more."""
        self._samples.append(sample)

    # -- on the loop's thread, after the write ---------------------------------------------
    def __call__(self, t_s: float, pose_deg: FloatArray) -> None:
        if self._skip_backlog:
            self._skip_backlog = False
            samples = self._samples
            while len(samples) > 1:
                samples.popleft()
                self.backlog_left_out += 1
        self.format_pending()

    def format_pending(self) -> None:
        """Turn the samples queued so far into rows for the writer."""
        samples = self._samples
        if not samples:
            return
        if self.error:  # the take stopped (a full disk): what comes now is not written
            self.frames_dropped += len(samples)
            samples.clear()
            return
        lines: list[tuple[bytes, float]] = []
        while samples:
            s = samples.popleft()
            line = self._row(s)
            if line is not None:
                lines.append((line, self._t_last))
        if lines:
            with self._lock:
                self._pending.extend(lines)

    def _row(self, s: GloveSample) -> bytes | None:
        raw = s.raw
        head = b""
        if self._width < 0:
            self._width = len(raw)
            self._t0 = s.host_time_s
            head = self._header()
        if len(raw) != self._width or not math.isfinite(s.host_time_s):
            self.frames_dropped += 1
            return None
        t = max(s.host_time_s - self._t0, self._t_last + TIME_STEP_S)
        self._t_last = t
        q = s.quat
        quat = ",,," if q is None or not np.all(np.isfinite(q)) else (
            f"{q[0]:.6f},{q[1]:.6f},{q[2]:.6f},{q[3]:.6f}")
        values = ",".join(f"{v:.10g}" for v in raw.tolist())
        self.frames_formatted += 1
        return head + f"{t:.6f},{values},{quat},{int(s.buttons)}\n".encode("ascii")

    def _header(self) -> bytes:
        names = [self.channel_names[i] if i < len(self.channel_names) and
                 self.channel_names[i] else f"ch{i}" for i in range(self._width)]
        lines = [MAGIC]
        if self.rate_hz:
            lines.append(f"# rate_hz: {self.rate_hz:g}")
        lines += [f"# {k}: {v}" for k, v in self.meta.items() if k != "rate_hz"]
        lines.append(",".join(["t_s", *names, *QUAT_COLUMNS, "buttons"]))
        return ("\n".join(lines) + "\n").encode("utf-8")

    # -- the writer thread -----------------------------------------------------------------
    def _writer(self) -> None:
        while not self._stop:
            self._wake.wait(self.flush_s)
            self._write_pending()

    def _write_pending(self) -> None:
        with self._lock:
            batch, self._pending = self._pending, []
        if not batch:
            return
        if self.error:
            self.frames_dropped += sum(1 for line, t in batch if not math.isnan(t))
            return
        data = b"".join(line for line, _ in batch)
        try:
            view = memoryview(data)
            while view:
                n = os.write(self._fd, view)
                view = view[n:]
            if self.sync:
                datasync(self._fd)
        except OSError as exc:
            self._failed(exc, sum(1 for line, t in batch if not math.isnan(t)))
            return
        self.bytes_written += len(data)
        frames = [t for _, t in batch if not math.isnan(t)]
        self.frames_written += len(frames)
        if frames:
            self._t_written = frames[-1]

    def _failed(self, exc: OSError, lost: int) -> None:
        """A write failed (a full disk, a file size limit): stop, and cut the file back to
        what was written before this batch, whole rows only, so the take and the counts
        agree."""
        with self._lock:
            lost += sum(1 for _, t in self._pending if not math.isnan(t))
            self._pending = []
        self.frames_dropped += lost
        try:
            os.ftruncate(self._fd, self.bytes_written)
            cut = ""
        except OSError as cut_exc:
            cut = (f"; cutting it back failed ({cut_exc.strerror}): `handrig record repair"
                   f" {self._tmp}` keeps its whole frames")
        self.error = (f"the glove take stopped: {exc.strerror or exc}; it keeps its first"
                      f" {self.frames_written} frames{cut}")
        if self.log is not None:
            self.log(f"{self.path}: {self.error}")

    # -- the end ---------------------------------------------------------------------------
    @property
    def duration_s(self) -> float:
        """From the first frame's arrival to the last's on disk (0 before two frames)."""
        return max(0.0, self._t_written) if self.frames_written > 1 else 0.0

    def status(self) -> OutputStatus:
        return GloveTakeStatus(kind="glove take", name="csv", path=str(self.path),
                            frames_written=self.frames_written,
                            bytes_written=self.bytes_written,
                            frames_dropped=self.frames_dropped, stopped_reason=self.error,
                            duration_s=self.duration_s)

    def summary(self, duration_s: float) -> tuple[str, dict[str, Any]]:
        """``glove_take``: the take's path, frames, time span, bytes, why it stopped."""
        st = self.status()
        stopped = f" ({st.stopped_reason})" if st.stopped_reason else ""
        return "glove_take", {
            "path": st.path, "frames": st.frames_written,
            "duration_s": round(st.duration_s, 3), "bytes": st.bytes_written,
            "frames_dropped": st.frames_dropped, "stopped_reason": st.stopped_reason,
            "said": f"glove take {st.path}: {st.frames_written} frames,"
                    f" {st.duration_s:.1f} s{stopped}"}

    def close(self) -> str:
        """Write what is left, close the file and name it ``path`` (a file that appeared
        there meanwhile keeps it: the take is then left as ``<path>.partial``, said in
        the returned line). Idempotent; returns a line for the log."""
        if self._closed:
            return self.describe()
        self._closed = True
        self.format_pending()
        self._stop = True
        self._wake.set()
        self._thread.join()
        if self.frames_formatted == 0 and not self.error:  # no frame: still a readable file
            self._width = 0
            with self._lock:
                self._pending.insert(0, (self._header(), math.nan))
        self._write_pending()
        os.close(self._fd)
        if self.bytes_written == 0 and self.error:  # not even the header: nothing to keep
            os.unlink(self._tmp)
            self.error += f"; nothing was recorded, {self.path} is not made"
            return self.describe()
        if self.path.exists():
            self.error = self.error or (f"{self.path} appeared during the run; the take is"
                                        f" left as {self._tmp}")
            return self.describe()
        os.rename(self._tmp, self.path)
        return self.describe()

    def describe(self) -> str:
        dropped = f", {self.frames_dropped} dropped" if self.frames_dropped else ""
        stopped = f" ({self.error})" if self.error else ""
        return (f"{self.path}: {self.frames_written} glove frames, {self.duration_s:.2f} s,"
                f" {self.bytes_written} bytes{dropped}{stopped}")
