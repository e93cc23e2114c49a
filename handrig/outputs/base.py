"""The output contract: :class:`Output`, what the loop hands each full pose to, and its
:class:`OutputStatus`.

The loop calls an output once per written pose, ``output(t_s, pose_deg)``: ``t_s``
seconds since the run started, ``pose_deg`` the full pose
(:data:`handrig.pose.pipeline.POSE_NAMES` order, degrees). The call runs on the
loop's thread and must not block (a recorder queues the frame, a network sender
drops it). ``status()`` may be called from any thread and returns a frozen record;
the panel and the telemetry read only that. What the panel shows of an output is its
status's :meth:`OutputStatus.cell` (an output's own status class overrides it, built on
the panel's thread, not the loop's) and what the run summary says is its
:meth:`Output.summary`: an output owns both, so a new one needs no branch in the panel
or the summary.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


SUMMARY_KEYS_WHEN_OFF: tuple[str, ...] = ("vmc", "recording")
"""The run summary's ``outputs`` has had these keys from the start, None when that output
is off (``--json`` readers may count on them); every other output's key is there only
when it ran."""


@dataclass(frozen=True)
class PanelCell:
    """An output's place on the panel's outputs line, as data (the panel formats it).

    ``label``: a short name ("VMC", "rec"; "" shows nothing); ``target``: its address or
    file, shortened to fit with its end kept; then the figures it has: the recent rate
    of its ``frames_written`` when ``rate`` (the panel fills in ``rate_hz``), its
    ``size_bytes`` on disk, ``duration_s`` of motion, ``frames``; ``errors`` and ``alert``
    (why it stopped) in red; ``ok`` False shows it in yellow (a timecode not locked).
    """

    label: str
    target: str = ""
    rate: bool = False
    rate_hz: float = float("nan")
    size_bytes: int | None = None
    duration_s: float | None = None
    frames: int | None = None
    errors: int = 0
    alert: str = ""
    ok: bool = True


@dataclass(frozen=True)
class OutputStatus:
    """What an output has done so far. ``kind``: ``"recorder"``, ``"vmc"`` ...;
    ``name``: a short label; ``path`` (a file) or ``address`` (``host:port``), the other
    empty; ``duration_s``: seconds of motion written (0 where that means nothing);
    ``stopped_reason``: why the output stopped taking frames ("" while it takes them)."""

    kind: str
    name: str
    path: str = ""
    address: str = ""
    frames_written: int = 0
    bytes_written: int = 0
    frames_dropped: int = 0
    errors: int = 0
    last_error: str = ""
    stopped_reason: str = ""
    duration_s: float = 0.0

    def cell(self) -> PanelCell:
        """What the panel shows of this output (on the panel's thread). Default: its name,
        its file or address, its errors and why it stopped; an output's status class
        (a subclass with no fields of its own) says more."""
        return PanelCell(self.name, self.path or self.address, errors=self.errors,
                         alert=self.stopped_reason)


class Output(ABC):
    """Something that takes the loop's full poses (a recorder, a network sender)."""

    @abstractmethod
    def __call__(self, t_s: float, pose_deg: FloatArray) -> None:
        """Take one pose (on the loop's thread: never blocks)."""

    @abstractmethod
    def status(self) -> OutputStatus:
        """The counters and state, as a frozen record (any thread)."""

    def close(self) -> object:
        """Finish (flush, close the file or socket). Idempotent."""
        return None

    def summary(self, duration_s: float) -> tuple[str, dict[str, Any]]:
        """This output's part of the run summary: (its key, its figures, JSON-able), the
        figures' ``said`` the line a person reads. ``duration_s``: how long the run
        lasted. Default: the status under its kind."""
        st = self.status()
        errors = f", {st.errors} errors" if st.errors else ""
        stopped = f" ({st.stopped_reason})" if st.stopped_reason else ""
        return st.kind, {"name": st.name, "path": st.path, "address": st.address,
                         "frames": st.frames_written, "bytes": st.bytes_written,
                         "frames_dropped": st.frames_dropped, "errors": st.errors,
                         "stopped_reason": st.stopped_reason,
                         "said": f"{st.name} {st.path or st.address}: {st.frames_written}"
                                 f" frames{errors}{stopped}"}
