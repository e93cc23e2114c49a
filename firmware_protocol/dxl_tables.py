"""The X-series control tables and servo models, as data.

Addresses, sizes, areas, access and ranges from the ROBOTIS e-manual control
tables (REFERENCE.md section 2); :mod:`firmware_protocol.dynamixel` is the wire
codec and re-exports these names. No I/O, no clock, imports neither ``handrig``
nor ``sim``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
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
    PWM_SLOPE = 62
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
    BACKUP_READY = 147


_E, _R = Area.EEPROM, Area.RAM
_RO, _RW = Access.R, Access.RW

# The X-series layout: sizes, areas, access and ranges from the XL330-M288 control
# table (e-manual). Each model's own table (:data:`MODELS`) is this layout with its
# ranges and without the items it lacks. Ranges that depend on a limit register
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
    Reg.PWM_SLOPE: Item(62, 1, _E, _RW, min_value=1, max_value=255),
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
    Reg.BACKUP_READY: Item(147, 1, _R, _RO),
}
# Control-table memory modelled, in bytes (items end at 148; indirect data not modelled).
CONTROL_TABLE_BYTES = 148
EEPROM_END = 64


@dataclass(frozen=True)
class ModelInfo:
    """A servo model from its ROBOTIS e-manual page: its control table (address, size,
    access, range of every item it has) and initial values, plus datasheet figures.

    Items whose range is another item (Goal Current up to Current Limit, ...) carry
    the widest range here; the servo checks the limit item as well.
    """

    name: str
    model_number: int
    firmware_version: int
    stall_torque_nm: float  # at the nominal voltage
    stall_current_a: float
    no_load_speed_rpm: float
    current_unit_ma: float  # Current Limit / Goal / Present Current unit
    nominal_voltage_dv: int  # the recommended supply, units of 0.1 V
    table: Mapping[Reg, Item]
    defaults: Mapping[Reg, int]
    operating_modes: tuple[int, ...]
    emanual: str  # the e-manual page the table comes from

    @property
    def current_limit(self) -> int:
        """Current Limit (38) initial value; 0 for a model without current sensing."""
        return self.defaults.get(Reg.CURRENT_LIMIT, 0)

    @property
    def position_p_gain(self) -> int:
        return self.defaults[Reg.POSITION_P_GAIN]

    @property
    def position_d_gain(self) -> int:
        return self.defaults[Reg.POSITION_D_GAIN]

    @property
    def has_current(self) -> bool:
        """Current Limit, Goal Current and current-based modes exist (not on XC430)."""
        return Reg.CURRENT_LIMIT in self.table

    def item_at(self) -> dict[int, Item]:
        """Address -> item of this model's table."""
        return {item.address: item for item in self.table.values()}


_EMANUAL = "https://emanual.robotis.com/docs/en/dxl/x/{}/"

# Initial values every X-series model in this file shares (e-manual control tables).
_COMMON_DEFAULTS: dict[Reg, int] = {
    Reg.MODEL_INFORMATION: 0, Reg.ID: 1, Reg.BAUD_RATE: 1, Reg.RETURN_DELAY_TIME: 250,
    Reg.DRIVE_MODE: 0, Reg.OPERATING_MODE: 3, Reg.SECONDARY_ID: 255, Reg.PROTOCOL_TYPE: 2,
    Reg.HOMING_OFFSET: 0, Reg.MOVING_THRESHOLD: 10, Reg.PWM_LIMIT: 885,
    Reg.MAX_POSITION_LIMIT: 4095, Reg.MIN_POSITION_LIMIT: 0, Reg.STARTUP_CONFIGURATION: 0,
    Reg.STATUS_RETURN_LEVEL: 2, Reg.POSITION_I_GAIN: 0, Reg.FEEDFORWARD_1ST_GAIN: 0,
    Reg.FEEDFORWARD_2ND_GAIN: 0,
}


def _table(ranges: Mapping[Reg, tuple[int, int]], drop: Iterable[Reg] = ()) -> dict[Reg, Item]:
    """The X-series layout with this model's ranges; ``drop``: items it lacks."""
    gone = set(drop)
    out = {}
    for reg, item in X_SERIES_TABLE.items():
        if reg in gone:
            continue
        if reg in ranges:
            low, high = ranges[reg]
            item = replace(item, min_value=low, max_value=high)
        out[reg] = item
    return out


def _x330(name: str, number: int, *, torque: float, amps: float, rpm: float, volts_dv: int,
          voltage: tuple[int, int, int, int], current_limit: int, velocity_limit: int,
          pwm_slope: int, shutdown: int, gains: tuple[int, int, int, int, int]) -> ModelInfo:
    """An X330 model (XL330, XC330): baud index 0-6, Drive Mode 0-5, Protocol Type 2-22,
    velocity limit up to 2047, current in 1 mA units, six operating modes.
    ``voltage``: Max default, Min default, range low, range high (0.1 V);
    ``gains``: Velocity I, Velocity P, Position D, Position I, Position P."""
    max_v, min_v, v_lo, v_hi = voltage
    table = _table({
        Reg.BAUD_RATE: (0, 6), Reg.DRIVE_MODE: (0, 5), Reg.PROTOCOL_TYPE: (2, 22),
        Reg.MAX_VOLTAGE_LIMIT: (v_lo, v_hi),
        Reg.MIN_VOLTAGE_LIMIT: (v_lo, v_hi), Reg.CURRENT_LIMIT: (0, current_limit),
        Reg.GOAL_CURRENT: (-current_limit, current_limit), Reg.VELOCITY_LIMIT: (0, 2047),
    })
    vi, vp, pd, pi, pp = gains
    defaults = {**_COMMON_DEFAULTS, Reg.MODEL_NUMBER: number, Reg.TEMPERATURE_LIMIT: 70,
                Reg.MAX_VOLTAGE_LIMIT: max_v, Reg.MIN_VOLTAGE_LIMIT: min_v,
                Reg.CURRENT_LIMIT: current_limit, Reg.VELOCITY_LIMIT: velocity_limit,
                Reg.PWM_SLOPE: pwm_slope, Reg.SHUTDOWN: shutdown, Reg.VELOCITY_I_GAIN: vi,
                Reg.VELOCITY_P_GAIN: vp, Reg.POSITION_D_GAIN: pd, Reg.POSITION_I_GAIN: pi,
                Reg.POSITION_P_GAIN: pp}
    return ModelInfo(name, number, 46, torque, amps, rpm, 1.0, volts_dv, table, defaults,
                     (0, 1, 3, 4, 5, 16), _EMANUAL.format(name.lower()))


def _x430(name: str, number: int, *, torque: float, amps: float, rpm: float,
          voltage: tuple[int, int, int, int], current_limit: int | None, velocity_limit: int,
          moving_threshold: int, gains: tuple[int, int, int, int, int],
          page: str = "") -> ModelInfo:
    """An X430 model (XM430, XC430): baud index 0-7 (7 is 4.5 Mbps), Drive Mode 0-5,
    Protocol Type 1-2, velocity limit up to 1023, Temperature Limit 80, no PWM Slope.
    ``current_limit`` None: no current sensing (XC430: 126 is Present Load, 0.1 %).
    ``page``: the e-manual page's name when it is not the model's in lower case."""
    max_v, min_v, v_lo, v_hi = voltage
    ranges: dict[Reg, tuple[int, int]] = {
        Reg.BAUD_RATE: (0, 7), Reg.DRIVE_MODE: (0, 5), Reg.PROTOCOL_TYPE: (1, 2),
        Reg.MAX_VOLTAGE_LIMIT: (v_lo, v_hi),
        Reg.MIN_VOLTAGE_LIMIT: (v_lo, v_hi), Reg.VELOCITY_LIMIT: (0, 1023),
    }
    drop = [Reg.PWM_SLOPE]
    if current_limit is None:
        drop += [Reg.CURRENT_LIMIT, Reg.GOAL_CURRENT]
    else:
        ranges[Reg.CURRENT_LIMIT] = (0, current_limit)
        ranges[Reg.GOAL_CURRENT] = (-current_limit, current_limit)
    vi, vp, pd, pi, pp = gains
    defaults = {**_COMMON_DEFAULTS, Reg.MODEL_NUMBER: number, Reg.TEMPERATURE_LIMIT: 80,
                Reg.MAX_VOLTAGE_LIMIT: max_v, Reg.MIN_VOLTAGE_LIMIT: min_v,
                Reg.VELOCITY_LIMIT: velocity_limit, Reg.SHUTDOWN: 52,
                Reg.MOVING_THRESHOLD: moving_threshold, Reg.VELOCITY_I_GAIN: vi,
                Reg.VELOCITY_P_GAIN: vp, Reg.POSITION_D_GAIN: pd, Reg.POSITION_I_GAIN: pi,
                Reg.POSITION_P_GAIN: pp}
    unit: float
    modes: tuple[int, ...]
    if current_limit is None:
        # Present Load (126) in 0.1 % of the stall current: the unit that makes it so
        unit, modes = amps, (1, 3, 4, 16)  # 0.1 % of the stall current, in mA
    else:
        defaults[Reg.CURRENT_LIMIT] = current_limit
        unit, modes = 2.69, (0, 1, 3, 4, 5, 16)
    return ModelInfo(name, number, 46, torque, amps, rpm, unit, 120, _table(ranges, drop),
                     defaults, modes, _EMANUAL.format(page or name.lower()))


# Control tables and datasheet figures from each model's e-manual page (ModelInfo.emanual);
# stall torque, stall current and no-load speed at the recommended voltage.
MODELS: dict[str, ModelInfo] = {m.name: m for m in (
    _x330("XL330-M288", 1200, torque=0.52, amps=1.47, rpm=103.0, volts_dv=50,
          voltage=(70, 35, 31, 70), current_limit=1750, velocity_limit=445, pwm_slope=140,
          shutdown=53, gains=(1600, 180, 0, 0, 400)),
    _x330("XL330-M077", 1190, torque=0.215, amps=1.47, rpm=383.0, volts_dv=50,
          voltage=(70, 35, 31, 70), current_limit=1750, velocity_limit=1620, pwm_slope=140,
          shutdown=53, gains=(400, 40, 0, 400, 400)),
    _x330("XC330-M288", 1240, torque=0.93, amps=1.80, rpm=81.0, volts_dv=50,
          voltage=(70, 35, 31, 70), current_limit=2352, velocity_limit=350, pwm_slope=140,
          shutdown=52, gains=(1600, 50, 500, 0, 1100)),
    _x330("XC330-T288", 1220, torque=0.92, amps=0.80, rpm=65.0, volts_dv=111,
          voltage=(140, 55, 55, 140), current_limit=910, velocity_limit=320, pwm_slope=255,
          shutdown=52, gains=(1200, 40, 0, 0, 900)),
    _x430("XM430-W350", 1020, torque=4.1, amps=2.3, rpm=46.0, voltage=(160, 95, 95, 160),
          current_limit=1193, velocity_limit=350, moving_threshold=10,
          gains=(1920, 100, 0, 0, 800)),
    _x430("XC430-W150", 1070, torque=1.6, amps=1.4, rpm=106.0, voltage=(160, 60, 60, 160),
          current_limit=None, velocity_limit=460, moving_threshold=20,
          gains=(1920, 100, 0, 0, 460)),
    # ORCA's wrist (orca_core knows it as 1080, "XC430-T240BB-T"): the XC430-W240's
    # motor and table with ball bearings; the e-manual page is xc430-t240bb
    _x430("XC430-T240BB", 1080, torque=1.9, amps=1.4, rpm=70.0, voltage=(160, 60, 60, 160),
          current_limit=None, velocity_limit=306, moving_threshold=10,
          gains=(1920, 100, 0, 0, 700), page="xc430-t240bb"),
)}
MODEL_BY_NUMBER: dict[int, ModelInfo] = {m.model_number: m for m in MODELS.values()}

# Baud Rate (8) index -> bits per second.
BAUD_BY_INDEX: dict[int, int] = {
    0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000,
    7: 4_500_000,  # X430 only
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
