"""Takes started and stopped by cue during a live run: :class:`CueTakes`.

``record/start [NAME]`` opens a new take (a :class:`~handrig.outputs.recorder.Recorder`,
so the takes' rules hold: streamed to ``<take>.partial`` while it records, renamed when
it closes, never over an existing take), ``record/stop`` closes it. The file is opened
and closed on the cue's thread; the loop only hands each pose to the take open at the
time, under a lock it alone takes on every frame (a cue's thread takes it twice a take,
to swap the take in and out), so a closing take never meets a frame half-added.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from handrig.errors import DataError
from handrig.outputs.base import FloatArray, OutputStatus
from handrig.outputs.recorder import Recorder, free_path

SUFFIXES = (".csv", ".bvh")


class CueTakes:
    """The takes of a run's cues, in ``folder``, one at a time; each starts at time 0
    (its first frame's). A BVH take is written at ``rate_hz``. Closing it (the run's
    end) closes a take still open, as ``record/stop`` does. Called as the loop's output
    (``takes(t_s, pose_deg)``); not an :class:`~handrig.outputs.base.Output`: its part
    of the summary is the cues' (``cues.takes``), present only when a cue was taken."""

    def __init__(self, folder: str | Path, rate_hz: float, *,
                 log: Callable[[str], None] | None = None) -> None:
        self.folder = Path(folder) if str(folder) else Path(".")
        self.rate_hz = float(rate_hz)
        self.log = log
        self._active: Recorder | None = None
        self._t0_s: float | None = None
        self._frame_lock = threading.Lock()  # the loop, on each frame while a take is open
        self._control = threading.Lock()  # start and stop, from the cues' threads
        self.done: list[dict[str, Any]] = []  # each closed take's figures

    def __call__(self, t_s: float, pose_deg: FloatArray) -> None:
        if self._active is None:
            return
        with self._frame_lock:
            take = self._active
            if take is None:
                return
            if self._t0_s is None:
                self._t0_s = t_s
            take(t_s - self._t0_s, pose_deg)

    def path_for(self, name: str | None) -> Path:
        """Where the take ``name`` goes (a plain file name; ``.csv`` when it has no
        suffix); without a name, ``take-<date>-<time>.csv`` (the next free one).
        DataError for a name that is a path or has another suffix."""
        if name is None:
            return free_path(self.folder / time.strftime("take-%Y%m%d-%H%M%S.csv"))
        if (not name or "/" in name or "\\" in name or name.startswith(".")
                or name != name.strip()):
            raise DataError(f"{name!r} is not a take's name: a plain file name is (e.g. "
                            f"act1 or act1.bvh), written in {self.folder}")
        p = self.folder / name
        if p.suffix.lower() not in SUFFIXES:
            p = p.with_name(p.name + ".csv")
        return p

    def start(self, name: str | None) -> str:
        """A new take (DataError: one is open, or the name is taken or not a name)."""
        with self._control:
            if self._active is not None:
                raise DataError(f"a take is recording already ({self._active.path}): "
                                "record/stop it first")
            path = self.path_for(name)
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise DataError(f"{path.parent}: cannot make the takes' folder "
                                f"({exc.strerror}); name another ([cues] takes, "
                                "--cue-takes)") from None
            take = Recorder(path, rate_hz=self.rate_hz, log=self.log)
            with self._frame_lock:
                self._t0_s = None
                self._active = take
            return f"recording {take.path}"

    def stop(self) -> str:
        """Close the open take (DataError when none is open)."""
        with self._control:
            with self._frame_lock:
                take, self._active = self._active, None
            if take is None:
                raise DataError("no take is recording: record/start one first")
            path = take.close()
            figures = take.summary(0.0)[1]
            self.done.append(figures)
            return (f"take {path} closed: {figures['frames']} frames, "
                    f"{figures['duration_s']:.2f} s")

    def close(self) -> str:
        """At the run's end: the open take closed (as ``record/stop``), "" when none was."""
        with self._control:
            if self._active is None:
                return ""
        return self.stop()

    @property
    def recording(self) -> str:
        """The open take's path, "" when none is open."""
        take = self._active
        return "" if take is None else str(take.path)

    def status(self) -> OutputStatus:
        take = self._active
        if take is None:
            return OutputStatus(kind="cue_takes", name="cue takes", path="",
                                frames_written=sum(d["frames"] for d in self.done))
        st = take.status()
        return OutputStatus(kind="cue_takes", name="cue take", path=st.path,
                            frames_written=st.frames_written, bytes_written=st.bytes_written,
                            frames_dropped=st.frames_dropped, errors=st.errors,
                            last_error=st.last_error, stopped_reason=st.stopped_reason,
                            duration_s=st.duration_s)

    def summary(self) -> dict[str, Any]:
        """Each take closed (path, frames, seconds ...) and the one open ("" none)."""
        return {"done": list(self.done), "recording": self.recording}
