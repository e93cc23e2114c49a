"""The "sensor pinned" window is one number in three places: the firmware's rail check
(GC_RAIL_LOW), the host's naming of the pinned channel (RAIL_MARGIN) and SPEC.md."""

from __future__ import annotations

import re
from pathlib import Path

from handrig.devices.glove_status import RAIL_MARGIN, pinned_channels

ROOT = Path(__file__).resolve().parents[2]


def test_firmware_host_and_spec_agree_on_the_rail_window():
    header = (ROOT / "firmware/glove/glove_core.h").read_text()
    firmware = int(re.search(r"#define GC_RAIL_LOW (\d+)", header).group(1))  # type: ignore[union-attr]
    spec = (ROOT / "firmware_protocol/SPEC.md").read_text()
    said = re.search(r"a raw channel has read within (\d+) counts of 0 or of full scale", spec)
    assert said is not None
    assert firmware == RAIL_MARGIN == int(said.group(1)) == 16


def test_a_single_sample_a_step_off_the_rail_is_named():
    # one 10-bit sample scaled to 12 bits, two steps of noise below full scale or above 0
    assert pinned_channels([4084, 8, 2000, 4070, 17]) == [(0, "full scale"), (1, "0")]
