"""A BVH take killed between writing a batch of frames and updating its 'Frames:' line has
more frames than its header declares: reading it says so and points at `handrig record
repair`, which keeps every whole frame and sets the count (a clean-clone CI run at
01:43 on 2026-12-06 met this case after a SIGKILL)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from handrig.errors import DataError
from handrig.outputs.recorder import Recorder, load_performance, partial_path, repair


def test_frames_beyond_the_header_point_at_repair_and_repair_keeps_them(
        tmp_path: Path) -> None:
    take = tmp_path / "take.bvh"
    rec = Recorder(take, rate_hz=100.0)
    pose = np.linspace(-10.0, 60.0, 50)
    for i in range(20):
        rec.add(i / 100.0, pose + i, None)
    rec.close()
    text = take.read_text(encoding="utf-8")
    lines = text.splitlines()
    frames = [ln for ln in lines[lines.index("MOTION") + 3:] if ln.strip()]
    assert len(frames) == 20
    killed = partial_path(take)
    assert re.search(r"(?m)^Frames: 20 *$", text)
    killed.write_text(text.replace("Frames: 20", "Frames: 17", 1), encoding="utf-8")
    take.unlink()
    with pytest.raises(DataError, match="more than the header declares") as caught:
        load_performance(killed)
    assert "record repair" in str(caught.value)
    fixed = repair(killed)
    assert fixed.frames == 20
    _, poses, _ = load_performance(fixed.path)
    np.testing.assert_allclose(poses[:, 0], pose[0] + np.arange(20), atol=1e-4)
