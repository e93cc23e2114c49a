"""Stream a take to disk while the show runs: :class:`Recorder`."""

from __future__ import annotations

import errno
import math
import os
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from handrig.errors import DataError
from handrig.outputs.base import Output, OutputStatus, PanelCell
from handrig.outputs.recorder.bvh_take import BvhTake
from handrig.outputs.recorder.csv_take import CsvTake
from handrig.outputs.recorder.formats import (
    N_VALUES,
    Format,
    TakeFormat,
    check_new_take,
    datasync,
    format_of,
    free_path,
    partial_path,
)

_IOV_MAX = 1024 if sys.platform.startswith("linux") else 16  # buffers per writev (Linux; POSIX)
_WHY = {
    errno.ENOSPC: "the disk is full",
    errno.EFBIG: "the file size limit was reached",
    errno.EDQUOT: "the disk quota is used up",
    errno.EIO: "the disk reported an I/O error",
}


class RecorderStatus(OutputStatus):
    """The recorder's status; on the panel: its take, the bytes on disk, the performance
    time, and why it stopped (if it did)."""

    def cell(self) -> PanelCell:
        return PanelCell("rec", self.path, size_bytes=self.bytes_written,
                         duration_s=self.duration_s,
                         alert=self.stopped_reason.removeprefix("recording "))


class Recorder(Output):
    """Stream frames to a CSV or BVH file while the show runs.

    ``add`` (or calling the recorder, the rig's output hook) turns the frame into text at
    once and appends it to a list; a writer thread takes that list every ``flush_s``
    seconds, writes it with ``os.writev`` and (``sync=True``) asks the OS to put it on
    the disk (``fdatasync``). So a killed process or a power cut loses at most the last
    ``flush_s`` seconds plus one write, and memory holds at most ``max_pending_s``
    seconds of lines at ``rate_hz`` (frames beyond that, when the disk stalls, are
    dropped and counted in :attr:`frames_dropped`, never raised into the loop).

    Time: a CSV row keeps its frame's time; a BVH file is written at ``rate_hz`` frames
    per second, resampled from the frames' times (:mod:`~handrig.outputs.recorder.bvh_take`),
    so ``rate_hz`` should be the glove's nominal rate or a rate the user chose.

    A write error (a full disk, a file size limit) stops the recording at that moment:
    the file is cut back to its last whole frame, :attr:`stopped_reason` says why and
    when, ``log`` (if given) is called with it from the writer thread, and later frames
    are dropped and counted while the show goes on. :meth:`close` then finishes the take
    as usual, readable with the frames written before the error. Only if the file could
    not be cut back is :attr:`error` raised by :meth:`close`, leaving ``<path>.partial``
    for :func:`~handrig.outputs.recorder.repair.repair`.

    A take is never replaced: an existing ``path`` (or its ``.partial``, an unfinished
    take) is refused when the recorder is made, with the next free name in the message;
    a file that appears at ``path`` during the run keeps it, and the take gets that
    next free name at :meth:`close` (logged, and in :attr:`path`). The file is written
    as ``<path>.partial`` and renamed by :meth:`close`; the BVH header's frame count is a
    fixed-width field rewritten after each batch, so a take cut by a kill between
    batches reads as it is (one cut inside a batch or by a power cut needs repair).
    ``with_wrist``: record the 4 wrist DOFs; None decides on the first frame.
    """

    def __init__(self, path: str | Path, fmt: str | None = None, rate_hz: float = 200.0, *,
                 with_wrist: bool | None = None, flush_s: float = 0.5, sync: bool = True,
                 max_pending_s: float = 60.0, log: Callable[[str], None] | None = None
                 ) -> None:
        self.path = Path(path)
        self.fmt: Format = format_of(self.path, fmt)
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise DataError(f"{self.path}: rate_hz must be a positive number, got {rate_hz}")
        if not (math.isfinite(flush_s) and 0 < flush_s <= 1.0):
            raise ValueError(f"flush_s must be in (0, 1] s, got {flush_s}")
        if not (math.isfinite(max_pending_s) and max_pending_s >= flush_s):
            raise ValueError(f"max_pending_s must be at least flush_s, got {max_pending_s}")
        self.rate_hz = float(rate_hz)
        self.with_wrist = with_wrist
        self.flush_s = float(flush_s)
        self.sync = sync
        self.log = log
        self._max_pending = max(1, math.ceil(max_pending_s * self.rate_hz)) + 1  # + header
        self._n_added = 0
        self._t_first = math.nan
        self._t_last = math.nan
        self.frames_dropped = 0
        """Frames not recorded because the disk fell ``max_pending_s`` behind or failed."""
        self.frames_written = 0
        """Frames the writer has handed to the OS (and synced, with ``sync``)."""
        self.bytes_written = 0
        self.error: DataError | None = None
        """Why the writing stopped (a DataError), or None."""
        self.stopped_reason = ""
        """Why the recording stopped before the end of the run ("" while it records)."""
        self._cut_clean = False  # after an error: the file was cut back to whole frames
        self._closed = False
        self._pending: list[bytes] = []
        self._lock = threading.Lock()  # the pending list (the loop thread takes only this)
        self._io_lock = threading.Lock()  # the file
        self._wake = threading.Event()
        self._stop = False
        self._format: TakeFormat = CsvTake() if self.fmt == "csv" else BvhTake(self.rate_hz)
        self._row = np.zeros(N_VALUES)
        self._tmp = partial_path(self.path)
        check_new_take(self.path)
        try:
            self._fd = os.open(self._tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as exc:
            raise DataError(
                f"{self.path}: cannot create the recording ({exc.strerror}); check that the"
                " directory exists and is writable"
            ) from None
        if self.with_wrist is not None or not self._format.header_needs_wrist:
            self._start(bool(self.with_wrist))
        self._thread = threading.Thread(target=self._writer, name=f"recorder:{self.path.name}",
                                        daemon=True)
        self._thread.start()

    @property
    def n_frames(self) -> int:
        """Frames added so far (recorded or, see :attr:`frames_dropped`, dropped)."""
        return self._n_added

    @property
    def duration_s(self) -> float:
        """Performance time added so far: from the first frame's time to the last's, plus
        one frame at ``rate_hz``; 0 before the first frame."""
        if self._n_added == 0:
            return 0.0
        return self._t_last - self._t_first + 1.0 / self.rate_hz

    def add(self, t_s: float, pose50_deg: NDArray[np.float64],
            wrist_deg: NDArray[np.float64] | None = None) -> None:
        """Append one frame: time (s), (50,) curves and (4,) wrist DOFs or None (degrees)."""
        if self._closed:
            raise ValueError(f"{self.path}: the recording is closed")
        if self.with_wrist is None:
            self.with_wrist = wrist_deg is not None
            if self._format.header_needs_wrist:
                self._start(self.with_wrist)
        if wrist_deg is None and self.with_wrist:
            raise ValueError(f"{self.path}: this recording has wrist DOFs; pass wrist_deg")
        row = self._row
        row[:50] = pose50_deg
        if wrist_deg is not None:
            row[50:] = wrist_deg
        else:
            row[50:] = 0.0
        if self._n_added == 0:
            self._t_first = t_s
        self._t_last = t_s
        self._n_added += 1
        self._format.add(t_s, row, self.with_wrist, self._queue)

    def _queue(self, line: bytes, count: int) -> None:
        with self._lock:
            room = 0 if self.error is not None else self._max_pending - len(self._pending)
            kept = min(count, max(room, 0))
            if kept == 1:
                self._pending.append(line)
            elif kept:
                self._pending.extend([line] * kept)
            self.frames_dropped += count - kept

    def _start(self, with_wrist: bool) -> None:
        head = self._format.header(with_wrist)
        with self._lock:
            self._pending.append(head)

    def __call__(self, t_s: float, pose_deg: NDArray[np.float64]) -> None:
        """The rig's output hook: ``pose_deg`` = 50 curves then the 4 wrist DOFs
        (:data:`handrig.hand.ALL_JOINT_NAMES` order)."""
        self.add(t_s, pose_deg[:50], pose_deg[50:54])

    def status(self) -> OutputStatus:
        """``stopped_reason``: why the recording stopped before the run's end (a full
        disk ...), "" while it records and after an orderly close; ``duration_s``: the
        performance time added (:attr:`duration_s`)."""
        error = "" if self.error is None else str(self.error)
        return RecorderStatus(
            kind="recorder", name=self.fmt, path=str(self.path),
            frames_written=self.frames_written, bytes_written=self.bytes_written,
            frames_dropped=self.frames_dropped, errors=int(self.error is not None),
            last_error=error, stopped_reason=self.stopped_reason,
            duration_s=self.duration_s)

    def summary(self, duration_s: float) -> tuple[str, dict[str, Any]]:
        """``recording``: the take's path, format, frames, performance time, bytes,
        frames dropped and why it stopped early (if it did)."""
        st = self.status()
        dropped = (f", {st.frames_dropped} frames dropped (disk too slow)"
                   if st.frames_dropped else "")
        if st.stopped_reason:
            dropped = f", {st.frames_dropped} frames not recorded: {st.stopped_reason}"
        return "recording", {
            "path": st.path, "format": st.name, "frames": st.frames_written,
            "duration_s": round(st.duration_s, 3), "bytes": st.bytes_written,
            "frames_dropped": st.frames_dropped, "stopped_reason": st.stopped_reason,
            "said": f"recording {st.path}: {st.frames_written} frames, {st.duration_s:.1f} s,"
                    f" {st.bytes_written} bytes{dropped}"}

    def _writer(self) -> None:
        while True:
            self._wake.wait(self.flush_s)
            self._wake.clear()
            stop = self._stop
            self._write_pending()
            if stop:
                return

    def _write_pending(self) -> None:
        with self._io_lock:  # batches reach the file in the order they were taken
            with self._lock:
                lines, self._pending = self._pending, []
            if lines and self.error is None:
                self._write(lines)

    def _write(self, lines: list[bytes]) -> None:
        header = 1 if self.bytes_written == 0 else 0  # the first line written is the header
        size = 0
        try:
            for k in range(0, len(lines), _IOV_MAX):  # no join: writev releases the GIL
                group = lines[k: k + _IOV_MAX]
                want = sum(len(b) for b in group)
                done = os.writev(self._fd, group)
                if done < want:  # a short write (a signal, a full disk): write the rest
                    view = memoryview(b"".join(group))[done:]
                    while view:
                        view = view[os.write(self._fd, view):]
                size += want
            if self.sync:
                datasync(self._fd)
        except OSError as exc:
            self._failed(exc, len(lines) - header)
            return
        self.bytes_written += size
        self.frames_written += len(lines) - header
        try:
            self._format.frames_written(self._fd, self.frames_written)
        except OSError as exc:
            self._failed(exc, 0)

    def _failed(self, exc: OSError, lost: int) -> None:
        """A write failed: stop recording, cut the file back to its whole frames, say so."""
        why = _WHY.get(exc.errno or 0, "writing failed")
        with self._lock:
            self.error = DataError(
                f"{self.path}: writing the recording failed ({exc.strerror}); the take"
                f" holds the first {self.frames_written} frames")
            self.frames_dropped += lost + len(self._pending)
            self._pending = []
        try:
            os.ftruncate(self._fd, self.bytes_written)
            if self.bytes_written:
                self._format.frames_written(self._fd, self.frames_written)
            self._cut_clean = self.bytes_written > 0
        except OSError:
            self._cut_clean = False
        kept = self.frames_written / self.rate_hz if self.fmt == "bvh" else None
        self.stopped_reason = (
            f"recording stopped: {why} ({exc.strerror}); {self.path} keeps its first"
            f" {self.frames_written} frames" + (f" ({kept:.1f} s)" if kept is not None else "")
            + "; the show goes on")
        if self.log is not None:
            self.log(self.stopped_reason)

    def flush(self) -> None:
        """Write everything added so far now (from the calling thread)."""
        self._write_pending()

    def close(self) -> Path:
        """Write the rest, set the BVH frame count, move the take to its name (once), and
        return where it is."""
        if self._closed:
            return self.path
        self._closed = True
        if self.with_wrist is None:
            self.with_wrist = False
            if self._format.header_needs_wrist:
                self._start(False)
        self._format.finish(self._queue)
        self._stop = True
        self._wake.set()
        self._thread.join()
        if self.error is not None and not self._cut_clean:  # stays a .partial, for repair
            os.close(self._fd)
            raise DataError(f"{self.error}; what was written is in {self._tmp}: `handrig"
                            f" record repair {self._tmp}` keeps its whole frames")
        try:
            self._format.frames_written(self._fd, self.frames_written)
            datasync(self._fd)
            os.close(self._fd)
            self.path = self._publish()
        except OSError as exc:
            raise DataError(f"{self.path}: finishing the recording failed ({exc.strerror});"
                            f" the take is in {self._tmp}: `handrig record repair"
                            f" {self._tmp}` makes it readable") from None
        return self.path

    def _publish(self) -> Path:
        """Give the ``.partial`` its name without replacing a file that appeared there
        during the run (a hard link fails if the name is taken; a file system without
        hard links gets a check and a rename)."""
        target = self.path
        while True:
            try:
                os.link(self._tmp, target)
            except FileExistsError:
                target = free_path(target)
                continue
            except OSError:  # no hard links here (FAT on a USB stick)
                if target.exists():
                    target = free_path(target)
                os.replace(self._tmp, target)
            else:
                os.unlink(self._tmp)
            break
        if target != self.path and self.log is not None:
            self.log(f"{self.path} appeared during the run and is kept: the take is"
                     f" {target}")
        return target

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
