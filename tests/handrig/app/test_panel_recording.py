"""The panel says when the recording stopped during the show, and why."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from handrig.app.panel import outputs_line
from handrig.errors import DataError
from handrig.outputs.recorder import Recorder


def test_a_recording_stopped_by_a_full_disk_shows_in_the_panel(tmp_path: Path) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("needs /dev/full (Linux)")
    rec = Recorder(tmp_path / "take.csv", sync=False)
    os.close(rec._fd)
    rec._fd = os.open("/dev/full", os.O_WRONLY)  # every write fails: ENOSPC
    rec.add(0.0, np.zeros(50), np.zeros(4))
    assert outputs_line((rec.status().cell(),)).plain.endswith("0:00")  # no warning
    rec.flush()
    st = rec.status()
    assert st.stopped_reason.startswith("recording stopped: the disk is full")
    line = outputs_line((st.cell(),)).plain
    assert "rec " in line and "stopped: the disk is full" in line
    with pytest.raises(DataError, match="record repair"):
        rec.close()
