"""Servo bring-up of Dynamixel X-series servos through the official ``dynamixel_sdk``:
find servos, set IDs and bauds, reboot, and compare a bus with a rig file; beside the
functions, :class:`DynamixelBringup`, the :class:`~handrig.devices.servo.bringup.BusBringup`
the commands talk to (opened by :func:`handrig.app.factory.servo_bringup`).

These are the steps between unpacking servos and a first run (``handrig servos``):
new X-series servos all answer as ID 1 at 57600 bps (e-manual, Baud Rate (8)
default 1); a rig wants distinct IDs at one fast baud. Everything here talks
Protocol 2.0 with the SDK's ``PortHandler`` and ``PacketHandler`` (no realtime path:
a broadcast ping waits the SDK's full timeout, up to 4.5 s at 9600 bps).

Facts used (ROBOTIS e-manual, X-series): ID (7) and Baud Rate (8) are EEPROM items,
written only with torque off; the input voltage range per model is
XL330-M288 and XC330-M288 3.7..6.0 V, XC330-T288 6.5..12.0 V, XM430-W350
10.0..14.8 V; Operating Mode (11) 0 current, 1 velocity, 3 position, 4 extended
position, 5 current-based position, 16 PWM.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler
from dynamixel_sdk.robotis_def import COMM_RX_CORRUPT, COMM_RX_TIMEOUT

from handrig.config.rig import RigConfig
from handrig.devices.servo.bringup import BusBringup, Finding, FoundServo, ScanResult
from handrig.devices.servo.models import BAUD_RATES, MODEL_NAMES, OPERATING_MODES, servo_model
from handrig.devices.servo.registers import Reg, describe_hardware_error
from handrig.devices.servo.transport import is_pseudo_terminal
from handrig.errors import DeviceError

PROTOCOL = 2.0
# Input voltage range per model, volts (e-manual, "Specifications").
VOLTAGE_RANGE_V: dict[str, tuple[float, float]] = {
    "XL330-M288": (3.7, 6.0),
    "XC330-M288": (3.7, 6.0),
    "XC330-T288": (6.5, 12.0),
    "XM430-W350": (10.0, 14.8),
}
OPERATING_MODE_NAMES: dict[int, str] = {
    0: "current", 1: "velocity", 3: "position", 4: "extended_position",
    5: "current_based_position", 16: "pwm",
}
BAUD_INDEX: dict[int, int] = {baud: i for i, baud in enumerate(BAUD_RATES)}
"""Baud Rate (8) value for each rate: 0 9600, 1 57600, ... 6 4 Mbps (REFERENCE.md 2)."""
EEPROM_WRITE_S = 0.05  # time given to an EEPROM write (and a status at the old ID or baud)
FACTORY_ID, FACTORY_BAUD = 1, 57600
REBOOT_WAIT_S = 0.5  # a rebooted servo is silent for a moment (ORCA measures about 0.3 s)
PING_TRIES = 3  # pings of a servo that should answer before it is taken as absent
DESCRIBE_TRIES = 3  # reads of a found servo's registers, each tried this many times
# Added to each SDK reply timeout (its own: twice a 16 ms latency timer + 2 ms) on a
# pseudo-terminal, where a program answers on the host's CPUs: on a loaded machine it
# may not run for tens of milliseconds (CI saw 3 reads in a row go unanswered in 34 ms).
PTY_PATIENCE_MS = 250.0
ONE_AT_A_TIME = (
    "two or more servos share an ID (new servos all come as ID 1 at 57600): connect one "
    "servo at a time and give each its own ID with `handrig servos set-id`"
)


def model_name(model_number: int) -> str:
    """The X-series name of ``model_number`` (``"model N"`` for one not in the table)."""
    return MODEL_NAMES.get(model_number, f"model {model_number}")


def mode_name(operating_mode: int | None) -> str:
    """Operating Mode (11) in words; "?" when it was not read."""
    if operating_mode is None:
        return "?"
    return OPERATING_MODE_NAMES.get(operating_mode, f"mode {operating_mode}")


class _PortHandler(PortHandler):
    """The SDK's port handler, whose reply timeouts get ``extra_ms`` more."""

    extra_ms = 0.0

    def setPacketTimeout(self, packet_length: int) -> None:  # the SDK's name
        super().setPacketTimeout(packet_length)
        self.packet_timeout += self.extra_ms


class ServoPort:
    """One serial port opened with the SDK; ``baud`` can change between calls. On a
    pseudo-terminal (an emulator, a bridge) each reply is waited for
    :data:`PTY_PATIENCE_MS` longer: a late reply there is the host's, not the bus's."""

    def __init__(self, port: str, baud: int = FACTORY_BAUD) -> None:
        self.port = port
        self.handler = _PortHandler(port)
        self.packet = PacketHandler(PROTOCOL)
        self.baud = 0
        self.set_baud(baud)

    def set_baud(self, baud: int) -> None:
        if baud not in BAUD_RATES:
            raise DeviceError(f"baud {baud} is not one the X series supports "
                              f"({', '.join(map(str, BAUD_RATES))})")
        if baud == self.baud:
            return
        try:
            ok = self.handler.setBaudRate(baud)
        except Exception as exc:  # pyserial raises SerialException, OSError, ValueError
            raise DeviceError(
                f"cannot open servo port {self.port}: {exc} (check the cable and the path; "
                "on Linux you need to be in the 'dialout' group, see docs/hardware.md)"
            ) from None
        if not ok:
            raise DeviceError(f"dynamixel-sdk refuses baud {baud} on {self.port}")
        self.handler.extra_ms = (PTY_PATIENCE_MS if is_pseudo_terminal(self.handler.ser.fileno())
                                 else 0.0)
        self.baud = baud

    def close(self) -> None:
        if self.handler.is_open:
            self.handler.closePort()

    def broadcast_ping(self) -> tuple[dict[int, tuple[int, int]], bool]:
        """``({id: (model number, firmware)}, collided)`` at the current baud."""
        found, result = self.packet.broadcastPing(self.handler)
        collided = result == COMM_RX_CORRUPT
        return {int(k): (int(v[0]), int(v[1])) for k, v in found.items()}, collided

    def ping(self, servo_id: int) -> int | None:
        """The model number of ``servo_id``, None if nothing answered; DeviceError when
        the reply is garbled (two servos with one ID answer together)."""
        model, result, _error = self.packet.ping(self.handler, servo_id)
        if result == COMM_SUCCESS:
            return int(model)
        if result == COMM_RX_TIMEOUT:
            return None
        if result == COMM_RX_CORRUPT:
            raise DeviceError(f"garbled reply from ID {servo_id} on {self.port} at "
                              f"{self.baud} bps: {ONE_AT_A_TIME}")
        return None

    def ping_confirmed(self, servo_id: int, tries: int = PING_TRIES) -> int | None:
        """:meth:`ping`, asked up to ``tries`` times while nothing answers (one lost or
        late reply, a loaded host or a USB adapter's latency timer, is not an absence)."""
        for _ in range(tries):
            model = self.ping(servo_id)
            if model is not None:
                return model
        return None

    def read(self, servo_id: int, reg: Reg) -> int:
        size = reg.size
        reader = {1: self.packet.read1ByteTxRx, 2: self.packet.read2ByteTxRx,
                  4: self.packet.read4ByteTxRx}[size]
        value, result, _error = reader(self.handler, servo_id, reg.address)
        if result != COMM_SUCCESS:
            raise DeviceError(f"servo {servo_id} on {self.port} at {self.baud} bps: reading "
                              f"{reg.name} failed ({self.packet.getTxRxResult(result)})")
        return reg.decode(int(value).to_bytes(size, "little", signed=False))

    def write(self, servo_id: int, reg: Reg, value: int) -> None:
        raw = int.from_bytes(reg.encode(value), "little")
        writer = {1: self.packet.write1ByteTxRx, 2: self.packet.write2ByteTxRx,
                  4: self.packet.write4ByteTxRx}[reg.size]
        result, error = writer(self.handler, servo_id, reg.address, raw)
        if result != COMM_SUCCESS:
            raise DeviceError(f"servo {servo_id} on {self.port} at {self.baud} bps: writing "
                              f"{reg.name} = {value} failed ({self.packet.getTxRxResult(result)})")
        if error:
            raise DeviceError(f"servo {servo_id} refused {reg.name} = {value}: "
                              f"{self.packet.getRxPacketError(error)}")

    def write_unconfirmed(self, servo_id: int, reg: Reg, value: int) -> None:
        """Write without waiting for the status: after an ID or baud change the reply
        comes from another ID or at another baud; the caller pings to confirm."""
        raw = int.from_bytes(reg.encode(value), "little")
        writer = {1: self.packet.write1ByteTxOnly, 2: self.packet.write2ByteTxOnly,
                  4: self.packet.write4ByteTxOnly}[reg.size]
        result = writer(self.handler, servo_id, reg.address, raw)
        if result != COMM_SUCCESS:
            raise DeviceError(f"servo {servo_id} on {self.port}: sending {reg.name} = {value} "
                              f"failed ({self.packet.getTxRxResult(result)})")
        time.sleep(EEPROM_WRITE_S)

    def reboot(self, servo_id: int) -> None:
        result, _error = self.packet.reboot(self.handler, servo_id)
        if result != COMM_SUCCESS:
            raise DeviceError(f"servo {servo_id} on {self.port} at {self.baud} bps did not "
                              f"take the reboot ({self.packet.getTxRxResult(result)})")

    def describe(self, servo_id: int, model_number: int, firmware: int) -> FoundServo:
        """A found servo with its mode, voltage, temperature and errors read. Each read is
        tried up to :data:`DESCRIBE_TRIES` times (one lost or late reply on a busy bus is
        not a finding); one that still fails leaves its field None and is named in
        ``unread``."""
        unread: list[str] = []

        def read_or_none(reg: Reg) -> int | None:
            for _ in range(DESCRIBE_TRIES):
                try:
                    return self.read(servo_id, reg)
                except DeviceError:
                    continue
            unread.append(reg.name)
            return None

        mode = read_or_none(Reg.OPERATING_MODE)
        volts = read_or_none(Reg.PRESENT_INPUT_VOLTAGE)
        temperature = read_or_none(Reg.PRESENT_TEMPERATURE)
        errors = read_or_none(Reg.HARDWARE_ERROR_STATUS)
        return FoundServo(
            servo_id, self.baud, model_number, firmware, model_name(model_number),
            operating_mode=mode, mode_name=mode_name(mode),
            voltage_v=None if volts is None else volts / 10.0,
            temperature_c=temperature,
            hardware_error=errors,
            errors_text="?" if errors is None else describe_hardware_error(errors),
            unread=tuple(unread),
        )


@contextmanager
def open_port(port: str, baud: int = FACTORY_BAUD) -> Iterator[ServoPort]:
    """A :class:`ServoPort`, closed on the way out."""
    sp = ServoPort(port, baud)
    try:
        yield sp
    finally:
        sp.close()


def scan(port: str, bauds: Sequence[int] = BAUD_RATES) -> ScanResult:
    """Broadcast-ping ``port`` at every baud in ``bauds`` and describe each servo found."""
    out = ScanResult()
    with open_port(port, bauds[0] if bauds else FACTORY_BAUD) as sp:
        for baud in bauds:
            sp.set_baud(baud)
            out.tried.append(baud)
            found, collided = sp.broadcast_ping()
            if collided:
                out.collisions.append(baud)
            for servo_id, (model, firmware) in sorted(found.items()):
                out.servos.append(sp.describe(servo_id, model, firmware))
    return out


def _eeprom_ready(sp: ServoPort, servo_id: int) -> str:
    """Torque off so EEPROM items can be written; a note when it had been on."""
    if sp.read(servo_id, Reg.TORQUE_ENABLE):
        sp.write(servo_id, Reg.TORQUE_ENABLE, 0)
        return f"servo {servo_id}: torque was on, turned it off (ID and baud need torque off)"
    return ""


def _answering(sp: ServoPort, servo_id: int, port: str, baud: int) -> int:
    """The model number of the servo answering as ``servo_id``; a DeviceError if none does."""
    model = sp.ping_confirmed(servo_id)
    if model is None:
        raise DeviceError(f"no servo answers as ID {servo_id} on {port} at {baud} bps "
                          "(`handrig servos scan` lists what is there)")
    return model


def search_order(first: Sequence[int] = ()) -> list[int]:
    """The bauds to look for a servo at: ``first`` (the rig's), the factory's 57600,
    then the fast ones, 9600 last (its broadcast ping alone waits seconds)."""
    order = [*first, FACTORY_BAUD, *sorted((b for b in BAUD_RATES if b > FACTORY_BAUD),
                                           reverse=True), *BAUD_RATES]
    return list(dict.fromkeys(b for b in order if b in BAUD_INDEX))


def find_baud(port: str, servo_id: int, bauds: Sequence[int]) -> int:
    """The baud at which a servo answers as ``servo_id``, trying ``bauds`` in order
    (:func:`search_order`); a DeviceError naming what was tried when none does, or
    when two servos answer as it (garbled) at a baud."""
    with open_port(port, bauds[0] if bauds else FACTORY_BAUD) as sp:
        for baud in bauds:
            sp.set_baud(baud)
            if sp.ping_confirmed(servo_id) is not None:
                return baud
    raise DeviceError(f"no servo answers as ID {servo_id} on {port} at any of "
                      f"{', '.join(map(str, bauds))} bps: check power and the cable "
                      "(`handrig servos scan` lists what is there)")


def set_id(port: str, baud: int, old_id: int, new_id: int) -> list[str]:
    """Give the servo answering as ``old_id`` at ``baud`` the ID ``new_id``. Refuses when
    no servo answers as ``old_id``, when ``new_id`` is taken at this baud, or when two
    servos answer as ``old_id``. Returns what was done."""
    if not 0 <= new_id <= 252:
        raise DeviceError(f"ID {new_id} is out of range: servo IDs are 0..252")
    notes: list[str] = []
    with open_port(port, baud) as sp:
        model = _answering(sp, old_id, port, baud)
        if new_id == old_id:
            return [f"servo {old_id} already has ID {new_id}: nothing to do"]
        taken = sp.ping_confirmed(new_id)
        if taken is not None:
            raise DeviceError(
                f"ID {new_id} is taken on {port} at {baud} bps (a "
                f"{MODEL_NAMES.get(taken, f'model {taken}')} answers): two servos with one ID "
                f"garble every reply. Give that one another ID first, or connect one servo "
                "at a time")
        if note := _eeprom_ready(sp, old_id):
            notes.append(note)
        sp.write_unconfirmed(old_id, Reg.ID, new_id)
        if sp.ping_confirmed(new_id) is None:
            raise DeviceError(f"wrote ID {new_id} to servo {old_id} but nothing answers as "
                              f"{new_id}: run `handrig servos scan`")
        notes.append(f"servo {old_id} ({MODEL_NAMES.get(model, model)}) is now ID {new_id} "
                     f"at {baud} bps")
    return notes


def set_baud(port: str, baud: int, servo_id: int, new_baud: int) -> list[str]:
    """Move servo ``servo_id`` from ``baud`` to ``new_baud``. Refuses when its ID is
    taken at ``new_baud`` (the two would answer together). Returns what was done."""
    if new_baud not in BAUD_INDEX:
        raise DeviceError(f"baud {new_baud} is not one the X series supports "
                          f"({', '.join(map(str, BAUD_RATES))})")
    notes: list[str] = []
    with open_port(port, baud) as sp:
        model = _answering(sp, servo_id, port, baud)
        if new_baud == baud:
            return [f"servo {servo_id} already runs at {baud} bps: nothing to do"]
        sp.set_baud(new_baud)
        taken = sp.ping_confirmed(servo_id)
        sp.set_baud(baud)
        if taken is not None:
            raise DeviceError(
                f"ID {servo_id} is taken at {new_baud} bps (a "
                f"{MODEL_NAMES.get(taken, f'model {taken}')} answers there): give this servo "
                f"another ID first (`handrig servos set-id --baud {baud} {servo_id} NEW`)")
        if note := _eeprom_ready(sp, servo_id):
            notes.append(note)
        sp.write_unconfirmed(servo_id, Reg.BAUD_RATE, BAUD_INDEX[new_baud])
        sp.set_baud(new_baud)
        if sp.ping_confirmed(servo_id) is None:
            raise DeviceError(f"wrote baud {new_baud} to servo {servo_id} but it does not "
                              f"answer at {new_baud} bps: run `handrig servos scan`")
        notes.append(f"servo {servo_id} ({MODEL_NAMES.get(model, model)}) now runs at "
                     f"{new_baud} bps")
    return notes


def reboot(port: str, baud: int, servo_id: int, wait_s: float = REBOOT_WAIT_S) -> FoundServo:
    """Reboot servo ``servo_id`` (clears a hardware error whose cause is gone) and
    return its state afterwards."""
    with open_port(port, baud) as sp:
        _answering(sp, servo_id, port, baud)
        sp.reboot(servo_id)
        deadline = time.monotonic() + wait_s + 2.0
        time.sleep(wait_s)
        while (model := sp.ping(servo_id)) is None:
            if time.monotonic() > deadline:
                raise DeviceError(f"servo {servo_id} did not answer after the reboot")
            time.sleep(0.05)
        firmware = sp.read(servo_id, Reg.FIRMWARE_VERSION)
        return sp.describe(servo_id, model, firmware)


def check(port: str, rig: RigConfig, *, baud: int | None = None) -> tuple[list[FoundServo],
                                                                          list[Finding]]:
    """Compare the servos answering at the rig's baud with its ``[[servos]]``: missing,
    extra, wrong model, wrong operating mode, voltage outside the model's range, and
    hardware errors."""
    baud = baud or rig.bus.baud
    with open_port(port, baud) as sp:
        found_ids, collided = sp.broadcast_ping()
        found = [sp.describe(i, m, fw) for i, (m, fw) in sorted(found_ids.items())]
    by_id = {s.id: s for s in found}
    wanted = {s.id: s for s in rig.servos}
    mode = OPERATING_MODES[rig.servo_settings.operating_mode]
    findings: list[Finding] = []
    if collided:
        findings.append(Finding(-1, "collision", f"garbled replies at {baud} bps",
                                ONE_AT_A_TIME))
    for servo_id, cal in sorted(wanted.items()):
        got = by_id.get(servo_id)
        if got is None:
            findings.append(Finding(
                servo_id, "missing", f"servo {servo_id} ({cal.joint}) does not answer at "
                f"{baud} bps",
                "check its cable and power; `handrig servos scan` finds it at another baud "
                "or ID, then `handrig servos set-baud`/`set-id`"))
            continue
        if got.model != servo_model(cal):
            findings.append(Finding(
                servo_id, "model", f"servo {servo_id} ({cal.joint}) is a {got.model}, the "
                f"rig file says {servo_model(cal)}",
                "fit the servo the rig file names, or correct `model` in its [[servos]]"))
        if got.operating_mode is not None and got.operating_mode != mode:
            findings.append(Finding(
                servo_id, "mode", f"servo {servo_id} is in {got.mode_name} mode "
                f"({got.operating_mode}), the rig wants {rig.servo_settings.operating_mode} "
                f"({mode})",
                "`handrig run` writes [servo_settings] operating_mode when it starts; a servo "
                "that keeps another mode has a different Operating Mode (11) written by "
                "another program: check [servo_settings]"))
        limits = VOLTAGE_RANGE_V.get(got.model)
        if got.voltage_v is not None and limits and not limits[0] <= got.voltage_v <= limits[1]:
            findings.append(Finding(
                servo_id, "voltage", f"servo {servo_id} reads {got.voltage_v:.1f} V, outside "
                f"the {got.model}'s {limits[0]:g}..{limits[1]:g} V",
                "check the supply voltage and the chain's wiring (docs/hardware.md)"))
        if got.hardware_error:
            findings.append(Finding(
                servo_id, "hardware error", f"servo {servo_id}: {got.errors_text}",
                f"remove the cause, then `handrig servos reboot {servo_id}`"))
        if got.unread:  # not checked is not fine: say so
            findings.append(Finding(
                servo_id, "unread", f"servo {servo_id} answered its ping but not the reads of "
                f"{', '.join(got.unread)} ({DESCRIBE_TRIES} tries each): not checked",
                "check its cable and the chain's wiring (a reply garbled or late), then run "
                "`handrig servos check` again"))
    for servo_id in sorted(set(by_id) - set(wanted)):
        s = by_id[servo_id]
        findings.append(Finding(
            servo_id, "extra", f"servo {servo_id} ({s.model}) answers but the rig file has "
            "no [[servos]] with this ID",
            "add it to the rig file, or give it the ID of a missing one with "
            "`handrig servos set-id`"))
    return found, findings


class DynamixelBringup(BusBringup):
    """Bring-up of X-series servos on ``port``: the functions above, each step opening
    the port with the SDK at the baud it is given (a pseudo-terminal's replies waited
    for :data:`PTY_PATIENCE_MS` longer)."""

    bauds = BAUD_RATES
    family = "the X series"
    one_at_a_time = ONE_AT_A_TIME

    def scan(self, bauds: Sequence[int]) -> ScanResult:
        return scan(self.port, bauds)

    def ping_all(self, baud: int) -> tuple[dict[int, int], bool]:
        with open_port(self.port, baud) as sp:
            found, collided = sp.broadcast_ping()
        return {i: model for i, (model, _firmware) in found.items()}, collided

    def ping(self, baud: int, servo_id: int) -> int | None:
        with open_port(self.port, baud) as sp:
            return sp.ping_confirmed(servo_id)

    def search_order(self, first: Sequence[int] = ()) -> list[int]:
        return search_order(first)

    def find_baud(self, servo_id: int, bauds: Sequence[int]) -> int:
        return find_baud(self.port, servo_id, bauds)

    def set_id(self, baud: int, old_id: int, new_id: int) -> list[str]:
        return set_id(self.port, baud, old_id, new_id)

    def set_baud(self, baud: int, servo_id: int, new_baud: int) -> list[str]:
        return set_baud(self.port, baud, servo_id, new_baud)

    def reboot(self, baud: int, servo_id: int) -> FoundServo:
        return reboot(self.port, baud, servo_id)

    def torque_off(self, baud: int, servo_id: int) -> bool:
        with open_port(self.port, baud) as sp:
            if sp.read(servo_id, Reg.TORQUE_ENABLE):
                sp.write(servo_id, Reg.TORQUE_ENABLE, 0)
                return True
        return False

    def check(self, rig: RigConfig, *, baud: int | None = None
              ) -> tuple[list[FoundServo], list[Finding]]:
        return check(self.port, rig, baud=baud)

    def model_name(self, model_number: int) -> str:
        return model_name(model_number)
