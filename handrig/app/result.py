"""What a live session returns and how a command prints it: :class:`LiveResult`,
:func:`failed` (a session that could not begin), :func:`print_result` (the summary and
the exit status)."""

from __future__ import annotations

import contextlib
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from handrig.app.hands import SessionParts
from handrig.app.parts import RigParts
from handrig.app.summary import format_hands_summary, format_summary, summary_dict
from handrig.errors import HandrigError
from handrig.loop.stats import RunStats


@dataclass
class LiveResult:
    """``summary``: the figures (:func:`handrig.app.summary.summary_dict`, plus ``error``
    when the session ended with one); ``started``: whether the rig got as far as
    torque-on; ``snapshots``: present positions (every hand's, in hand order) kept every
    ``snapshot_every`` frames, taken at ``snapshot_times_s`` (seconds since the loop
    started)."""

    summary: dict[str, Any]
    snapshots: list[np.ndarray]
    joint_names: tuple[str, ...]
    sim_output: str = ""
    error: HandrigError | None = None
    started: bool = False
    snapshot_times_s: list[float] = field(default_factory=list)  # of each snapshot



def failed(error: HandrigError, parts: RigParts | SessionParts | None = None) -> LiveResult:
    """The result of a session that could not begin (a config, an emulator, a port)."""
    summary = summary_dict(RunStats(), None, None, None)
    summary["error"] = str(error)
    joints = tuple(s.joint for s in parts.rig_config.servos) if parts is not None else ()
    return LiveResult(summary, [], joints, error=error)


def print_result(result: LiveResult, as_json: bool) -> int:
    """Print a session's summary (one JSON object with ``as_json``) and return the exit
    status: 0 when it ended cleanly with torque off, 1 when the run ended with an error
    or torque may still be on, 2 when it failed before the rig started. A summary that
    cannot be written (the terminal is gone) is not an error."""
    import json

    summary = result.summary
    with contextlib.suppress(OSError, ValueError):
        if as_json:
            print(json.dumps(summary), flush=True)
        elif result.started:
            print(format_hands_summary(summary) if "hands" in summary
                  else format_summary(summary), flush=True)
        if result.error is not None and (as_json or not result.started):
            print(f"handrig: error: {result.error}", file=sys.stderr, flush=True)
    if result.error is not None and not result.started:
        return 2
    return 1 if result.error is not None or summary["torque_off"] is not True else 0
