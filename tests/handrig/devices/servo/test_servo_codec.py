"""The driver's codec: CRC against the SDK and the datasheet, framing, the compiled kernels.

References, kept here only: dynamixel-sdk's ``updateCRC`` (a Python loop) for the
CRC, plain Python and numpy written from the e-manual's layouts for the kernels,
and the emulator's independent codec (``firmware_protocol``) for packets.
"""

from __future__ import annotations

import numpy as np
import pytest
from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol import dynamixel as dx
from handrig.devices.servo import codec
from handrig.devices.servo.codec import (
    build_instruction,
    crc16,
    fast_sync_intact,
    parse_status,
    stuff,
    unstuff,
)
from handrig.devices.servo.registers import Reg, describe_hardware_error, describe_status_error
from handrig.errors import ProtocolError

SDK = Protocol2PacketHandler()


def sdk_crc(data: bytes, crc: int = 0) -> int:
    return int(SDK.updateCRC(crc, list(data), len(data)))


def test_crc_golden_ping() -> None:
    # REFERENCE.md section 1: ping of ID 1 has CRC 19 4E (low byte first)
    assert build_instruction(1, 0x01) == bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")


def sdk_crc16(data: bytes) -> int:
    return sdk_crc(data)


@given(st.binary(max_size=300), st.integers(0, 0xFFFF))
def test_crc_equals_sdk(data: bytes, start: int) -> None:
    assert crc16(data) == sdk_crc(data)
    arr = np.frombuffer(data, np.uint8)
    assert codec.crc16_kernel(arr, 0, len(data), start) == sdk_crc(data, start)


def test_crc_golden_emulator_codec() -> None:
    # the emulator's CRC is written from the e-manual, not taken from the SDK
    for n in (0, 1, 2, 9, 116, 168, 600):
        data = bytes(np.random.default_rng(n).integers(0, 256, n, dtype=np.uint8))
        assert crc16(data) == dx.crc16(data)


@given(st.binary(max_size=64))
def test_stuffing_round_trip(body: bytes) -> None:
    stuffed = stuff(body)
    assert unstuff(stuffed) == body
    assert b"\xff\xff\xfd" not in stuffed.replace(b"\xff\xff\xfd\xfd", b"")


def test_instruction_is_stuffed() -> None:
    pkt = build_instruction(3, 0x03, bytes([0x74, 0x00, 0xFF, 0xFF, 0xFD, 0x00]))
    assert pkt[5] == 3 + 7  # LEN grew by one for the stuffed FD
    assert b"\xff\xff\xfd\xfd" in pkt[7:]
    assert pkt[-2] | pkt[-1] << 8 == sdk_crc(pkt[:-2])


def status(servo_id: int, err: int, params: bytes) -> bytes:
    length = len(params) + 4
    head = bytes([0xFF, 0xFF, 0xFD, 0x00, servo_id, length & 0xFF, length >> 8, 0x55, err])
    crc = sdk_crc(head + params)
    return head + params + bytes([crc & 0xFF, crc >> 8])


def test_parse_status_and_errors() -> None:
    s = parse_status(status(7, 0x80, b"\x01\x02"))
    assert (s.servo_id, s.error, s.params) == (7, 0x80, b"\x01\x02")
    bad = bytearray(status(7, 0, b"\x01\x02"))
    bad[-1] ^= 0xFF
    with pytest.raises(ProtocolError, match="CRC"):
        parse_status(bytes(bad))
    with pytest.raises(ProtocolError, match="shorter"):
        parse_status(status(7, 0, b"")[:9])
    with pytest.raises(ProtocolError, match="LEN"):
        parse_status(status(7, 0, b"\x01\x02") + b"\x00")


def fast_reply(blocks: list[tuple[int, int, bytes]]) -> bytes:
    """A Fast Sync Read reply built with the SDK's CRC: running CRC per servo block."""
    data_len = len(blocks[0][2])
    length = 1 + (data_len + 4) * len(blocks)
    out = bytearray([0xFF, 0xFF, 0xFD, 0x00, 0xFE, length & 0xFF, length >> 8, 0x55])
    for err, sid, data in blocks:
        out += bytes([err, sid]) + data
        crc = sdk_crc(bytes(out))
        out += bytes([crc & 0xFF, crc >> 8])
    return bytes(out)


def check(raw: bytes, ids: tuple[int, ...], data_len: int, out: list[bool]) -> None:
    """codec.fast_sync_check into a list, as the old per-servo check returned it."""
    valid = np.zeros(len(ids), np.bool_)
    codec.fast_sync_check(np.frombuffer(raw, np.uint8), np.array(ids, np.uint8), data_len, valid)
    out[:] = valid.tolist()


def test_fast_sync_check_per_servo() -> None:
    ids = (3, 7, 4)
    raw = fast_reply([(0, 3, b"\x00\x08\x00\x00"), (0x80, 7, b"\x10\x00\x00\x00"),
                      (0, 4, b"\xff\x0f\x00\x00")])
    out = [False] * 3
    check(raw, ids, 4, out)
    assert out == [True, True, True]
    # truncated in the last block: the first two still verify
    check(raw[:-3], ids, 4, out)
    assert out == [True, True, False]
    # corrupted data of the second servo: it and every later block fail (running CRC)
    bad = bytearray(raw)
    bad[8 + 8 + 3] ^= 0x01
    check(bytes(bad), ids, 4, out)
    assert out == [True, False, False]
    # a block naming the wrong servo is not accepted for the one asked
    check(raw, (3, 8, 4), 4, out)
    assert out == [True, False, True]
    check(b"\xff\xff\xfd\x00\x01\x04\x00\x55\x00", ids, 4, out)
    assert out == [False, False, False]


def test_register_codec_and_words() -> None:
    assert Reg.GOAL_POSITION.encode(-1) == b"\xff\xff\xff\xff"
    assert Reg.BUS_WATCHDOG.decode(b"\xff") == -1
    assert Reg.PRESENT_POSITION.decode(b"\x00\x08\x00\x00") == 2048
    with pytest.raises(OverflowError):
        Reg.TORQUE_ENABLE.encode(256)
    assert describe_hardware_error(0x20) == "overload (bit 5)"
    assert describe_hardware_error(0x05) == "input voltage (bit 0), overheating (bit 2)"
    assert describe_status_error(0x84).startswith("alert")
    assert describe_status_error(0x04) == "data range error"


@given(st.lists(st.binary(min_size=3, max_size=3), min_size=1, max_size=6))
def test_fast_sync_check_odd_data_length(datas: list[bytes]) -> None:
    # odd data length takes the byte-wise path; every block must verify
    ids = tuple(range(1, len(datas) + 1))
    raw = fast_reply([(0, i, d) for i, d in zip(ids, datas, strict=True)])
    out = [False] * len(ids)
    check(raw, ids, 3, out)
    assert all(out)


@settings(deadline=None)  # the first example may compile the kernel
@given(st.lists(st.binary(min_size=10, max_size=10), min_size=1, max_size=6),
       st.integers(0, 200))
def test_fast_sync_check_prefix_on_truncation(datas: list[bytes], cut: int) -> None:
    ids = tuple(range(1, len(datas) + 1))
    raw = fast_reply([(0, i, d) for i, d in zip(ids, datas, strict=True)])
    cut = min(cut, len(raw))
    out = [True] * len(ids)
    check(raw[:cut], ids, 10, out)
    complete = max(0, (cut - 8) // 14)
    assert out == [i < complete for i in range(len(ids))]


def test_kernel_crc_is_the_sdk_crc() -> None:
    rng = np.random.default_rng(1)
    for n in (0, 1, 2, 9, 116, 168, 600):
        data = rng.integers(0, 256, n, dtype=np.uint8)
        assert codec.crc16_kernel(data, 0, n, 0) == sdk_crc16(data.tobytes())
        assert codec.crc16_kernel(data, 0, n // 2, 0) == sdk_crc16(data[: n // 2].tobytes())


def test_goal_packet_clamps_holds_encodes_ticks_and_crc() -> None:
    rng = np.random.default_rng(3)
    n = 20
    low, high = rng.uniform(-40, 0, n), rng.uniform(10, 90, n)
    tpd = rng.choice([-1, 1], n) * rng.uniform(4, 30, n)
    zero = rng.uniform(1000, 3000, n)
    last = np.full(n, np.nan)
    hold = np.clip(0.0, low, high)
    prefix = b"\xff\xff\xfd\x00\xfe" + (5 * n + 7).to_bytes(2, "little") + b"\x83\x74\x00\x04\x00"
    packet = np.zeros(codec.SYNC_WRITE_BODY + 5 * n + 2, np.uint8)
    packet[:12] = np.frombuffer(prefix, np.uint8)
    packet[12::5][:n] = np.arange(1, n + 1)
    for _ in range(300):
        goals = rng.uniform(-120, 150, n)
        goals[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        out = np.zeros(n)
        changed = codec.goal_packet(goals, low, high, last, hold, tpd, zero, out, packet)
        want = np.clip(goals, low, high)
        bad = ~np.isfinite(goals)
        want[bad] = np.where(np.isnan(last), hold, last)[bad]
        assert changed == np.count_nonzero(want != goals)
        np.testing.assert_array_equal(out, want)
        ticks = np.clip(np.rint(want * tpd + zero), 0, 4095).astype("<i4")
        blocks = b"".join(bytes((i + 1,)) + ticks[i].tobytes() for i in range(n))
        body = prefix + blocks
        crc = sdk_crc16(body)
        assert packet.tobytes() == body + bytes((crc & 0xFF, crc >> 8))
        last = out.copy()


def _fast_sync_reply(blocks: list[tuple[int, int, bytes]]) -> np.ndarray:
    """A Fast Sync Read reply: header, then [ERR, ID, data, running CRC] per servo."""
    total = 8 + sum(4 + len(d) for _, _, d in blocks)
    raw = bytearray(b"\xff\xff\xfd\x00\xfe" + (total - 7).to_bytes(2, "little") + b"\x55")
    for err, sid, data in blocks:
        raw += bytes((err, sid)) + data
        crc = sdk_crc16(raw)
        raw += bytes((crc & 0xFF, crc >> 8))
    return np.frombuffer(bytes(raw), np.uint8)


def test_fast_sync_whole_checks_and_decodes_signed_fields_in_any_order() -> None:
    rng = np.random.default_rng(9)
    n = 7
    order = rng.permutation(n)
    ids = (10 + order).astype(np.uint8)  # servo k has ID 10 + k
    scale = np.stack([rng.uniform(1000, 3000, n), rng.choice([-1, 1], n) * rng.uniform(5, 20, n),
                      rng.uniform(0.1, 2, n), rng.uniform(0.5, 3, n)])
    zero, tpd, dps, ma = scale
    for read_len in (4, 10):
        for alerting in (False, True):
            cur = rng.integers(-2000, 2000, n).astype("<i2")
            vel = rng.integers(-400, 400, n).astype("<i4")
            pos = rng.integers(-5000, 9000, n).astype("<i4")
            errs = np.zeros(n, np.uint8)
            if alerting:
                errs[rng.integers(n)] = 0x80
            raw = _fast_sync_reply([
                (int(errs[i]), int(ids[i]), pos[i].tobytes() if read_len == 4
                 else cur[i].tobytes() + vel[i].tobytes() + pos[i].tobytes())
                for i in range(n)])
            latest = np.full((5, n), np.nan)
            latest[3] = rng.uniform(20, 40, n)  # temperatures: kept, copied into the state
            status = np.zeros(n, np.uint8)
            stale_run = np.full(n, 3, np.int64)
            fresh = np.zeros(n, bool)
            out, out_u8 = np.full((5, n), -1.0), np.full((3, n), 7, np.uint8)
            args = (read_len, order, ids, scale, latest, status, stale_run, fresh, 12.5, out,
                    out_u8)
            alerts = codec.fast_sync_whole(raw, *args)
            assert alerts == np.count_nonzero(errs)
            np.testing.assert_allclose(latest[0, order], (pos - zero[order]) / tpd[order])
            np.testing.assert_array_equal(status[order], errs)
            assert fresh.all()
            if read_len == 10:
                np.testing.assert_allclose(latest[1, order], vel * dps[order])
                np.testing.assert_allclose(latest[2, order], cur * ma[order])
            else:
                assert np.isnan(latest[1:3]).all()
            if alerting:  # not a whole read: the caller handles the alert, no state written
                assert (out == -1.0).all() and (out_u8 == 7).all() and (stale_run == 3).all()
                assert np.isnan(latest[4]).all()
            else:
                np.testing.assert_array_equal(out[:4], latest[:4])
                assert (out[4] == 0).all() and (latest[4] == 12.5).all()
                np.testing.assert_array_equal(out_u8[0], status)
                assert (out_u8[1:] == 0).all() and (stale_run == 0).all()

            # damaged replies write nothing
            flipped = raw.copy()
            flipped[9 + 2 * (read_len + 4) + 1] ^= 0x40  # a data bit: the CRC fails
            reordered = _fast_sync_reply([(0, int(ids[i]), bytes(read_len))
                                          for i in np.roll(np.arange(n), 1)])
            refusing = _fast_sync_reply([(0x02 if i == 3 else 0, int(ids[i]), bytes(read_len))
                                         for i in range(n)])
            fresh[:] = False
            touched = (latest, status, stale_run, fresh, out, out_u8)
            for bad, code in ((flipped, codec.BAD_CRC), (raw[:-1], codec.NOT_THIS_REPLY),
                              (reordered, codec.NOT_THIS_REPLY),  # another read's order
                              (refusing, codec.ERROR_NUMBER)):
                before = [a.copy() for a in touched]
                assert codec.fast_sync_whole(bad, *args) == code
                for a, b in zip(touched, before, strict=True):
                    np.testing.assert_array_equal(a, b)


def test_fast_sync_intact_and_emulator_built_replies() -> None:
    ids = (4, 9, 2)
    datas = [b"\x01\x02\x03\x04", b"\xff\xff\xfd\x00", b"\x00\x00\x00\x80"]
    raw = dx.build_fast_read_reply([(i, 0, d) for i, d in zip(ids, datas, strict=True)])
    assert raw == fast_reply([(0, i, d) for i, d in zip(ids, datas, strict=True)])
    scratch = np.zeros(3, np.bool_)
    assert fast_sync_intact(raw, bytes(ids), 4, scratch)
    assert not fast_sync_intact(raw, bytes((9, 4, 2)), 4, scratch)  # another order
    assert not fast_sync_intact(raw[:-1], bytes(ids), 4, scratch)
    bad = bytearray(raw)
    bad[-3] ^= 1
    assert not fast_sync_intact(bytes(bad), bytes(ids), 4, scratch)
    assert codec.fast_reply_ids(raw, 4, 3) == bytes(ids)
    assert codec.fast_reply_ids(raw[:20], 4, 3) == bytes(ids[:1])
    assert codec.fast_block(raw, 1, 4) == (0, 9, datas[1])


@settings(deadline=None)  # the first example may compile the kernel
@given(st.lists(st.tuples(st.sampled_from([0, 0x80, 0x04]), st.binary(min_size=10, max_size=10)),
                min_size=1, max_size=8), st.integers(0, 200))
def test_fast_sync_take_matches_a_plain_reference(blocks: list[tuple[int, bytes]],
                                                  cut: int) -> None:
    n = len(blocks)
    ids = np.frombuffer(bytes(range(1, n + 1)), np.uint8)  # read-only, as an Order's
    order = np.arange(n)[::-1].copy()  # block i carries servo n-1-i
    raw = dx.build_fast_read_reply([(int(ids[i]), e, d) for i, (e, d) in enumerate(blocks)])
    raw = raw[: min(cut, len(raw))]
    scale = np.stack([np.full(n, 2048.0), np.full(n, 11.4), np.full(n, 1.3), np.full(n, 2.69)])
    latest = np.full((5, n), np.nan)
    status = np.zeros(n, np.uint8)
    fresh = np.zeros(n, np.bool_)
    valid = np.zeros(n, np.bool_)
    complete, taken, refused = codec.fast_sync_take(
        np.frombuffer(raw, np.uint8), 10, order, ids, scale, latest, status, fresh, valid)
    # the reference: every complete block whose running CRC checks (emulator's codec)
    want_complete = max(0, min(n, (len(raw) - 8) // 14)) if len(raw) >= 8 else 0
    assert complete == want_complete
    for i in range(complete):
        k = order[i]
        err, data = blocks[i]
        assert valid[i]
        assert status[k] == err
        if err & 0x7F:
            assert not fresh[k] and np.isnan(latest[0, k])
            continue
        cur, vel, pos = (int.from_bytes(data[a:b], "little", signed=True)
                         for a, b in ((0, 2), (2, 6), (6, 10)))
        assert fresh[k]
        assert latest[0, k] == pytest.approx((pos - 2048.0) / 11.4)
        assert latest[1, k] == pytest.approx(vel * 1.3)
        assert latest[2, k] == pytest.approx(cur * 2.69)
    assert taken == sum(1 for e, _ in blocks[:complete] if not e & 0x7F)
    assert refused == complete - taken
    assert not fresh[order[complete:]].any()


@given(st.integers(0, 252), st.sampled_from([0x01, 0x02, 0x03, 0x82, 0x83, 0x8A]),
       st.binary(max_size=40))
def test_instructions_parse_with_the_emulator_codec(servo_id: int, inst: int,
                                                    params: bytes) -> None:
    packet = build_instruction(servo_id, inst, params)
    parsed = dx.parse_instruction(packet)
    assert (parsed.id, parsed.instruction, parsed.params) == (servo_id, inst, params)


@given(st.integers(0, 252), st.integers(0, 255), st.binary(max_size=40))
def test_emulator_statuses_parse_with_the_driver_codec(servo_id: int, err: int,
                                                       params: bytes) -> None:
    s = parse_status(dx.build_status(servo_id, err, params))
    assert (s.servo_id, s.error, s.params) == (servo_id, err, params)


def test_sync_write_prefix_and_reply_length() -> None:
    prefix = codec.sync_write_prefix(116, 4, 20)
    assert prefix == bytes.fromhex("FF FF FD 00 FE") + (5 * 20 + 7).to_bytes(2, "little") + \
        bytes.fromhex("83 74 00 04 00")
    assert len(prefix) == codec.SYNC_WRITE_BODY
    assert codec.fast_reply_len(4, 20) == 168
