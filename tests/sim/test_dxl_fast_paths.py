"""The emulator's quick paths (sim/dxl_fast.py) answer byte for byte as the general path.

Two buses with the same servos get the same random packets through ``SimBus.feed``
(no pty, no thread): one as shipped, one whose quick paths always decline (a
subclass), so every packet goes through the general dispatcher. Their replies and
every servo's control table must stay equal, packet after packet.
"""

from __future__ import annotations

import random

import pytest

from firmware_protocol import dynamixel as dx
from handrig.clock import FakeClock
from sim.dxl_bus import SimBus, _Reply
from sim.dxl_servo import EmulatedServo

IDS = (1, 2, 3, 4, 7)


class GeneralOnly(SimBus):
    """The emulated bus with its quick paths switched off."""

    def _quick_goal_write(self, params: bytes, now: float) -> bool:
        return False

    def _quick_fast_read(self, params: bytes, now: float) -> list[_Reply] | None:
        return None


def _bus(cls: type[SimBus]) -> tuple[SimBus, list[bytes]]:
    out: list[bytes] = []
    bus = cls([EmulatedServo(i, model) for i, model in zip(
        IDS, ("XL330-M288", "XC330-T288", "XM430-W350", "XL330-M288", "XC430-W150"),
        strict=True)], clock=FakeClock(0.0), realtime=False)
    bus.goal_limits = {1: (1000, 3000), 3: (0, 4095)}
    bus._emit = out.append  # type: ignore[method-assign]
    return bus, out


def _packet(rng: random.Random) -> bytes:
    ids = [rng.choice((*IDS, 9)) for _ in range(rng.randint(1, 5))]
    kind = rng.random()
    if kind < 0.35:  # Goal Position, in and out of every limit, to known and unknown IDs
        items = [(i, rng.choice((rng.randint(0, 4095), rng.randint(-2_000_000, 2_000_000)))
                  .to_bytes(4, "little", signed=True)) for i in dict.fromkeys(ids)]
        return dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE,
                                    dx.sync_write_params(116, 4, items), do_stuff=False)
    if kind < 0.7:  # Fast Sync Read of a random range
        address = rng.choice((132, 126, 120, 122, 64, 0, 600, 660))
        length = rng.choice((1, 2, 4, 10, 4))
        return dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.FAST_SYNC_READ,
                                    dx.sync_read_params(address, length, ids), do_stuff=False)
    servo = rng.choice(IDS)
    address, data = rng.choice([
        (64, bytes((rng.randint(0, 1),))),  # torque
        (11, bytes((rng.choice((3, 4, 5, 1)),))),  # operating mode (torque off only)
        (98, bytes((rng.choice((0, 1, 5)),))),  # Bus Watchdog
        (68, bytes((rng.choice((0, 1, 2)),))),  # Status Return Level
        (24, rng.randint(0, 30).to_bytes(4, "little")),  # Moving Threshold
        (112, rng.choice((0, 50)).to_bytes(4, "little")),  # Profile Velocity
        (20, rng.randint(-500, 500).to_bytes(4, "little", signed=True)),  # Homing Offset
    ])
    if rng.random() < 0.1:
        return dx.build_instruction(servo, dx.Instruction.REBOOT)
    return dx.build_instruction(servo, dx.Instruction.WRITE, dx.write_params(address, data))


@pytest.mark.parametrize("seed", range(3))
def test_quick_paths_answer_as_the_general_path(seed: int) -> None:
    rng = random.Random(seed)
    quick, quick_out = _bus(SimBus)
    general, general_out = _bus(GeneralOnly)
    for step in range(400):
        packet = _packet(rng)
        t = step * 0.004
        for bus in (quick, general):
            clock = bus.clock
            assert isinstance(clock, FakeClock)
            clock.advance(t - clock.now())
            bus.feed(packet, now=t)
            if step % 7 == 0:  # motion and watchdogs, as the bus's housekeeping does
                bus._housekeeping(t)
            if step % 97 == 50:  # an overload: the Alert bit in every status until a reboot
                bus.servo(IDS[step % len(IDS)]).inject_hardware_error()
        assert quick_out == general_out, f"step {step}: {packet.hex(' ')}"
        for a, b in zip(quick.servos, general.servos, strict=True):
            assert bytes(a.mem) == bytes(b.mem), f"step {step}, servo {a.id}"
            assert a.counters == b.counters and a.last_heard == b.last_heard
    assert quick.stats.goals_decoded == general.stats.goals_decoded > 100
    assert quick.stats.goals_outside == general.stats.goals_outside > 10
    assert len(quick_out) > 100
