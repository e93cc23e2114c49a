"""The servo tests' fixtures: an emulated bus of the first six shipped servos on a pty
(``sim``) and the driver connected to it (``bus``)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from handrig.devices.servo import DynamixelBus
from sim.dxl_bus import SimBus
from tests.helpers.servos import small_rig


@pytest.fixture
def sim() -> Iterator[SimBus]:
    with SimBus.from_rig(small_rig()) as bus:
        yield bus


@pytest.fixture
def bus(sim: SimBus) -> Iterator[DynamixelBus]:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000)
    b.connect()
    yield b
    b.close()
