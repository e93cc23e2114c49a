"""Whether the servo port still drains, judged long before its buffer is full (issue 24.4).

On a real pty pair: the fact the pty rule rests on (TIOCOUTQ on a pty slave reads 0
whatever the other side has not read), the answer rule a pty is judged by, and the
queue rule of a serial driver that reports its queue, with the driver's queue
scripted by a subclass (no USB adapter on the test machine: its TIOCOUTQ is what
``SerialTransport._output_queue`` reads).
"""

from __future__ import annotations

import fcntl
import os
import select
import struct
import termios
import time
import tty
from collections.abc import Iterator

import pytest

from handrig.clock import FakeClock
from handrig.devices.servo.transport import (
    ANSWER_STALL_S,
    DRAIN_CHUNK_BYTES,
    DRAIN_STALL_S,
    UNANSWERED_WEDGED,
    SerialTransport,
)
from handrig.devices.servo.wire import wire_time_s
from handrig.errors import DeviceTimeoutError

BAUD = 1_000_000
GOALS = bytes(114)  # a goal Sync Write to 20 servos


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    try:
        yield master, os.ttyname(slave)
    finally:
        os.close(slave)
        os.close(master)


def test_a_pty_slave_reports_no_output_queue_whatever_is_unread(
        pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    try:
        for _ in range(20):
            os.write(fd, GOALS)
        unread = 0
        end = time.monotonic() + 5.0  # the kernel hands the bytes over in a worker
        while unread < 20 * len(GOALS) and time.monotonic() < end:
            select.select([master], [], [], 0.05)
            unread = struct.unpack("i", fcntl.ioctl(master, termios.FIONREAD, bytes(4)))[0]
        queued = struct.unpack("i", fcntl.ioctl(fd, termios.TIOCOUTQ, bytes(4)))[0]
    finally:
        os.close(fd)
    assert unread == 20 * len(GOALS)  # waiting at the other side, never read
    assert queued == 0  # and the slave cannot see it: answers are a pty's only sign


def _reply(master: int, t: SerialTransport) -> None:
    os.write(master, b"\xff\xff\xfd\x00")
    assert len(t.read_exact(4, t.clock.now() + 1.0, answer=True)) == 4


def _unanswered_reads(t: SerialTransport, clock: FakeClock, n: int) -> None:
    for _ in range(n):
        assert t.read_exact(7, clock.now() + 0.005, answer=True) == b""


def test_a_pty_that_answers_no_state_read_for_the_stall_time_is_wedged(
        pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    clock = FakeClock(10.0)
    t = SerialTransport(path, BAUD, clock)
    t.open()
    try:
        assert t.pty
        t.judge_answers(True)
        _reply(master, t)
        _unanswered_reads(t, clock, UNANSWERED_WEDGED)
        clock.advance(ANSWER_STALL_S - 0.05)
        t.write(GOALS)  # quiet, but not yet for the stall time
        clock.advance(0.1)
        with pytest.raises(DeviceTimeoutError, match=f"{path} answered none.*stopped draining"):
            t.write(GOALS)
        assert t.wedged
    finally:
        t.close()


def test_a_pty_is_not_judged_by_answers_while_judging_is_off_or_after_an_answer(
        pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    clock = FakeClock(10.0)
    t = SerialTransport(path, BAUD, clock)
    t.open()
    try:
        _reply(master, t)
        _unanswered_reads(t, clock, UNANSWERED_WEDGED)
        clock.advance(2.0)
        t.write(GOALS)  # commissioning (judging off): a missing servo is no wedge
        t.judge_answers(True)
        _unanswered_reads(t, clock, UNANSWERED_WEDGED - 1)
        clock.advance(2.0)
        t.write(GOALS)  # fewer unanswered reads than it takes
        _reply(master, t)  # an answer: draining
        _unanswered_reads(t, clock, 1)
        t.write(GOALS)
        assert not t.wedged
    finally:
        t.close()


class ScriptedQueue(SerialTransport):
    """A serial port whose driver reports ``queue`` as its output queue (TIOCOUTQ)."""

    queue = 0

    def open(self) -> None:
        super().open()
        self.pty = False  # judged by its queue, as a USB serial port

    def _output_queue(self) -> int | None:
        return self.queue


def _drain(master: int) -> None:
    """The pty's other side reads what came (the scripted queue is what is judged)."""
    while select.select([master], [], [], 0)[0]:
        os.read(master, 65536)


def test_a_queue_that_stops_shrinking_is_wedged_within_the_stall_time(
        pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    clock = FakeClock(0.0)
    t = ScriptedQueue(path, BAUD, clock)
    t.open()
    allowed = DRAIN_STALL_S + wire_time_s(DRAIN_CHUNK_BYTES, BAUD)
    try:
        # draining: the queue shrinks between writes, for longer than the stall time
        for _ in range(100):
            t.queue = 300
            t.write(GOALS)
            _drain(master)
            clock.advance(0.005)
        # wedged: every write's bytes stay queued
        stalled = clock.now()
        with pytest.raises(DeviceTimeoutError,
                           match=f"{path} drained none of its .* queued bytes.*unplug"):
            while clock.now() - stalled < 1.0:
                t.queue += len(GOALS)
                t.write(GOALS)
                _drain(master)
                clock.advance(0.005)
        assert t.wedged
        assert allowed - 0.01 < clock.now() - stalled <= allowed + 0.01  # a write apart
    finally:
        t.close()


def test_a_write_after_an_idle_port_starts_the_stall_clock_afresh(
        pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    clock = FakeClock(0.0)
    t = ScriptedQueue(path, BAUD, clock)
    t.open()
    try:
        t.write(GOALS)  # drained at once
        clock.advance(5.0)  # nothing written for a while (commissioning, a pause)
        t.queue = len(GOALS)  # the new write is still queued when looked at
        t.write(GOALS)
        _drain(master)
        clock.advance(DRAIN_STALL_S / 2)
        t.queue = 2 * len(GOALS)
        t.write(GOALS)
        _drain(master)
        assert not t.wedged
    finally:
        t.close()


def test_an_empty_queue_is_never_wedged(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    clock = FakeClock(0.0)
    t = ScriptedQueue(path, BAUD, clock)
    t.open()
    try:
        for _ in range(400):  # 2 s of goals, each drained before the next
            t.write(GOALS)
            _drain(master)
            clock.advance(0.005)
        assert not t.wedged
    finally:
        t.close()
