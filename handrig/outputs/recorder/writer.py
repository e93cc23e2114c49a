"""Stream a take to disk while the show runs: :class:`Recorder`."""

from __future__ import annotations

import math
import os
import sys
import threading
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig.errors import DataError
from handrig.outputs.base import Output, OutputStatus
from handrig.outputs.recorder.bvh_take import BvhTake
from handrig.outputs.recorder.csv_take import CsvTake
from handrig.outputs.recorder.formats import (
    N_VALUES,
    Format,
    TakeFormat,
    datasync,
    format_of,
    partial_path,
)

_IOV_MAX = 1024 if sys.platform.startswith("linux") else 16  # buffers per writev (Linux; POSIX)


class Recorder(Output):
    """Stream frames to a CSV or BVH file while the show runs.

    ``add`` (or calling the recorder, the rig's output hook) turns the frame into one
    text line at once and appends it to a list; a writer thread takes that list every
    ``flush_s`` seconds, writes it with ``os.writev`` and (``sync=True``) asks the OS to
    put it on the disk (``fdatasync``). So a killed process or a power cut loses at most
    the last ``flush_s`` seconds plus one write, and memory holds at most
    ``max_pending_s`` seconds of lines (frames beyond that, when the disk stalls, are
    dropped and counted in :attr:`frames_dropped`, never raised into the loop). A
    write error (disk full) stops the writing, is kept in :attr:`error` and raised by
    :meth:`close`, which then leaves the take as ``<path>.partial`` for
    :func:`~handrig.outputs.recorder.repair.repair`.

    The file is written as ``<path>.partial`` and renamed to ``path`` by :meth:`close`.
    The BVH header's frame count is a fixed-width field, rewritten after each batch, so
    a take cut by a kill between batches reads as it is; one cut inside a batch or by a
    power cut needs repair. A ``.partial`` left by a run that did not close is refused at
    start (it holds a take): repair turns it into a readable file.
    ``with_wrist``: record the 4 wrist DOFs; None decides on the first frame.
    """

    def __init__(self, path: str | Path, fmt: str | None = None, rate_hz: float = 200.0, *,
                 with_wrist: bool | None = None, flush_s: float = 0.5, sync: bool = True,
                 max_pending_s: float = 60.0) -> None:
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
        self._max_pending = max(1, math.ceil(max_pending_s * self.rate_hz)) + 1  # + header
        self._n_added = 0
        self.frames_dropped = 0
        """Frames not recorded because the disk fell ``max_pending_s`` behind or failed."""
        self.frames_written = 0
        """Frames the writer has handed to the OS (and synced, with ``sync``)."""
        self.bytes_written = 0
        self.error: DataError | None = None
        self._closed = False
        self._pending: list[bytes] = []
        self._lock = threading.Lock()  # the pending list (the loop thread takes only this)
        self._io_lock = threading.Lock()  # the file
        self._wake = threading.Event()
        self._stop = False
        self._format: TakeFormat = CsvTake() if self.fmt == "csv" else BvhTake(self.rate_hz)
        self._row = np.zeros(N_VALUES)
        self._tmp = partial_path(self.path)
        if self._tmp.exists():
            raise DataError(
                f"{self._tmp}: an unfinished take from a run that did not close it is in"
                f" the way; recover it with `handrig record repair {self._tmp}` (or move it)"
                " and start again")
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
        line = self._format.encode(t_s, row, self.with_wrist)
        self._n_added += 1
        with self._lock:
            if len(self._pending) >= self._max_pending or self.error is not None:
                self.frames_dropped += 1
                return
            self._pending.append(line)

    def _start(self, with_wrist: bool) -> None:
        head = self._format.header(with_wrist)
        with self._lock:
            self._pending.append(head)

    def __call__(self, t_s: float, pose_deg: NDArray[np.float64]) -> None:
        """The rig's output hook: ``pose_deg`` = 50 curves then the 4 wrist DOFs
        (:data:`handrig.hand.ALL_JOINT_NAMES` order)."""
        self.add(t_s, pose_deg[:50], pose_deg[50:54])

    def status(self) -> OutputStatus:
        error = "" if self.error is None else str(self.error)
        stopped = ("closed" if self._closed else "") or (
            "write error: the take stops here" if error else "")
        return OutputStatus(
            kind="recorder", name=self.fmt, path=str(self.path),
            frames_written=self.frames_written, bytes_written=self.bytes_written,
            frames_dropped=self.frames_dropped, errors=int(self.error is not None),
            last_error=error, stopped_reason=stopped,
            duration_s=self.frames_written / self.rate_hz)

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
            with self._lock:
                self.error = DataError(
                    f"{self.path}: writing the recording failed ({exc.strerror}); the take"
                    f" holds the first {self.frames_written} frames")
                self.frames_dropped += len(lines) - header
            return
        self.bytes_written += size
        self.frames_written += len(lines) - header
        try:
            self._format.frames_written(self._fd, self.frames_written)
        except OSError as exc:
            with self._lock:
                self.error = DataError(f"{self.path}: updating the frame count failed"
                                       f" ({exc.strerror})")

    def flush(self) -> None:
        """Write everything added so far now (from the calling thread)."""
        self._write_pending()

    def close(self) -> Path:
        """Write the rest, set the BVH frame count, rename to the final name (once)."""
        if self._closed:
            return self.path
        self._closed = True
        if self.with_wrist is None:
            self.with_wrist = False
            if self._format.header_needs_wrist:
                self._start(False)
        self._stop = True
        self._wake.set()
        self._thread.join()
        if self.error is not None:  # the take stays a .partial, for repair
            os.close(self._fd)
            raise DataError(f"{self.error}; what was written is in {self._tmp}: `handrig"
                            f" record repair {self._tmp}` keeps its whole frames")
        try:
            self._format.frames_written(self._fd, self.frames_written)
            datasync(self._fd)
            os.close(self._fd)
            os.replace(self._tmp, self.path)
        except OSError as exc:
            raise DataError(f"{self.path}: finishing the recording failed ({exc.strerror});"
                            f" the take is in {self._tmp}: `handrig record repair"
                            f" {self._tmp}` makes it readable") from None
        return self.path

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
