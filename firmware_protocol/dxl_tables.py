"""The X-series control tables and servo models, as data.

Addresses, sizes, areas, access and ranges from the ROBOTIS e-manual control
tables (REFERENCE.md section 2); :mod:`firmware_protocol.dynamixel` is the wire
codec and re-exports these names. No I/O, no clock, imports neither ``handrig``
nor ``sim``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum


class Area(Enum):
    EEPROM = "EEPROM"
    RAM = "RAM"


class Access(Enum):
    R = "R"
    RW = "RW"


@dataclass(frozen=True)
class Item:
    """One control-table item: address, size in bytes, memory area, access, value range."""

    address: int
    size: int
    area: Area
    access: Access
    signed: bool = False
    min_value: int | None = None
    max_value: int | None = None

    def encode(self, value: int) -> bytes:
        return int(value).to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes | bytearray) -> int:
        return int.from_bytes(data, "little", signed=self.signed)


class Reg(IntEnum):
    """X-series (XL330 / XC330 / XM430) control-table items; the value is the address."""

    MODEL_NUMBER = 0
    MODEL_INFORMATION = 2
    FIRMWARE_VERSION = 6
    ID = 7
    BAUD_RATE = 8
    RETURN_DELAY_TIME = 9
    DRIVE_MODE = 10
    OPERATING_MODE = 11
    SECONDARY_ID = 12
    PROTOCOL_TYPE = 13
    HOMING_OFFSET = 20
    MOVING_THRESHOLD = 24
    TEMPERATURE_LIMIT = 31
    MAX_VOLTAGE_LIMIT = 32
    MIN_VOLTAGE_LIMIT = 34
    PWM_LIMIT = 36
    CURRENT_LIMIT = 38
    VELOCITY_LIMIT = 44
    MAX_POSITION_LIMIT = 48
    MIN_POSITION_LIMIT = 52
    STARTUP_CONFIGURATION = 60
    SHUTDOWN = 63
    TORQUE_ENABLE = 64
    LED = 65
    STATUS_RETURN_LEVEL = 68
    REGISTERED_INSTRUCTION = 69
    HARDWARE_ERROR_STATUS = 70
    VELOCITY_I_GAIN = 76
    VELOCITY_P_GAIN = 78
    POSITION_D_GAIN = 80
    POSITION_I_GAIN = 82
    POSITION_P_GAIN = 84
    FEEDFORWARD_2ND_GAIN = 88
    FEEDFORWARD_1ST_GAIN = 90
    BUS_WATCHDOG = 98
    GOAL_PWM = 100
    GOAL_CURRENT = 102
    GOAL_VELOCITY = 104
    PROFILE_ACCELERATION = 108
    PROFILE_VELOCITY = 112
    GOAL_POSITION = 116
    REALTIME_TICK = 120
    MOVING = 122
    MOVING_STATUS = 123
    PRESENT_PWM = 124
    PRESENT_CURRENT = 126
    PRESENT_VELOCITY = 128
    PRESENT_POSITION = 132
    VELOCITY_TRAJECTORY = 136
    POSITION_TRAJECTORY = 140
    PRESENT_INPUT_VOLTAGE = 144
    PRESENT_TEMPERATURE = 146


_E, _R = Area.EEPROM, Area.RAM
_RO, _RW = Access.R, Access.RW

# Sizes, areas, access and ranges from the XL330-M288 control table (e-manual);
# XC330 and XM430 share the layout. Ranges that depend on a limit register
# (goal position, goal current, ...) are checked by the servo, not here.
X_SERIES_TABLE: dict[Reg, Item] = {
    Reg.MODEL_NUMBER: Item(0, 2, _E, _RO),
    Reg.MODEL_INFORMATION: Item(2, 4, _E, _RO),
    Reg.FIRMWARE_VERSION: Item(6, 1, _E, _RO),
    Reg.ID: Item(7, 1, _E, _RW, min_value=0, max_value=252),
    Reg.BAUD_RATE: Item(8, 1, _E, _RW, min_value=0, max_value=6),
    Reg.RETURN_DELAY_TIME: Item(9, 1, _E, _RW, min_value=0, max_value=254),
    Reg.DRIVE_MODE: Item(10, 1, _E, _RW, min_value=0, max_value=13),
    Reg.OPERATING_MODE: Item(11, 1, _E, _RW, min_value=0, max_value=16),
    Reg.SECONDARY_ID: Item(12, 1, _E, _RW, min_value=0, max_value=255),
    Reg.PROTOCOL_TYPE: Item(13, 1, _E, _RW, min_value=1, max_value=22),
    Reg.HOMING_OFFSET: Item(20, 4, _E, _RW, True, -1_044_479, 1_044_479),
    Reg.MOVING_THRESHOLD: Item(24, 4, _E, _RW, False, 0, 1023),
    Reg.TEMPERATURE_LIMIT: Item(31, 1, _E, _RW, min_value=0, max_value=100),
    Reg.MAX_VOLTAGE_LIMIT: Item(32, 2, _E, _RW, min_value=31, max_value=70),
    Reg.MIN_VOLTAGE_LIMIT: Item(34, 2, _E, _RW, min_value=31, max_value=70),
    Reg.PWM_LIMIT: Item(36, 2, _E, _RW, min_value=0, max_value=885),
    Reg.CURRENT_LIMIT: Item(38, 2, _E, _RW, min_value=0, max_value=1750),
    Reg.VELOCITY_LIMIT: Item(44, 4, _E, _RW, min_value=0, max_value=2047),
    Reg.MAX_POSITION_LIMIT: Item(48, 4, _E, _RW, min_value=0, max_value=4095),
    Reg.MIN_POSITION_LIMIT: Item(52, 4, _E, _RW, min_value=0, max_value=4095),
    Reg.STARTUP_CONFIGURATION: Item(60, 1, _E, _RW, min_value=0, max_value=3),
    Reg.SHUTDOWN: Item(63, 1, _E, _RW, min_value=0, max_value=255),
    Reg.TORQUE_ENABLE: Item(64, 1, _R, _RW, min_value=0, max_value=1),
    Reg.LED: Item(65, 1, _R, _RW, min_value=0, max_value=1),
    Reg.STATUS_RETURN_LEVEL: Item(68, 1, _R, _RW, min_value=0, max_value=2),
    Reg.REGISTERED_INSTRUCTION: Item(69, 1, _R, _RO),
    Reg.HARDWARE_ERROR_STATUS: Item(70, 1, _R, _RO),
    Reg.VELOCITY_I_GAIN: Item(76, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.VELOCITY_P_GAIN: Item(78, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.POSITION_D_GAIN: Item(80, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.POSITION_I_GAIN: Item(82, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.POSITION_P_GAIN: Item(84, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.FEEDFORWARD_2ND_GAIN: Item(88, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.FEEDFORWARD_1ST_GAIN: Item(90, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.BUS_WATCHDOG: Item(98, 1, _R, _RW, True, 0, 127),  # the servo sets -1 on a trip
    Reg.GOAL_PWM: Item(100, 2, _R, _RW, True, -885, 885),
    Reg.GOAL_CURRENT: Item(102, 2, _R, _RW, True, -1750, 1750),
    Reg.GOAL_VELOCITY: Item(104, 4, _R, _RW, True, -2047, 2047),
    Reg.PROFILE_ACCELERATION: Item(108, 4, _R, _RW, False, 0, 32767),
    Reg.PROFILE_VELOCITY: Item(112, 4, _R, _RW, False, 0, 32767),
    Reg.GOAL_POSITION: Item(116, 4, _R, _RW, True, -1_048_575, 1_048_575),
    Reg.REALTIME_TICK: Item(120, 2, _R, _RO),
    Reg.MOVING: Item(122, 1, _R, _RO),
    Reg.MOVING_STATUS: Item(123, 1, _R, _RO),
    Reg.PRESENT_PWM: Item(124, 2, _R, _RO, True),
    Reg.PRESENT_CURRENT: Item(126, 2, _R, _RO, True),
    Reg.PRESENT_VELOCITY: Item(128, 4, _R, _RO, True),
    Reg.PRESENT_POSITION: Item(132, 4, _R, _RO, True),
    Reg.VELOCITY_TRAJECTORY: Item(136, 4, _R, _RO, True),
    Reg.POSITION_TRAJECTORY: Item(140, 4, _R, _RO, True),
    Reg.PRESENT_INPUT_VOLTAGE: Item(144, 2, _R, _RO),
    Reg.PRESENT_TEMPERATURE: Item(146, 1, _R, _RO),
}
# Control-table memory modelled, in bytes (items end at 147; indirect data not modelled).
CONTROL_TABLE_BYTES = 148
EEPROM_END = 64


@dataclass(frozen=True)
class ModelInfo:
    """A servo model: model number, firmware, defaults that differ between models."""

    name: str
    model_number: int
    firmware_version: int
    stall_torque_nm: float  # at the nominal voltage
    stall_current_a: float
    no_load_speed_rpm: float
    current_limit: int  # Current Limit (38) default, units of 1 mA (XL330) / 2.69 mA (XM430)
    current_unit_ma: float
    nominal_voltage_dv: int  # Present Input Voltage, units of 0.1 V
    position_p_gain: int
    position_d_gain: int


# Datasheet figures (ROBOTIS e-manual): XL330-M288 0.52 Nm / 1.47 A / 103 rpm at 5 V;
# XC330-T288 0.92 Nm / 0.8 A / 67 rpm at 11.1 V; XM430-W350 4.1 Nm / 2.3 A / 46 rpm at 12 V;
# XC330-M288 (the LEAP hand's servo) 0.93 Nm / 1.80 A / 81 rpm at 5 V, model number 1240,
# Current Limit 2352 x 1 mA, Position P 1100 / D 500 by default.
MODELS: dict[str, ModelInfo] = {
    "XL330-M288": ModelInfo("XL330-M288", 1200, 46, 0.52, 1.47, 103.0, 1750, 1.0, 50, 400, 0),
    "XC330-T288": ModelInfo("XC330-T288", 1220, 46, 0.92, 0.8, 67.0, 910, 1.0, 120, 400, 0),
    "XC330-M288": ModelInfo("XC330-M288", 1240, 46, 0.93, 1.80, 81.0, 2352, 1.0, 50, 1100, 500),
    "XM430-W350": ModelInfo("XM430-W350", 1020, 46, 4.1, 2.3, 46.0, 1193, 2.69, 120, 800, 0),
}
MODEL_BY_NUMBER: dict[int, ModelInfo] = {m.model_number: m for m in MODELS.values()}

# Baud Rate (8) index -> bits per second.
BAUD_BY_INDEX: dict[int, int] = {
    0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000,
}
INDEX_BY_BAUD: dict[int, int] = {v: k for k, v in BAUD_BY_INDEX.items()}
# Units: Present Velocity 0.229 rpm; Return Delay Time 2 us; Bus Watchdog 20 ms.
VELOCITY_UNIT_RPM = 0.229
RETURN_DELAY_UNIT_S = 2e-6
BUS_WATCHDOG_UNIT_S = 0.020
TICKS_PER_TURN = 4096


def items_covering(address: int, length: int) -> list[Item] | None:
    """The items exactly covering ``[address, address + length)``, or ``None`` when the
    range cuts an item or touches an undefined address."""
    out: list[Item] = []
    pos = address
    end = address + length
    while pos < end:
        item = ITEM_AT.get(pos)
        if item is None or pos + item.size > end:
            return None
        out.append(item)
        pos += item.size
    return out


ITEM_AT: dict[int, Item] = {item.address: item for item in X_SERIES_TABLE.values()}
