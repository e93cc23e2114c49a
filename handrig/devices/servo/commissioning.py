"""Commissioning: what ``connect()`` checks and sets on every servo before any cycle.

Pings each configured servo and checks its model; sets Status Return Level 2,
then, with torque off, the rig file's ``[servo_settings]`` for that servo
(:func:`handrig.devices.servo.models.servo_settings_for`): Return Delay Time,
Operating Mode and Current Limit (EEPROM), then Goal Current and Position P/D
Gain, each only when the rig sets it. Every value is read first, written when it
differs, and read back: a servo that keeps another value is a DeviceError naming
the servo, the register, the value wanted and the value read. Then clears the Bus
Watchdog and handles a pending hardware error; checks or sets the USB latency
timer; probes Fast Sync Read. Each finding is one line in ``notes``.
"""

from __future__ import annotations

from collections.abc import Callable

from handrig.clock import Clock
from handrig.config.rig import RigConfig
from handrig.devices.servo.bus import ServoState
from handrig.devices.servo.codec import INST_PING, INST_WRITE, build_instruction, u16
from handrig.devices.servo.fast_read import FastSyncRead
from handrig.devices.servo.faults import FaultHandler
from handrig.devices.servo.link import COMMAND_ATTEMPTS, COMMAND_TIMEOUT_S, Link
from handrig.devices.servo.models import (
    MODEL_NAMES,
    RETURN_DELAY_UNIT_US,
    current_limit_units,
    servo_model,
    servo_settings_for,
)
from handrig.devices.servo.readings import ReadPlan
from handrig.devices.servo.registers import (
    OPERATING_MODE_CURRENT_BASED_POSITION,
    OPERATING_MODE_EXTENDED_POSITION,
    OPERATING_MODE_POSITION,
    STATUS_RETURN_ALL,
    Reg,
)
from handrig.devices.servo.roster import Roster
from handrig.errors import DeviceError, DeviceTimeoutError

MODE_NAMES: dict[int, str] = {
    OPERATING_MODE_POSITION: "position control mode",
    OPERATING_MODE_EXTENDED_POSITION: "extended position control mode",
    OPERATING_MODE_CURRENT_BASED_POSITION: "current-based position control mode",
}


def servo_settings(rig: RigConfig, index: int) -> tuple[tuple[Reg, int, str], ...]:
    """What commissioning writes to the servo at rig index ``index``, in order:
    ``(register, value, why)``; EEPROM items first (written with torque off)."""
    servo = rig.servos[index]
    s = servo_settings_for(rig, servo.id)
    delay = s.return_delay_us // RETURN_DELAY_UNIT_US
    out: list[tuple[Reg, int, str]] = [
        (Reg.RETURN_DELAY_TIME, delay, f"return delay {s.return_delay_us} us"),
        (Reg.OPERATING_MODE, s.operating_mode,
         MODE_NAMES.get(s.operating_mode, f"mode {s.operating_mode}")),
    ]
    current = current_limit_units(s.current_limit_ma, servo_model(servo))
    if current is not None:
        out.append((Reg.CURRENT_LIMIT, current, f"current limit {s.current_limit_ma} mA"))
        out.append((Reg.GOAL_CURRENT, current, f"goal current {s.current_limit_ma} mA"))
    if s.position_p_gain is not None:
        out.append((Reg.POSITION_P_GAIN, s.position_p_gain, "the rig's position P gain"))
    if s.position_d_gain is not None:
        out.append((Reg.POSITION_D_GAIN, s.position_d_gain, "the rig's position D gain"))
    return tuple(out)


class Commissioner:
    """Commissioning of the servos of ``roster``; ``read_every_servo(purpose)`` is the
    bus's read until every servo has answered."""

    def __init__(
        self, roster: Roster, link: Link, plan: ReadPlan, fast: FastSyncRead,
        faults: FaultHandler, clock: Clock, notes: list[str],
        read_every_servo: Callable[[str], ServoState], missing_ok: bool = False,
    ) -> None:
        self.roster = roster
        self.link = link
        self.plan = plan
        self.fast = fast
        self.faults = faults
        self.clock = clock
        self.notes = notes
        self.read_every_servo = read_every_servo
        self.missing_ok = bool(missing_ok)  # [silence] action "continue": start without them
        self.models: dict[int, int] = {}
        self.firmware: dict[int, int] = {}

    def run(self) -> None:
        """Commission every servo; DeviceError listing every servo missing or wrong."""
        self.notes.clear()
        self.notes.append(self.link.transport.latency_timer().note)
        # traffic of an earlier session (replies still queued) must not pass for answers
        self.link.transport.wait_quiet(0.02, 0.5)
        self.check_servos()
        for i in range(self.roster.n):
            if not self.roster.absent[i]:
                self.configure(i)
        self.notes.append(self.settings_note())
        if not self.roster.absent.any():  # else the reader asks the absent ones last
            self.probe_fast_sync_read()
        self.read_every_servo("finish commissioning")

    # ------------------------------------------------------------------ who is there
    def check_servos(self) -> None:
        """Ping every servo and check its model."""
        r = self.roster
        problems: list[str] = []
        missing = 0
        absent: list[int] = []
        r.absent[:] = False
        for i, sid in enumerate(r.ids):
            status = self.link.transact(build_instruction(sid, INST_PING), sid, n_params=3)
            if status is None or len(status.params) < 3:
                missing += 1
                absent.append(i)
                problems.append(f"{r.describe(i)} did not answer {r.where()}: check power and ID")
                continue
            model = status.params[0] | status.params[1] << 8
            self.models[sid] = model
            self.firmware[sid] = status.params[2]
            want = r.expected_models[i]
            if model != want:
                problems.append(
                    f"{r.describe(i)} is model {model} ({MODEL_NAMES.get(model, 'unknown')}), "
                    f"the rig says {servo_model(r.rig.servos[i])} ({want}): fix config/rig.toml "
                    "or the servo")
        if problems and self.missing_ok and len(problems) == missing < r.n:
            r.absent[absent] = True
            who = ", ".join(r.describe(i) for i in absent)
            self.notes.append(
                f"{who} did not answer at start-up {r.where()}: the run goes on without "
                f"{'it' if missing == 1 else 'them'} ([silence] action continue); no goal "
                "and no torque go to a servo left out, for the whole run")
            self.notes.append(f"{r.n - missing} servos answered {r.where()} with the "
                              "expected models")
            return
        if problems:
            policy = ([] if not missing or missing == r.n else
                      ["[silence] action is not continue: the run does not start without "
                       "a servo (set action = \"continue\" to start without it)"])
            raise DeviceError("; ".join(problems + self._hints(missing) + policy))
        self.notes.append(f"{r.n} servos answered {r.where()} with the expected models")

    def _hints(self, missing: int) -> list[str]:
        """What a broadcast ping says about servos that did not answer their own pings."""
        r = self.roster
        if missing == r.n:
            return [f"no configured servo answered: check the power supply, the adapter and "
                    f"that the servos are set to {r.baud} baud (register 8)"]
        if not missing:
            return []
        found = sorted(self.link.broadcast_ping())
        hints = [f"IDs answering a broadcast ping {r.where()}: {found or 'none'}"]
        flaky = [sid for sid in r.ids if sid in found and sid not in self.models]
        if flaky:
            hints.append(
                f"servo(s) {flaky} answered the broadcast ping but not {COMMAND_ATTEMPTS} "
                "pings of their own: the bus is unreliable (cable, termination, power, or a "
                "baud rate the adapter barely holds)")
        return hints

    # ------------------------------------------------------------------ settings
    def configure(self, index: int) -> None:
        """Status Return Level, torque off, the settings, watchdog 0, hardware errors."""
        link = self.link
        self.ensure_status_return_level(index)
        link.write_register(index, Reg.TORQUE_ENABLE, 0)
        for reg, want, why in servo_settings(self.roster.rig, index):
            value = link.read_register(index, reg)
            if value == want:
                continue
            link.write_register(index, reg, want)
            now = link.read_register(index, reg)
            if now != want:
                raise DeviceError(
                    f"{self.roster.describe(index)} {self.roster.where()}: {reg.name} "
                    f"(address {reg.address}) reads {now} after writing {want} ({why}): "
                    "check the value against the servo model's range and the rig's "
                    "[servo_settings], or set it with DYNAMIXEL Wizard")
            self.notes.append(
                f"{self.roster.describe(index)}: {reg.name} {value} -> {want} ({why})")
        link.write_register(index, Reg.BUS_WATCHDOG, 0)
        hw = link.read_register(index, Reg.HARDWARE_ERROR_STATUS)
        if hw:
            self.faults.hardware_error(index, hw)

    def settings_note(self) -> str:
        """The one line saying what every servo was set to."""
        rig = self.roster.rig
        first = servo_settings_for(rig, rig.servos[0].id) if rig.servos else None
        mode = (MODE_NAMES.get(first.operating_mode, "position control mode")
                .replace(" control", "") if first else "")
        delay = first.return_delay_us if first else 0
        extra = ""
        st = rig.servo_settings
        if any(v is not None for v in (st.current_limit_ma, st.position_p_gain,
                                       st.position_d_gain)) or st.groups:
            extra = ", current limit and P/D gains of [servo_settings] checked"
        return f"return delay {delay}, {mode}, status level 2, watchdog cleared{extra}: done"

    def ensure_status_return_level(self, index: int) -> None:
        """Status Return Level 2 (a status for every instruction), which the driver needs.

        At level 1 a write gets no reply and at level 0 neither does a read, so the
        item is written without waiting for a reply, then read back.
        """
        reg = Reg.STATUS_RETURN_LEVEL
        r = self.roster
        level = self._try_read(index, reg)
        if level == STATUS_RETURN_ALL:
            return
        self.link.send(build_instruction(
            r.ids[index], INST_WRITE, u16(reg.address) + reg.encode(STATUS_RETURN_ALL)))
        self.clock.sleep(COMMAND_TIMEOUT_S / 5)
        self.link.transport.discard_input()
        now = self._try_read(index, reg)
        if now != STATUS_RETURN_ALL:
            raise DeviceError(
                f"{r.describe(index)} answers ping but keeps Status Return Level {now} "
                f"{r.where()}: set it to 2 (e.g. with DYNAMIXEL Wizard)")
        was = "0 (reads unanswered)" if level is None else str(level)
        self.notes.append(f"{r.describe(index)}: STATUS_RETURN_LEVEL {was} -> 2 (status for "
                          "every instruction)")

    def _try_read(self, index: int, reg: Reg) -> int | None:
        try:
            return self.link.read_register(index, reg)
        except DeviceTimeoutError:
            return None  # level 0: only pings are answered

    def probe_fast_sync_read(self) -> None:
        """Fall back to Sync Read when no Fast Sync Read of every servo gets a valid reply."""
        rig_order = self.fast.orders[0]
        if not any(self.fast.read(rig_order.indices, self.clock.now() + COMMAND_TIMEOUT_S,
                                  rig_order) for _ in range(COMMAND_ATTEMPTS)):
            self.plan.fall_back(
                f"no valid Fast Sync Read reply in {COMMAND_ATTEMPTS} attempts at connect")
        self.notes.append(
            "present state by " + ("Fast Sync Read" if self.plan.fast else "Sync Read"))
