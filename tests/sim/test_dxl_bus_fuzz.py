"""The bus emulator fed arbitrary bytes and arbitrary valid packets, without a pty:
it never fails, and everything it sends is a well-formed status or fast-read reply."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol import dynamixel as dx
from handrig.clock import FakeClock
from sim.dxl_bus import FaultSpec, SimBus
from sim.dxl_servo import EmulatedServo


class CapturingBus(SimBus):
    """A SimBus whose line is a list: what it would write to the pty."""

    def __init__(self, faults: FaultSpec | None = None) -> None:
        super().__init__([EmulatedServo(i) for i in (1, 2, 3)], faults=faults,
                         clock=FakeClock())
        self.sent: list[bytes] = []

    def _emit(self, data: bytes) -> None:
        self.sent.append(data)


def _check_sent(bus: CapturingBus) -> None:
    for data in bus.sent:
        assert data[:4] == dx.HEADER
        announced = 7 + (data[5] | data[6] << 8)
        if data[4] == dx.BROADCAST_ID:  # a fast read reply, cut short at a missing servo
            assert data[7] == dx.STATUS_INSTRUCTION and len(data) <= announced
            if len(data) == announced:
                assert dx.find_frame(data) == (0, len(data))
                assert dx.crc16(data[:-2]) == data[-2] | data[-1] << 8
        else:
            assert len(data) == announced
            dx.parse_status(data)


instructions = st.sampled_from([int(i) for i in dx.Instruction] + [0x00, 0x77, 0xFF])
ids = st.sampled_from([0, 1, 2, 3, 4, dx.BROADCAST_ID])


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(ids, instructions, st.binary(max_size=40)), max_size=8))
def test_valid_packets_with_any_parameters(packets: list[tuple[int, int, bytes]]) -> None:
    bus = CapturingBus()
    for servo_id, inst, params in packets:
        bus.feed(dx.build_instruction(servo_id, inst, params, do_stuff=False))
    assert bus.stats.packets == len(packets)
    _check_sent(bus)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_garbage_never_breaks_framing(data: bytes) -> None:
    bus = CapturingBus()
    bus.feed(data)
    bus.feed(dx.build_instruction(2, dx.Instruction.PING), now=10.0)  # stale partials give up
    bus.feed(dx.build_instruction(2, dx.Instruction.PING), now=10.0)
    assert any(dx.parse_status(d).id == 2 for d in bus.sent if d[4] == 2)


fast_inst = st.sampled_from([dx.Instruction.FAST_SYNC_READ, dx.Instruction.SYNC_READ])


@settings(max_examples=300, deadline=None)
@given(fast_inst, st.integers(0, 800), st.integers(0, 70000),
       st.lists(st.integers(0, 5), max_size=6))
def test_sync_reads_of_any_range(inst: int, address: int, length: int, ids: list[int]) -> None:
    bus = CapturingBus()
    bus.feed(dx.build_instruction(dx.BROADCAST_ID, inst,
                                  dx.sync_read_params(address, min(length, 0xFFFF), ids),
                                  do_stuff=False))
    _check_sent(bus)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.integers(0, 800), st.integers(0, 2000)),
                min_size=1, max_size=5))
def test_fast_bulk_reads_of_any_range(items: list[tuple[int, int, int]]) -> None:
    bus = CapturingBus()
    bus.feed(dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.FAST_BULK_READ,
                                  dx.bulk_read_params(items), do_stuff=False))
    bus.feed(dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.BULK_READ,
                                  dx.bulk_read_params(items), do_stuff=False))
    _check_sent(bus)


def test_sync_write_then_fast_sync_read_without_a_pty() -> None:
    bus = CapturingBus()
    goals = [(i, (2000 + i).to_bytes(4, "little")) for i in (1, 2, 3)]
    bus.feed(dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE,
                                  dx.sync_write_params(116, 4, goals), do_stuff=False))
    bus.feed(dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.FAST_SYNC_READ,
                                  dx.sync_read_params(116, 4, [3, 1]), do_stuff=False))
    (reply,) = bus.sent
    parts = dx.parse_fast_read_reply(reply, [4, 4])
    assert [(p.id, int.from_bytes(p.params, "little")) for p in parts] == [(3, 2003), (1, 2001)]


def test_wrong_id_fault_in_a_fast_read_keeps_the_crcs_valid() -> None:
    bus = CapturingBus(FaultSpec(wrong_id=1.0, seed=2))
    bus.feed(dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.FAST_SYNC_READ,
                                  dx.sync_read_params(132, 4, [1, 2]), do_stuff=False))
    (reply,) = bus.sent
    parts = dx.parse_fast_read_reply(reply, [4, 4])
    assert parts[0].id != 1 and parts[1].id == 2
    assert bus.fault_counts["wrong_id"] == 1


def test_faults_switched_at_runtime() -> None:
    bus = CapturingBus()
    ping = dx.build_instruction(2, dx.Instruction.PING)
    bus.feed(ping)
    assert len(bus.sent) == 1
    bus.faults = FaultSpec(missing=frozenset({2}))
    bus.feed(ping)
    assert len(bus.sent) == 1 and bus.fault_counts["missing"] == 1
    bus.faults = FaultSpec()
    bus.feed(ping)
    assert len(bus.sent) == 2
