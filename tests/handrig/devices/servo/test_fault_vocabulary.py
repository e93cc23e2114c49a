"""The bus contract names what a servo reports wrong with itself (``ServoFault``, a bit
each, a letter each on the panel); the X-series driver passes its Hardware Error Status
on as it is, so its bits must be those, meaning for meaning."""

from __future__ import annotations

from handrig.devices.servo.bus import FAULT_LETTERS, ServoFault, fault_letters
from handrig.devices.servo.registers import HARDWARE_ERROR_BITS, describe_hardware_error

MEANING = {ServoFault.INPUT_VOLTAGE: "input voltage", ServoFault.OVERHEATING: "overheating",
           ServoFault.ENCODER: "motor encoder", ServoFault.ELECTRICAL_SHOCK: "electrical shock",
           ServoFault.OVERLOAD: "overload"}


def test_the_drivers_hardware_error_bits_are_the_contracts_faults() -> None:
    assert {1 << bit: name for bit, name in HARDWARE_ERROR_BITS.items()} == {
        int(fault): MEANING[fault] for fault in ServoFault}
    for fault in ServoFault:  # the driver's words for each bit say the same
        assert describe_hardware_error(int(fault)).startswith(MEANING[fault])


def test_each_fault_has_its_own_letter() -> None:
    assert {fault for fault, _ in FAULT_LETTERS} == set(ServoFault)
    assert len({letter for _, letter in FAULT_LETTERS}) == len(FAULT_LETTERS)
    assert fault_letters(0) == ""
    assert fault_letters(ServoFault.OVERLOAD) == "L"
    assert fault_letters(ServoFault.INPUT_VOLTAGE | ServoFault.OVERHEATING) == "VH"
    assert fault_letters(1 << 1) == ""  # a bit the contract does not name shows nothing
