"""The driver's register table against the emulator's: written apart, they must agree."""

from __future__ import annotations

import pytest

from firmware_protocol import dynamixel as dx
from handrig.devices.servo.registers import Reg


@pytest.mark.parametrize("reg", list(Reg), ids=lambda r: r.name)
def test_every_driver_register_agrees_with_the_emulator(reg: Reg) -> None:
    item = dx.X_SERIES_TABLE[dx.Reg[reg.name]]
    assert reg.address == item.address == int(dx.Reg[reg.name])
    assert reg.size == item.size
    assert reg.signed == item.signed
    assert reg.writable == (item.access is dx.Access.RW)


def test_the_present_state_spans_are_contiguous_in_both_tables() -> None:
    # "motion" reads current, velocity and position in one 10-byte span
    assert Reg.PRESENT_CURRENT.address + Reg.PRESENT_CURRENT.size == Reg.PRESENT_VELOCITY.address
    assert Reg.PRESENT_VELOCITY.address + Reg.PRESENT_VELOCITY.size == (
        Reg.PRESENT_POSITION.address)
    covered = dx.items_covering(Reg.PRESENT_CURRENT.address, 10)
    assert covered is not None and [i.address for i in covered] == [126, 128, 132]


def test_the_current_based_settings_are_in_the_drivers_table() -> None:
    for name in ("CURRENT_LIMIT", "POSITION_P_GAIN", "POSITION_D_GAIN", "GOAL_CURRENT"):
        assert name in Reg.__members__
