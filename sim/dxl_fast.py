"""The emulated bus's two hot packets, answered without the general dispatcher.

A realtime client sends two packets a cycle: a Sync Write of Goal Position and a
Fast Sync Read. The general path (:class:`sim.dxl_dispatch.Dispatcher`) answers
them in ~2-3 us of Python per servo; this module answers the common case, where
every addressed servo is there, awake, hears the packet's baud and no reply fault
is switched on, with one plan per request made once (which servos, where each
one's bytes go in the reply) and the reply's running CRCs two bytes a step.
Anything else (a servo missing, rebooting, at another baud, a Status Return Level
of 0, a fault spec with reply faults or mutes) returns ``None`` and the general
path answers, byte for byte as before: the plans only skip work whose result they
know.

The CRC here is the emulator's own (CRC-16/BUYPASS,
:func:`firmware_protocol.dynamixel.crc16`), not the driver's, so a misreading
on one side still fails a test instead of cancelling out. Where the install built
``sim/_dxl_c.c`` (setup.py; any C compiler), the instruction's CRC check and the
reply's ERR bytes, data and running CRCs are compiled (``COMPILED``); without it the
same bytes come from pure Python, slower (docs/measurements.md, issue 36).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

from firmware_protocol.dynamixel import (
    BROADCAST_ID,
    ERROR_ALERT,
    HEADER,
    MAX_PACKET_LEN,
    PREFIX_LEN,
    STATUS_INSTRUCTION,
    InstructionPacket,
    crc16,
    parse_instruction,
    unstuff,
)
from sim.dxl_rig import GOAL_POSITION_ADDRESS
from sim.dxl_servo import READABLE_BYTES, EmulatedServo

try:
    from sim import _dxl_c
except ImportError:  # not built (no C compiler at install): pure Python, the same bytes
    _dxl_c = None  # type: ignore[assignment]

COMPILED = _dxl_c is not None
"""Whether the compiled packet path (sim/_dxl_c.c) answers; the bus benches print it."""
PACKET_PATH = "compiled" if COMPILED else "pure Python"
_HARDWARE_ERROR_ADDRESS = 70  # Hardware Error Status (X-series control table)


# Bytes before the first servo's ERR in a fast read reply: header, ID, LEN, 0x55.
_REPLY_PREFIX = 8
_ID_GOAL = struct.Struct("<Bi")  # a Sync Write item of Goal Position


def running_crcs(reply: bytearray, stride: int, count: int) -> None:
    """Fill a fast read reply's running CRCs in place (chunks of equal ``stride``): the
    running CRC at the end of each of ``count`` chunks (its last two bytes), after the
    8-byte prefix; each covers the CRCs before it too. The emulator's own CRC
    (:func:`firmware_protocol.dynamixel.crc16`, two bytes a step): no compiled kernel,
    so the emulator's process starts without numba (0.5 s a start, hundreds of starts
    in the test suite)."""
    view = memoryview(reply)
    crc = 0
    start = 0
    for k in range(count):
        end = _REPLY_PREFIX + (k + 1) * stride - 2
        crc = crc16(view[start:end], crc)
        reply[end] = crc & 0xFF
        reply[end + 1] = crc >> 8
        start = end


def parse_frame(frame: bytes, compiled: bool = COMPILED) -> InstructionPacket:
    """:func:`firmware_protocol.dynamixel.parse_instruction`, its CRC compiled
    (``compiled``, where built): a frame with the right header, length and CRC is taken
    apart here; any other goes to ``parse_instruction``, which raises the same
    :class:`PacketError` as before."""
    if compiled and _dxl_c is not None and len(frame) >= PREFIX_LEN + 3 and frame[:4] == HEADER \
            and len(frame) == PREFIX_LEN + (frame[5] | frame[6] << 8) \
            and _dxl_c.crc16(memoryview(frame)[:-2]) == frame[-2] | frame[-1] << 8:
        region = unstuff(frame[PREFIX_LEN:-2])
        return InstructionPacket(frame[4], region[0], region[1:])
    return parse_instruction(frame)


def _servos(by_id: dict[int, EmulatedServo], ids: bytes) -> list[EmulatedServo] | None:
    """The servos ``ids`` address, in order; None when one is not on the bus."""
    servos = []
    for i in ids:
        servo = by_id.get(i)
        if servo is None:
            return None
        servos.append(servo)
    return servos


@dataclass
class ReadPlan:
    """A Fast Sync Read request the bus has answered before: its servos in order,
    the bytes each one reads, and the reply with everything but ERR, data and CRCs."""

    servos: tuple[EmulatedServo, ...]
    address: int
    length: int
    template: bytes
    generation: int
    mems: tuple[bytearray, ...]  # the servos' control tables, in order


@dataclass
class WritePlan:
    """The servos of a Sync Write's ID sequence, and their goal limits as arrays."""

    servos: tuple[EmulatedServo, ...]
    low: tuple[int, ...]  # per item; low > high: no limits
    high: tuple[int, ...]
    generation: int
    limits: dict[int, tuple[int, int]]
    mems: tuple[bytearray, ...]  # the servos' control tables, in order


def read_plan(by_id: dict[int, EmulatedServo], address: int, length: int,
              ids: bytes, generation: int) -> ReadPlan | None:
    """The plan for a Fast Sync Read of ``ids``, or None when the general path must
    answer (an ID not on the bus, a range the reply cannot carry)."""
    total = _REPLY_PREFIX + len(ids) * (length + 4)
    if not ids or length == 0 or address + length > READABLE_BYTES or total > MAX_PACKET_LEN:
        return None
    servos = _servos(by_id, ids)
    if servos is None:
        return None
    template = bytearray(total)
    template[:4] = HEADER
    template[4] = BROADCAST_ID
    template[5:7] = (total - 7).to_bytes(2, "little")
    template[7] = STATUS_INSTRUCTION
    for k, i in enumerate(ids):
        template[_REPLY_PREFIX + k * (length + 4) + 1] = i
    return ReadPlan(tuple(servos), address, length, bytes(template), generation,
                    tuple(s.mem for s in servos))


def answer_read(plan: ReadPlan, now: float, baud_index: int,
                compiled: bool = COMPILED) -> bytes | None:
    """The reply to the planned Fast Sync Read now, or None when a servo would not
    answer it normally (rebooting, another baud, Status Return Level 0).
    ``baud_index``: the packet's Baud Rate item value, -1 when every servo hears it;
    ``compiled``: ERR bytes, data and CRCs from sim/_dxl_c.c where built."""
    servos = plan.servos
    a, n = plan.address, plan.length
    reply = bytearray(plan.template)
    if compiled and _dxl_c is not None:
        if not _dxl_c.answer_fast_read(reply, servos, plan.mems, a, n, _REPLY_PREFIX,
                                       _HARDWARE_ERROR_ADDRESS, ERROR_ALERT, now, baud_index):
            return None
        return bytes(reply)
    for s in servos:
        m = s.mem
        if s.silent_until > now or (baud_index >= 0 and m[8] != baud_index) or not m[68]:
            return None
    for s in servos:
        s.last_heard = now
        s.counters["reads"] += 1
    stride = n + 4
    pos = _REPLY_PREFIX
    for s in servos:
        m = s.mem
        if m[_HARDWARE_ERROR_ADDRESS]:
            reply[pos] = ERROR_ALERT
        reply[pos + 2 : pos + 2 + n] = m[a : a + n]
        pos += stride
    running_crcs(reply, stride, len(servos))
    return bytes(reply)


def write_plan(by_id: dict[int, EmulatedServo], ids: bytes,
               limits: dict[int, tuple[int, int]], generation: int) -> WritePlan | None:
    """The plan for a Sync Write of Goal Position to ``ids`` (None: an ID not on the bus)."""
    servos = _servos(by_id, ids)
    if servos is None:
        return None
    no_limits = (1, 0)
    low = tuple(limits.get(i, no_limits)[0] for i in ids)
    high = tuple(limits.get(i, no_limits)[1] for i in ids)
    return WritePlan(tuple(servos), low, high, generation, limits,
                     tuple(s.mem for s in servos))


def write_goals(plan: WritePlan, body: bytes, now: float, compiled: bool = COMPILED) -> None:
    """Each planned servo hears the Sync Write (``ID goal`` x N) and takes its goal, as
    :meth:`EmulatedServo.write` does it (``compiled``: in sim/_dxl_c.c where built)."""
    if compiled and _dxl_c is not None:
        _dxl_c.write_goals(plan.servos, plan.mems, body, now)
        return
    k = 1
    for servo in plan.servos:
        servo.last_heard = now
        servo.write(GOAL_POSITION_ADDRESS, body[k : k + 4])
        k += 5


def goals_heard(plan: WritePlan, body: bytes, now: float, baud_index: int,
                compiled: bool = COMPILED) -> int:
    """-1 when a planned servo does not hear a Sync Write of Goal Position (``ID goal`` x
    N) at ``baud_index`` (-1: any) now; else how many of its goals lie outside the plan's
    limits."""
    if compiled and _dxl_c is not None:
        return _dxl_c.goals_heard(plan.servos, plan.mems, body, now, baud_index,
                                  plan.low, plan.high)
    if not hear_all(plan.servos, now, baud_index):
        return -1
    return goals_outside(body, plan)


def mark_heard(servos: Sequence[EmulatedServo], mems: Sequence[bytearray], now: float,
               baud_index: int, compiled: bool = COMPILED) -> None:
    """A broadcast heard ``now`` by every servo at ``baud_index`` (-1: every servo; -2:
    none); ``mems`` the servos' control tables, in the same order."""
    if compiled and _dxl_c is not None:
        _dxl_c.mark_heard(servos, mems, now, baud_index)
        return
    for s in servos:
        if baud_index == -1 or s.mem[8] == baud_index:
            s.last_heard = now


def hear_all(servos: Sequence[EmulatedServo], now: float, baud_index: int) -> bool:
    """Whether every servo is awake and hears a packet at ``baud_index`` (-1: any)."""
    for s in servos:
        if s.silent_until > now or (baud_index >= 0 and s.mem[8] != baud_index):
            return False
    return True


def goals_outside(body: bytes, plan: WritePlan) -> int:
    """How many goals of a Sync Write body (``ID goal`` x N) lie outside the plan's limits."""
    return sum(1 for (_, goal), low, high in zip(_ID_GOAL.iter_unpack(body), plan.low,
                                                 plan.high, strict=True)
               if low <= high and not low <= goal <= high)
