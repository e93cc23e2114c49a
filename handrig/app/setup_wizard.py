"""``handrig setup``'s steps: from a plugged-in adapter to servos a rig can run.

1. :func:`find_port`: which serial port is the servo adapter. Like LeRobot's
   ``find_port``: the ports are listed, the person unplugs the adapter, the port
   that went away is it; they plug it back in. Its stable ``/dev/serial/by-id/``
   name is suggested (a ``/dev/ttyUSB0`` can change with the order things are
   plugged in).
2. (the command writes the port into the person's rig file)
3. :func:`commission_servos`: a box of new servos, one at a time, as the vendor's
   wizard and LeRobot's motor setup do: plug one in, it is found at whatever ID
   and baud it has (a factory-new servo: ID 1 at the factory baud the driver knows),
   given the rig's next ID and the rig's baud, torque off, next.

The servos are reached through a :class:`~handrig.devices.servo.bringup.BusBringup`
on the adapter's port (the factory's :func:`~handrig.app.factory.servo_bringup`), so
nothing here knows their vendor. Every question goes through ``ask`` and every line
through ``say``, and the port list through ``list_ports``, so a test drives the steps
against the emulated bus.
"""

from __future__ import annotations

import glob
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from handrig.config.rig import RigConfig
from handrig.devices.servo.bringup import BusBringup
from handrig.errors import DeviceError, HandrigError

Ask = Callable[[str], str]
Say = Callable[[str], None]
PORT_PATTERNS = ("/dev/ttyUSB*", "/dev/ttyACM*", "/dev/tty.usbserial*", "/dev/tty.usbmodem*")
"""Where USB serial adapters appear (Linux: FTDI/CH340 as ttyUSB, CDC-ACM such as the
U2D2's newer firmware or an Arduino as ttyACM; macOS: tty.usb*)."""
REPLUG_WAIT_S = 5.0  # how long a port may take to come back after the adapter is replugged


class Quit(HandrigError):
    """The person asked to stop (``q``): nothing more is done."""


def serial_ports() -> list[str]:
    """The USB serial ports there are now (:data:`PORT_PATTERNS`), sorted."""
    return sorted({p for pattern in PORT_PATTERNS for p in glob.glob(pattern)})


def find_port(list_ports: Callable[[], Sequence[str]], ask: Ask, say: Say, *,
              stable_name: Callable[[str], Path | None] = lambda _port: None,
              tries: int = 3) -> str:
    """The servo adapter's port, found by unplugging it: the one port that went away.
    Returns its stable name (``stable_name``, e.g. ``/dev/serial/by-id/...``) when it
    has one. DeviceError after ``tries`` attempts where no single port went away."""
    for _ in range(tries):
        before = set(list_ports())
        if not before:
            say("no USB serial port is there: plug the servo adapter (U2D2 or similar) "
                "into a USB port")
            _enter(ask, "press Enter when it is plugged in: ")
            continue
        say(f"serial ports now: {', '.join(sorted(before))}")
        _enter(ask, "unplug the servo adapter's USB cable, then press Enter: ")
        gone = sorted(before - set(list_ports()))
        if len(gone) != 1:
            say("no port went away: was it the adapter you unplugged? try again" if not gone
                else f"{len(gone)} ports went away ({', '.join(gone)}): unplug only the "
                "servo adapter; try again")
            _enter(ask, "plug it back in, then press Enter: ")
            continue
        port = gone[0]
        _enter(ask, f"the adapter is {port}: plug it back in, then press Enter: ")
        deadline = time.monotonic() + REPLUG_WAIT_S
        while port not in list_ports():
            if time.monotonic() > deadline:
                raise DeviceError(f"{port} did not come back after the adapter was plugged in "
                                  "again: run `handrig setup` once more")
            time.sleep(0.1)
        stable = stable_name(port)
        if stable is not None:
            say(f"{port} is also {stable}: that name stays the same when the adapter is "
                "plugged in again or other USB devices come and go; the rig file gets it")
            return str(stable)
        say(f"{port} has no /dev/serial/by-id/ name here: the rig file gets {port} (it can "
            "change with the order USB devices are plugged in)")
        return port
    raise DeviceError(f"no single port went away in {tries} tries: give the adapter's port "
                      "with `handrig setup --port PORT`")


def _enter(ask: Ask, prompt: str) -> None:
    if ask(prompt).strip().lower() == "q":
        raise Quit("setup stopped")


@dataclass
class Commissioned:
    """What :func:`commission_servos` did: servo IDs made ready, skipped, and lines."""

    ready: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class NewServo:
    id: int
    baud: int
    model_number: int
    model: str  # the vendor's name for it


def find_new_servo(servos: BusBringup, bauds: Sequence[int],
                   ready: dict[int, int]) -> NewServo | None:
    """The one servo on the port of ``servos`` that is not among ``ready`` ({ID: baud} of
    servos made ready before, still chained), looking at ``bauds`` in order and stopping
    at the first baud where one answers; None if none does. DeviceError when replies
    collide (two servos with one ID) or more than one new servo answers."""
    for baud in bauds:
        found, collided = servos.ping_all(baud)
        if collided:
            raise DeviceError(f"replies collide at {baud} bps: {servos.one_at_a_time}")
        new = {i: m for i, m in found.items() if ready.get(i) != baud}
        if len(new) > 1:
            raise DeviceError(f"{len(new)} new servos answer at {baud} bps (IDs "
                              f"{', '.join(map(str, sorted(new)))}): plug in one new "
                              "servo at a time")
        if new:
            (servo_id, model), = new.items()
            return NewServo(servo_id, baud, model, servos.model_name(model))
    return None


def make_ready(servos: BusBringup, servo: NewServo, new_id: int, baud: int) -> list[str]:
    """Give ``servo`` the ID ``new_id`` and the baud ``baud`` (each only if it differs),
    confirm it answers there and leave its torque off. Returns what was done."""
    notes: list[str] = []
    if (servo.id, servo.baud) != (new_id, baud):
        taken = servos.ping(baud, new_id)
        if taken is not None:
            raise DeviceError(
                f"ID {new_id} is taken at {baud} bps by another servo on the bus (a "
                f"{servos.model_name(taken)}): two servos with one ID garble "
                "every reply. Unplug the others and plug in this new servo alone")
    if servo.id != new_id:
        notes += servos.set_id(servo.baud, servo.id, new_id)
    if servo.baud != baud:
        notes += servos.set_baud(servo.baud, new_id, baud)
    if servos.ping(baud, new_id) is None:
        raise DeviceError(f"servo {new_id} does not answer at {baud} bps after the "
                          "changes: run `handrig servos scan`")
    servos.torque_off(baud, new_id)
    return notes


def commission_servos(servos: BusBringup, rig: RigConfig, ids: Sequence[int], ask: Ask,
                      say: Say, *, bauds: Sequence[int] | None = None) -> Commissioned:
    """For each of ``ids`` (the rig's servo IDs, in order): ask for one servo to be
    plugged in on the port of ``servos``, find it at any baud (``bauds``, else
    :meth:`~handrig.devices.servo.bringup.BusBringup.search_order` with the rig's
    first), give it the ID and the rig's baud, torque off. ``s`` skips a servo, ``q``
    stops (:class:`Quit`); a servo not found, or a collision, says what to do and asks
    again."""
    order = list(bauds) if bauds else servos.search_order([rig.bus.baud])
    done = Commissioned()
    ready: dict[int, int] = {}
    joints = {s.id: s.joint for s in rig.servos}
    for k, target in enumerate(ids):
        while True:
            answer = ask(f"[{k + 1}/{len(ids)}] plug in the servo for ID {target} "
                         f"({joints.get(target, '?')}): one new servo (alone, or chained "
                         "behind the ones done), powered; Enter finds it, s skips, q "
                         "stops: ").strip().lower()
            if answer == "q":
                raise Quit("setup stopped")
            if answer == "s":
                say(f"servo {target}: skipped")
                done.skipped.append(target)
                break
            try:
                found = find_new_servo(servos, order, ready)
                if found is None:
                    say(f"no new servo answers at any of {', '.join(map(str, order))} bps: "
                        "check its power (its LED blinks once at power-on) and cable, then "
                        "press Enter again")
                    continue
                say(f"found a {found.model} as ID {found.id} at {found.baud} bps")
                for line in make_ready(servos, found, target, rig.bus.baud):
                    say(f"  {line}")
            except DeviceError as exc:
                say(f"servo {target}: {exc}")
                continue
            say(f"servo {target} ready: ID {target} at {rig.bus.baud} bps, torque off "
                f"(label it {target}); next")
            ready[target] = rig.bus.baud
            done.ready.append(target)
            break
    return done
