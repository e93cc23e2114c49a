"""The emulator's compiled packet path (sim/_dxl_c.c) answers byte for byte as pure Python.

Three buses with the same servos get the same random packets through ``SimBus.feed``:
the general dispatcher alone, the quick paths in pure Python (``compiled = False``,
what an install without a C compiler runs) and the quick paths compiled. Replies,
control tables, counters and ``last_heard`` must stay equal packet after packet,
through goals inside and outside every limit, profiles running, torque off, a Bus
Watchdog tripped, hardware errors and other modes. Skipped where the module was not
built (no C compiler at install): then only pure Python runs.
"""

from __future__ import annotations

import os
import random

import pytest

from firmware_protocol import dynamixel as dx
from handrig.clock import FakeClock
from sim import dxl_fast
from sim.dxl_bus import SimBus, _Reply
from sim.dxl_servo import EmulatedServo

pytestmark = pytest.mark.skipif(not dxl_fast.COMPILED, reason="sim/_dxl_c.c was not built")

IDS = (1, 2, 3, 5, 8, 13)
MODELS = ("XL330-M288", "XC330-T288", "XM430-W350", "XL330-M288", "XC430-W150", "XL330-M077")


class GeneralOnly(SimBus):
    """The emulated bus with its quick paths switched off."""

    def _quick_goal_write(self, params: bytes, now: float) -> bool:
        return False

    def _quick_fast_read(self, params: bytes, now: float) -> list[_Reply] | None:
        return None


class PurePython(SimBus):
    """The quick paths without the compiled module."""

    compiled = False


def _bus(cls: type[SimBus]) -> tuple[SimBus, list[bytes]]:
    out: list[bytes] = []
    bus = cls([EmulatedServo(i, m) for i, m in zip(IDS, MODELS, strict=True)],
              clock=FakeClock(0.0), realtime=False)
    bus.goal_limits = {1: (1000, 3000), 5: (0, 4095)}
    bus._emit = out.append  # type: ignore[method-assign]
    return bus, out


def _goal(rng: random.Random) -> bytes:
    value = rng.choice((rng.randint(1900, 2200), rng.randint(0, 4095),
                        rng.randint(-2_000_000, 2_000_000), 1_048_575, -1_048_576))
    return value.to_bytes(4, "little", signed=True)


def _packet(rng: random.Random) -> bytes:
    kind = rng.random()
    if kind < 0.4:  # Goal Position to every servo (the hot packet), now and then one more
        ids = list(IDS) if rng.random() < 0.8 else [*rng.sample(IDS, 3), 9]
        items = [(i, _goal(rng)) for i in ids]
        return dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE,
                                    dx.sync_write_params(116, 4, items), do_stuff=False)
    if kind < 0.75:  # Fast Sync Read: position (the hot one), or any range
        address, length = rng.choice(((132, 4), (132, 4), (126, 10), (64, 1), (120, 4)))
        return dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.FAST_SYNC_READ,
                                    dx.sync_read_params(address, length, IDS), do_stuff=False)
    if kind < 0.78:  # a torn or corrupted frame: the same PacketError path as before
        frame = bytearray(dx.build_instruction(IDS[0], dx.Instruction.PING))
        frame[-1] ^= 0x5A
        return bytes(frame)
    servo = rng.choice(IDS)
    address, data = rng.choice([
        (64, bytes((rng.randint(0, 1),))),  # Torque Enable
        (11, bytes((rng.choice((3, 4, 5, 1)),))),  # Operating Mode (taken with torque off)
        (98, bytes((rng.choice((0, 1)),))),  # Bus Watchdog: 1 trips it within 20 ms
        (24, rng.randint(0, 30).to_bytes(4, "little")),  # Moving Threshold
        (112, rng.choice((0, 0, 50, 200)).to_bytes(4, "little")),  # Profile Velocity
        (108, rng.choice((0, 20)).to_bytes(4, "little")),  # Profile Acceleration
        (48, rng.randint(2500, 4095).to_bytes(4, "little")),  # Max Position Limit
        (52, rng.randint(0, 1500).to_bytes(4, "little")),  # Min Position Limit
    ])
    if rng.random() < 0.05:
        return dx.build_instruction(servo, dx.Instruction.REBOOT)
    return dx.build_instruction(servo, dx.Instruction.WRITE, dx.write_params(address, data))


@pytest.mark.parametrize("seed", range(3))
def test_compiled_path_answers_as_pure_python_and_the_general_path(seed: int) -> None:
    rng = random.Random(seed)
    buses = [_bus(GeneralOnly), _bus(PurePython), _bus(SimBus)]
    assert buses[2][0].compiled and not buses[1][0].compiled
    for step in range(600):
        packet = _packet(rng)
        t = step * 0.003
        for bus, _ in buses:
            clock = bus.clock
            assert isinstance(clock, FakeClock)
            clock.advance(t - clock.now())
            bus.feed(packet, now=t)
            if step % 5 == 0:  # motion, profiles and watchdogs, as housekeeping does
                bus._housekeeping(t)
            if step % 131 == 70:  # an overload: the Alert bit until a reboot
                bus.servo(IDS[step % len(IDS)]).inject_hardware_error()
        outs = [out for _, out in buses]
        assert outs[0] == outs[1] == outs[2], f"step {step}: {packet.hex(' ')}"
        for servos in zip(*(bus.servos for bus, _ in buses), strict=True):
            general = servos[0]
            for s in servos[1:]:
                assert bytes(s.mem) == bytes(general.mem), f"step {step}, servo {s.id}"
                assert s.counters == general.counters and s.last_heard == general.last_heard
    stats = [bus.stats for bus, _ in buses]
    assert stats[0].goals_outside == stats[1].goals_outside == stats[2].goals_outside > 10
    assert stats[0].bad_crc == stats[2].bad_crc > 5
    assert len(buses[2][1]) > 150


def test_compiled_crc_is_the_emulators_crc16() -> None:
    from sim import _dxl_c

    rng = random.Random(1)
    for n in (0, 1, 2, 3, 7, 114, 255, 1001):
        data = os.urandom(n)
        start = rng.randrange(0x10000)
        assert _dxl_c.crc16(data) == dx.crc16(data)
        assert _dxl_c.crc16(data, start) == dx.crc16(data, start)
