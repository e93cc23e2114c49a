"""One emulated X-series Dynamixel servo: control-table memory and instruction semantics.

The servo knows nothing about bytes on a wire or time on a bus (that is
:mod:`sim.dxl_bus`); it answers ``ping``/``read``/``write``/... with the ERR
byte a real servo would put in its status packet, and the data.

Rules modelled (ROBOTIS e-manual, X-series control table and protocol 2.0):

- EEPROM items (address < 64) are writable only with torque off (else Access Error).
- Read-only items refuse writes (Access Error); a write that cuts an item
  is a Data Length Error; an undefined address is an Access Error.
- A value outside an item's range is a Data Range Error; a Goal Position outside
  the position limits (position mode) or a Goal Current above the Current
  Limit is a Data Limit Error.
- A hardware error (e.g. overload) turns torque off, keeps it off, sets the
  Alert bit (0x80) in every status, and only a reboot clears it.
- Bus Watchdog: with torque on and the watchdog armed, silence for longer than
  the watchdog stops the servo, sets Bus Watchdog to -1 and refuses goal
  writes with a Data Range Error until 0 is written to it.
- Present Position = direction * motor position + Homing Offset (Drive Mode bit 0
  reverses direction); the motor position is what moves the joint.
- Current-based position control (Operating Mode 5): the position controller's
  output current is capped by Goal Current, which cannot exceed Current Limit
  (e-manual, Current Limit(38) and Goal Current(102));
  :meth:`EmulatedServo.current_cap_ma` is that cap, which the physics applies
  (:mod:`sim.puppet`). Goal Current starts at Current Limit after power-on or a
  reboot: an assumption of this emulator (the e-manual gives no initial value), so
  a servo put in mode 5 without a Goal Current write still has its full torque.
- Goal PWM (100) caps the motor's PWM (e-manual, Goal PWM), from PWM Limit after a
  reboot (assumed, as Goal Current): :meth:`EmulatedServo.effort_fraction`, for the physics.

Without a physics model attached (see :mod:`sim.puppet`), :meth:`advance` moves
the motor toward the goal at the Velocity Limit (or Profile Velocity) so the
servo still moves.
"""

from __future__ import annotations

import math
import struct

from firmware_protocol.dynamixel import (
    BAUD_BY_INDEX,
    BUS_WATCHDOG_UNIT_S,
    CONTROL_TABLE_BYTES,
    ERROR_ALERT,
    INDEX_BY_BAUD,
    MODELS,
    RETURN_DELAY_UNIT_S,
    TICKS_PER_TURN,
    VELOCITY_UNIT_RPM,
    X_SERIES_TABLE,
    Access,
    Area,
    ErrorCode,
    HardwareError,
    Item,
    ModelInfo,
    Reg,
)
from sim.dxl_profile import (
    IN_POSITION,
    PROFILE_NONE,
    PROFILE_ONGOING,
    VELOCITY_UNIT_TICKS_S,
    profile_limits,
    profile_step,
    profile_type,
)
from sim.dxl_thermal import AMBIENT_TEMPERATURE_C, THERMAL

# Addresses above the modelled table up to the end of the XL330 table (661) read as 0.
READABLE_BYTES = 662
# Time a servo is silent after REBOOT or FACTORY RESET. An assumption of this
# emulator, not a datasheet figure.
REBOOT_S = 0.1
POSITION_MODES = (3, 4, 5)
CURRENT_MODE = 0
CURRENT_BASED_POSITION_MODE = 5
# Present Current (126, int16), Present Velocity (128, int32), Present Position (132, int32).
_PRESENT = struct.Struct("<hii")
_I16, _U16, _I32, _U32 = (struct.Struct(f) for f in ("<h", "<H", "<i", "<I"))
_GOAL_MIN, _GOAL_MAX = -1_048_575, 1_048_575  # Goal Position's range (e-manual, every model)
_PRESENT_INPUTS = (Reg.HOMING_OFFSET, Reg.DRIVE_MODE, Reg.GOAL_POSITION, Reg.TORQUE_ENABLE,
                   Reg.MOVING_THRESHOLD, Reg.PWM_LIMIT, Reg.OPERATING_MODE)
def _defaults(info: ModelInfo, servo_id: int, baud: int) -> dict[Reg, int]:
    """Initial values: the model's e-manual table, this servo's ID and baud, and the
    supply at the model's recommended voltage."""
    return {
        **info.defaults,
        Reg.FIRMWARE_VERSION: info.firmware_version,
        Reg.ID: servo_id,
        Reg.BAUD_RATE: INDEX_BY_BAUD[baud],
        Reg.PRESENT_INPUT_VOLTAGE: info.nominal_voltage_dv,
        Reg.PRESENT_TEMPERATURE: AMBIENT_TEMPERATURE_C,
    }


PWM_FULL = 885  # Goal/Present PWM at 100 % (0.113 % per unit)


class EmulatedServo:
    """An X-series servo's control table and instruction semantics.

    ``baud`` sets the Baud Rate item (the emulated bus does not enforce it).
    ``motor_ticks`` is the physical motor position (before Homing Offset and
    Drive Mode), initially ``start_ticks``.
    """

    def __init__(
        self,
        servo_id: int = 1,
        model: str = "XL330-M288",
        *,
        baud: int = 1_000_000,
        start_ticks: float = 2048.0,
    ) -> None:
        if model not in MODELS:
            raise ValueError(f"unknown servo model {model!r}; known: {', '.join(MODELS)}")
        if not 0 <= servo_id <= 252:
            raise ValueError(f"servo ID {servo_id} out of range 0..252")
        if baud not in INDEX_BY_BAUD:
            raise ValueError(f"servo {servo_id}: {baud} baud is not an X-series rate; "
                             f"known: {', '.join(str(b) for b in INDEX_BY_BAUD)}")
        self.info = MODELS[model]
        self.thermal = THERMAL[model]
        self._item_at = self.info.item_at()
        self.mem = bytearray(READABLE_BYTES)
        # the profile generator's output, in Present Position units and units/s
        self.trajectory_ticks = float(start_ticks)
        self.trajectory_velocity = 0.0
        self._profile_goal: int | None = None
        self._profile_type = PROFILE_NONE
        self.motor_ticks = float(start_ticks)
        self.motor_velocity_rpm = 0.0
        self.motor_current_ma = 0.0
        self.silent_until = 0.0
        self.last_heard = 0.0
        self.tick_ms = 0.0
        self.temperature_c = float(AMBIENT_TEMPERATURE_C)
        self.injected_hardware_error = 0
        self._baud = baud
        self._registered: tuple[int, bytes] | None = None
        self._set_all(_defaults(self.info, servo_id, baud))
        self._reset_ram()
        self.counters = {"writes": 0, "reads": 0, "errors": 0, "reboots": 0}

    # ------------------------------------------------------------------ registers

    def get(self, reg: Reg) -> int:
        """The value of one control-table item."""
        item = X_SERIES_TABLE[reg]
        return item.decode(self.mem[item.address : item.address + item.size])

    def set(self, reg: Reg, value: int) -> None:
        """Set an item directly (no access checks: the emulator's own hand)."""
        item = X_SERIES_TABLE[reg]
        self.mem[item.address : item.address + item.size] = item.encode(value)

    def _set_all(self, values: dict[Reg, int]) -> None:
        for reg, value in values.items():
            self.set(reg, value)

    def _reset_ram(self) -> None:
        """RAM as after power-on: defaults, torque off, goal = present position."""
        defaults = _defaults(self.info, self.id, self._baud)
        self.mem[64:CONTROL_TABLE_BYTES] = bytes(CONTROL_TABLE_BYTES - 64)
        for reg, value in defaults.items():
            if X_SERIES_TABLE[reg].area is Area.RAM:
                self.set(reg, value)
        self._registered = None
        self._publish_present()
        self.set(Reg.GOAL_POSITION, self.get(Reg.PRESENT_POSITION))
        self.trajectory_ticks = float(self.present)
        self.trajectory_velocity = 0.0
        self._profile_goal = None
        self._profile_type = PROFILE_NONE
        self._publish_trajectory()
        if self.info.has_current:
            self.set(Reg.GOAL_CURRENT, self.get(Reg.CURRENT_LIMIT))
        # Goal PWM starts at PWM Limit (the same assumption as Goal Current: full effort)
        self.set(Reg.GOAL_PWM, self.get(Reg.PWM_LIMIT))

    @property
    def id(self) -> int:
        return self.mem[7]

    @property
    def baud(self) -> int:
        """The rate the servo listens and answers at (its Baud Rate item), bits/s."""
        return BAUD_BY_INDEX[self.mem[8]]

    @property
    def torque_enabled(self) -> bool:
        return self.mem[64] == 1

    @property
    def goal(self) -> int:
        """Goal Position register, ticks."""
        return self.get(Reg.GOAL_POSITION)

    @property
    def present(self) -> int:
        """Present Position register, ticks."""
        return self.get(Reg.PRESENT_POSITION)

    @property
    def hardware_error(self) -> int:
        """Hardware Error Status bits (see :class:`HardwareError`)."""
        return self.mem[70]

    @property
    def status_return_level(self) -> int:
        return self.mem[68]

    @property
    def return_delay_s(self) -> float:
        return self.mem[9] * RETURN_DELAY_UNIT_S

    @property
    def direction(self) -> int:
        return -1 if self.mem[10] & 1 else 1

    @property
    def operating_mode(self) -> int:
        """Operating Mode (11): 3 position, 4 extended position, 5 current-based position."""
        return self.mem[11]

    def current_cap_ma(self) -> float | None:
        """The motor current the controller may use, mA: in current-based position
        (and current) mode min(|Goal Current|, Current Limit); ``None`` in the other
        modes, where only the motor's stall current bounds it."""
        if self.mem[11] not in (CURRENT_MODE, CURRENT_BASED_POSITION_MODE) \
                or not self.info.has_current:
            return None
        units = min(abs(self.get(Reg.GOAL_CURRENT)), self.get(Reg.CURRENT_LIMIT))
        return units * self.info.current_unit_ma

    def effort_fraction(self) -> float:
        """The motor's share of full effort: min(PWM Limit, |Goal PWM|) / 100 % PWM."""
        pwm = min(self.get(Reg.PWM_LIMIT), abs(self.get(Reg.GOAL_PWM)))
        return pwm / PWM_FULL

    def error_byte(self, code: int = 0) -> int:
        """ERR byte of a status: ``code`` plus the Alert bit while a hardware error stands."""
        return code | (ERROR_ALERT if self.mem[70] else 0)

    # ---------------------------------------------------------- motion interface

    def goal_motor_ticks(self) -> float:
        """The goal as a motor position (undoing Homing Offset and Drive Mode)."""
        mem = self.mem
        goal = int.from_bytes(mem[116:120], "little", signed=True)
        homing = int.from_bytes(mem[20:24], "little", signed=True)
        return (homing - goal) if mem[10] & 1 else (goal - homing)

    def trajectory_motor_ticks(self) -> float:
        """The profile generator's position (Position Trajectory) as a motor position:
        the goal itself while Profile Velocity is 0."""
        mem = self.mem
        if mem[112:116] == b"\0\0\0\0":
            return self.goal_motor_ticks()
        homing = int.from_bytes(mem[20:24], "little", signed=True)
        t = self.trajectory_ticks
        return (homing - t) if mem[10] & 1 else (t - homing)

    def set_motion(self, motor_ticks: float, velocity_rpm: float, current_ma: float) -> None:
        """Physics writes the motor's state; Present Position/Velocity/Current follow."""
        self.motor_ticks = motor_ticks
        self.motor_velocity_rpm = velocity_rpm
        self.motor_current_ma = current_ma
        self._publish_present()

    def _publish_present(self) -> None:
        mem = self.mem
        d = -1 if mem[10] & 1 else 1
        position = round(d * self.motor_ticks) + int.from_bytes(mem[20:24], "little", signed=True)
        velocity = round(d * self.motor_velocity_rpm / VELOCITY_UNIT_RPM)
        current = round(d * self.motor_current_ma / self.info.current_unit_ma)
        current = max(-32768, min(32767, current))
        _PRESENT.pack_into(mem, 126, current, velocity, position)
        threshold = _U32.unpack_from(mem, 24)[0]
        mem[122] = 1 if abs(velocity) > threshold else 0
        _I16.pack_into(mem, 124, self._present_pwm())
        self._publish_moving_status(position, threshold)

    def _present_pwm(self) -> int:
        """Present PWM (124): the share of the supply the motor needs for its speed
        (back EMF) and current (winding), each against the datasheet's no-load speed
        and stall current, capped by PWM Limit; 0 with torque off."""
        if not self.mem[64]:
            return 0
        info = self.info
        duty = (self.motor_velocity_rpm / info.no_load_speed_rpm
                + self.motor_current_ma / (info.stall_current_a * 1000.0))
        limit = _U16.unpack_from(self.mem, 36)[0]
        pwm = round((-duty if self.mem[10] & 1 else duty) * PWM_FULL)
        return max(-limit, min(limit, pwm))

    def _publish_moving_status(self, position: int, threshold: int) -> None:
        """Moving Status (123): profile type and Profile Ongoing while the profile runs;
        In-Position in a position mode once the profile is done and Present Position is
        within Moving Threshold of Goal Position (this emulator reads the threshold in
        pulses for it: the e-manual names no other window)."""
        mem = self.mem
        goal = _I32.unpack_from(mem, 116)[0]
        status = self._profile_type
        ongoing = mem[112:116] != b"\0\0\0\0" and self.trajectory_ticks != goal
        if ongoing and mem[64]:
            status |= PROFILE_ONGOING
        elif mem[64] and mem[11] in POSITION_MODES and abs(goal - position) <= threshold:
            status |= IN_POSITION
        mem[123] = status

    def _publish_trajectory(self) -> None:
        mem = self.mem
        mem[136:140] = round(self.trajectory_velocity / VELOCITY_UNIT_TICKS_S).to_bytes(
            4, "little", signed=True)
        mem[140:144] = round(self.trajectory_ticks).to_bytes(4, "little", signed=True)

    def step_profile(self, dt_s: float) -> None:
        """Advance the profile generator by ``dt_s`` (e-manual, Profile Velocity(112) and
        Profile Acceleration(108), velocity-based): no profile while Profile Velocity is
        0 (the trajectory is the goal); a rectangular one at Profile Velocity when
        Profile Acceleration is 0; else trapezoidal, or triangular when the move is too
        short to reach Profile Velocity. Velocity Limit caps Profile Velocity."""
        mem = self.mem
        goal = int.from_bytes(mem[116:120], "little", signed=True)
        profile = int.from_bytes(mem[112:116], "little")
        if not mem[64] or mem[11] not in POSITION_MODES:
            self.trajectory_ticks = float(self.present if not mem[64] else goal)
            self.trajectory_velocity = 0.0
            self._profile_goal = goal
            self._profile_type = PROFILE_NONE
        elif not profile:
            self.trajectory_ticks, self.trajectory_velocity = float(goal), 0.0
            self._profile_goal, self._profile_type = goal, PROFILE_NONE
        else:
            self._profile_toward(goal, profile, dt_s)
        self._publish_trajectory()

    def _profile_toward(self, goal: int, profile: int, dt_s: float) -> None:
        mem = self.mem
        v_max, accel = profile_limits(profile, int.from_bytes(mem[44:48], "little"),
                                      int.from_bytes(mem[108:112], "little"))
        if goal != self._profile_goal:
            self._profile_goal = goal
            self._profile_type = profile_type(goal - self.trajectory_ticks, v_max, accel)
        self.trajectory_ticks, self.trajectory_velocity = profile_step(
            self.trajectory_ticks, self.trajectory_velocity, goal, v_max, accel, dt_s)

    def heat(self, dt_s: float) -> None:
        """Warm the servo by I^2 R at the present current plus its standby draw, and cool
        it toward ambient (first order with the model's :data:`THERMAL` figures); above
        the Temperature Limit it reports overheating (torque off)."""
        if dt_s <= 0:
            return
        self.temperature_c = self.thermal.temperature_after(
            self.temperature_c, self.mem[144] / 10.0, self.motor_current_ma,
            self.info.stall_current_a, dt_s)
        self.mem[146] = max(0, min(255, round(self.temperature_c)))
        if self.mem[146] > self.mem[31] and not self.mem[70] & HardwareError.OVERHEATING:
            self.inject_hardware_error(HardwareError.OVERHEATING)

    def warm_to(self, temp_c: float) -> None:
        """Set the internal temperature (warm from earlier use); heat goes on from there."""
        self.temperature_c = float(temp_c)
        self.mem[146] = max(0, min(255, round(temp_c)))

    def speed_limit_ticks_per_s(self) -> float:
        """Motor speed limit: Profile Velocity if set, else Velocity Limit."""
        profile = int.from_bytes(self.mem[112:116], "little")
        limit = int.from_bytes(self.mem[44:48], "little")
        units = min(profile, limit) if profile else limit
        return units * VELOCITY_UNIT_RPM * TICKS_PER_TURN / 60.0

    def tick(self, dt_s: float) -> None:
        """The servo's own clock: Realtime Tick, the profile generator, Moving Status."""
        mem = self.mem
        self.tick_ms = (self.tick_ms + dt_s * 1000.0) % 32768.0
        _U16.pack_into(mem, 120, int(self.tick_ms))
        if dt_s <= 0:
            return
        if mem[112:116] == b"\0\0\0\0" and self._profile_type == PROFILE_NONE \
                and (mem[64] or self._profile_goal is None):
            # no profile: the trajectory is the goal (cheap: the puppet ticks every push)
            if mem[140:144] != mem[116:120] or mem[136:140] != b"\0\0\0\0":
                mem[140:144] = mem[116:120]
                mem[136:140] = b"\0\0\0\0"
                self.trajectory_ticks = float(_I32.unpack_from(mem, 116)[0])
                self.trajectory_velocity = 0.0
            return
        self.step_profile(dt_s)
        self._publish_moving_status(self.present, _U32.unpack_from(mem, 24)[0])

    def advance(self, dt_s: float) -> None:
        """Kinematic motion without physics: :meth:`tick`, then toward the goal (or the
        profile's trajectory) at the speed limit."""
        self.tick(dt_s)
        if dt_s <= 0:
            return
        self.heat(dt_s)
        if not self.torque_enabled:
            if self.motor_velocity_rpm or self.motor_current_ma:
                self.set_motion(self.motor_ticks, 0.0, 0.0)
            return
        error = self.trajectory_motor_ticks() - self.motor_ticks
        step = self.speed_limit_ticks_per_s() * dt_s
        moved = math.copysign(min(abs(error), step), error)
        rpm = moved / dt_s * 60.0 / TICKS_PER_TURN
        self.set_motion(self.motor_ticks + moved, rpm, 0.0)

    # ------------------------------------------------------------------ faults

    def set_supply_voltage(self, volts: float) -> None:
        """The supply the servo sees: Present Input Voltage (144) follows it; outside
        Min/Max Voltage Limit (34, 32) the servo reports an input voltage error
        (Hardware Error Status bit 0; torque off if Shutdown (63) has bit 0)."""
        dv = max(0, min(65535, round(volts * 10)))
        self.set(Reg.PRESENT_INPUT_VOLTAGE, dv)
        if not self.get(Reg.MIN_VOLTAGE_LIMIT) <= dv <= self.get(Reg.MAX_VOLTAGE_LIMIT):
            self.inject_hardware_error(HardwareError.INPUT_VOLTAGE)

    def inject_hardware_error(
        self, bits: int = HardwareError.OVERLOAD, *, persistent: bool = False
    ) -> None:
        """A hardware error (overload by default): Hardware Error Status bit and the
        Alert bit set, torque off when Shutdown (63) has the bit, until a reboot clears
        it. ``persistent``: the cause stays, so it comes back after every reboot until
        :meth:`clear_injected_fault`."""
        if persistent:
            self.injected_hardware_error |= int(bits)
        self.mem[70] |= int(bits)
        if self.mem[63] & int(bits):  # Shutdown (63) picks the errors that stop the motor
            self.mem[64] = 0

    def clear_injected_fault(self) -> None:
        """Remove the cause of a persistent injected fault (the status stays until a reboot)."""
        self.injected_hardware_error = 0

    def check_watchdog(self, now: float) -> bool:
        """Trip the Bus Watchdog if the bus has been quiet too long; True when it tripped."""
        wd = self.mem[98]
        if wd == 0 or wd == 0xFF or not self.torque_enabled:
            return False
        if now - self.last_heard > wd * BUS_WATCHDOG_UNIT_S:
            self.mem[98] = 0xFF
            # The servo stops where it is.
            self.set(Reg.GOAL_POSITION, self.present)
            return True
        return False

    # ------------------------------------------------------------ instructions

    def ping(self) -> tuple[int, bytes]:
        """ERR and the ping data: model number (LE16) and firmware version."""
        return self.error_byte(), bytes(self.mem[0:2]) + bytes(self.mem[6:7])

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """ERR and ``length`` bytes from ``address`` (no data on error)."""
        self.counters["reads"] += 1
        if length == 0 or address + length > READABLE_BYTES:
            self.counters["errors"] += 1
            return self.error_byte(ErrorCode.ACCESS), b""
        return self.error_byte(), bytes(self.mem[address : address + length])

    def check_write(self, address: int, data: bytes) -> int:
        """The error code a write would get (0 when it is accepted)."""
        end = address + len(data)
        if not data:
            return ErrorCode.DATA_LENGTH
        pos = address
        torque = self.torque_enabled
        while pos < end:
            item = self._item_at.get(pos)
            if item is None:
                inside = any(i.address < pos < i.address + i.size
                             for i in self._item_at.values())
                return ErrorCode.DATA_LENGTH if inside else ErrorCode.ACCESS
            if pos + item.size > end:
                return ErrorCode.DATA_LENGTH
            if item.access is Access.R or (item.area is Area.EEPROM and torque):
                return ErrorCode.ACCESS
            offset = pos - address
            value = item.decode(data[offset : offset + item.size])
            code = self._check_value(pos, item, value)
            if code:
                return code
            pos += item.size
        return ErrorCode.NONE

    def _check_value(self, pos: int, item: Item, value: int) -> int:
        low, high = item.min_value, item.max_value
        if low is not None and high is not None and not low <= value <= high:
            return ErrorCode.DATA_RANGE
        if pos == Reg.OPERATING_MODE and value not in self.info.operating_modes:
            return ErrorCode.DATA_RANGE
        goals = (Reg.GOAL_POSITION, Reg.GOAL_VELOCITY, Reg.GOAL_CURRENT, Reg.GOAL_PWM)
        if pos in goals and self.mem[98] == 0xFF:  # Bus Watchdog error stands
            return ErrorCode.DATA_RANGE
        if pos == Reg.GOAL_POSITION and self.mem[11] == 3:
            low = self.get(Reg.MIN_POSITION_LIMIT)
            high = self.get(Reg.MAX_POSITION_LIMIT)
            if not low <= value <= high:
                return ErrorCode.DATA_LIMIT
        if pos == Reg.GOAL_CURRENT and abs(value) > self.get(Reg.CURRENT_LIMIT):
            return ErrorCode.DATA_LIMIT
        if pos == Reg.GOAL_PWM and abs(value) > self.get(Reg.PWM_LIMIT):
            return ErrorCode.DATA_LIMIT
        if pos == Reg.GOAL_VELOCITY and abs(value) > self.get(Reg.VELOCITY_LIMIT):
            return ErrorCode.DATA_LIMIT
        return ErrorCode.NONE

    def write(self, address: int, data: bytes) -> int:
        """Write ``data`` at ``address``; returns the ERR byte (0 or an error, plus Alert)."""
        self.counters["writes"] += 1
        mem = self.mem
        # Hot path: Goal Position in a position mode, torque on or off (as the general path)
        if address == 116 and len(data) == 4 and mem[98] != 0xFF and mem[11] in POSITION_MODES:
            value = _I32.unpack(data)[0]
            if (_GOAL_MIN <= value <= _GOAL_MAX) if mem[11] != 3 else \
                    _I32.unpack_from(mem, 52)[0] <= value <= _I32.unpack_from(mem, 48)[0]:
                mem[116:120] = data  # present state is current (see below): Moving Status only
                self._publish_moving_status(_I32.unpack_from(mem, 132)[0],
                                            _U32.unpack_from(mem, 24)[0])
                return ERROR_ALERT if mem[70] else 0
            if mem[11] == 3:  # outside the position limits (mode 4/5: the general path)
                self.counters["errors"] += 1
                return self.error_byte(ErrorCode.DATA_LIMIT)
        code = self.check_write(address, data)
        if code:
            self.counters["errors"] += 1
            return self.error_byte(code)
        end = address + len(data)
        self.mem[address:end] = data
        if address <= Reg.TORQUE_ENABLE < end and self.mem[64] and self.mem[70]:
            # A standing hardware error keeps torque off until a reboot.
            self.mem[64] = 0
        # every item present state is derived from (with the motor's state): a write to
        # one publishes it again, so present state never waits for the next motion step
        if any(address <= r < end for r in _PRESENT_INPUTS):
            self._publish_present()
        return self.error_byte()

    def reg_write(self, address: int, data: bytes) -> int:
        """Check and hold a write until ACTION (Registered Instruction = 1)."""
        code = self.check_write(address, data)
        if code:
            self.counters["errors"] += 1
            return self.error_byte(code)
        self._registered = (address, bytes(data))
        self.mem[69] = 1
        return self.error_byte()

    def action(self) -> int:
        """Run the registered write; an Instruction Error when none is registered."""
        if self._registered is None:
            self.counters["errors"] += 1
            return self.error_byte(ErrorCode.INSTRUCTION)
        address, data = self._registered
        self._registered = None
        self.mem[69] = 0
        return self.write(address, data)

    def reboot(self, now: float) -> int:
        """Reboot: RAM to defaults, torque off, hardware error cleared unless its cause
        stands; silent for :data:`REBOOT_S`. Returns the ERR byte of the status sent first."""
        err = self.error_byte()
        self.counters["reboots"] += 1
        self._reset_ram()
        self.mem[70] = self.injected_hardware_error & 0xFF
        self.silent_until = now + REBOOT_S
        return err

    def factory_reset(self, option: int, now: float) -> int:
        """FACTORY RESET: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate."""
        if option not in (0xFF, 0x01, 0x02):
            self.counters["errors"] += 1
            return self.error_byte(ErrorCode.DATA_RANGE)
        err = self.error_byte()
        keep_id = self.id if option in (0x01, 0x02) else 1
        keep_baud = self.mem[8] if option == 0x02 else 1
        self.mem[0:64] = bytes(64)
        self._set_all({r: v for r, v in _defaults(self.info, keep_id, self._baud).items()
                       if X_SERIES_TABLE[r].area is Area.EEPROM})
        self.mem[8] = keep_baud
        self._reset_ram()
        self.mem[70] = self.injected_hardware_error & 0xFF
        self.silent_until = now + REBOOT_S
        return err

    def available(self, now: float) -> bool:
        """False while rebooting."""
        return now >= self.silent_until

    def __repr__(self) -> str:
        return (f"EmulatedServo(id={self.id}, {self.info.name}, torque={int(self.torque_enabled)}, "
                f"goal={self.goal}, present={self.present}, hw_error={self.hardware_error:#04x})")

