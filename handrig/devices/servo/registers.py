"""X-series control table items the driver uses (REFERENCE.md section 2), as data.

Each :class:`Reg` member is ``(address, size in bytes, signed, access)``, access
``"R"`` (read only) or ``"RW"``; values on the wire are little-endian two's
complement. Addresses below 64 are EEPROM (writable only with torque off).
"""

from __future__ import annotations

from enum import Enum


class Reg(Enum):
    """A control-table item: ``address``, ``size`` (bytes), ``signed``, ``access``."""

    MODEL_NUMBER = (0, 2, False, "R")
    FIRMWARE_VERSION = (6, 1, False, "R")
    ID = (7, 1, False, "RW")
    BAUD_RATE = (8, 1, False, "RW")
    RETURN_DELAY_TIME = (9, 1, False, "RW")
    DRIVE_MODE = (10, 1, False, "RW")
    OPERATING_MODE = (11, 1, False, "RW")
    HOMING_OFFSET = (20, 4, True, "RW")
    PWM_LIMIT = (36, 2, False, "RW")
    CURRENT_LIMIT = (38, 2, False, "RW")
    MAX_POSITION_LIMIT = (48, 4, False, "RW")
    MIN_POSITION_LIMIT = (52, 4, False, "RW")
    TORQUE_ENABLE = (64, 1, False, "RW")
    LED = (65, 1, False, "RW")
    STATUS_RETURN_LEVEL = (68, 1, False, "RW")
    HARDWARE_ERROR_STATUS = (70, 1, False, "R")
    POSITION_D_GAIN = (80, 2, False, "RW")
    POSITION_I_GAIN = (82, 2, False, "RW")
    POSITION_P_GAIN = (84, 2, False, "RW")
    BUS_WATCHDOG = (98, 1, True, "RW")
    GOAL_PWM = (100, 2, True, "RW")  # in the position modes, a cap on the motor's PWM
    GOAL_CURRENT = (102, 2, True, "RW")
    PROFILE_VELOCITY = (112, 4, False, "RW")
    GOAL_POSITION = (116, 4, True, "RW")
    MOVING = (122, 1, False, "R")
    PRESENT_CURRENT = (126, 2, True, "R")
    PRESENT_VELOCITY = (128, 4, True, "R")
    PRESENT_POSITION = (132, 4, True, "R")
    PRESENT_INPUT_VOLTAGE = (144, 2, False, "R")
    PRESENT_TEMPERATURE = (146, 1, False, "R")

    @property
    def address(self) -> int:
        return int(self.value[0])

    @property
    def size(self) -> int:
        return int(self.value[1])

    @property
    def signed(self) -> bool:
        return bool(self.value[2])

    @property
    def writable(self) -> bool:
        return self.value[3] == "RW"

    def encode(self, value: int) -> bytes:
        """Little-endian bytes of ``value``; raises OverflowError if it does not fit."""
        return int(value).to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes) -> int:
        """The value held in ``data`` (exactly ``size`` bytes)."""
        return int.from_bytes(data[: self.size], "little", signed=self.signed)


OPERATING_MODE_POSITION = 3
OPERATING_MODE_EXTENDED_POSITION = 4
OPERATING_MODE_CURRENT_BASED_POSITION = 5  # position control, torque capped by Goal Current
STATUS_RETURN_ALL = 2
BUS_WATCHDOG_UNIT_MS = 20  # Bus Watchdog counts in 20 ms units
BUS_WATCHDOG_TRIPPED = -1  # the servo writes -1 (0xFF) after a watchdog stop

# Velocity: 0.229 rev/min per unit on every X-series servo (e-manual, Present Velocity).
VELOCITY_DPS_PER_UNIT = 0.229 * 360.0 / 60.0
# Present Current unit per model number: XL330/XC330 1 mA, XM430 2.69 mA (e-manual).
CURRENT_MA_PER_UNIT: dict[int, float] = {1200: 1.0, 1220: 1.0, 1020: 2.69}
CURRENT_MA_PER_UNIT[1240] = 1.0  # XC330-M288 (the LEAP hand's servo)

# Status ERR byte (protocol 2.0): bit 7 Alert; bits 0-6 hold an error number.
ERR_ALERT = 0x80
ERROR_NUMBERS: dict[int, str] = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}
# Hardware Error Status bits (addr 70).
HARDWARE_ERROR_BITS: dict[int, str] = {
    0: "input voltage",
    2: "overheating",
    3: "motor encoder",
    4: "electrical shock",
    5: "overload",
}
# These bits are the bus contract's ServoFault bits as they are (handrig.devices.servo.bus:
# the driver passes Hardware Error Status on unmapped; test_fault_vocabulary.py holds the
# two tables equal).


def describe_status_error(err: int) -> str:
    """Words for a status packet's ERR byte, e.g. ``"alert + data range error"``."""
    parts = []
    if err & ERR_ALERT:
        parts.append("alert (hardware error, see Hardware Error Status)")
    number = err & 0x7F
    if number:
        parts.append(ERROR_NUMBERS.get(number, f"unknown error number {number}"))
    return " + ".join(parts) if parts else "no error"


def describe_hardware_error(bits: int) -> str:
    """Words for Hardware Error Status, naming each bit: ``"overload (bit 5)"``."""
    names = [
        f"{HARDWARE_ERROR_BITS.get(b, 'unknown')} (bit {b})" for b in range(8) if bits >> b & 1
    ]
    return ", ".join(names) if names else "none"
