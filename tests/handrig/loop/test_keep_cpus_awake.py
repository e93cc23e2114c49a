"""Idle CPUs kept awake around each frame (``[loop] keep_cpus_awake``,
handrig/realtime.py ``CpuWake``): a CPU latency request of 0 written to
/dev/cpu_dma_latency at the warm-up before each expected frame and taken back once
the frame's Sync Write is out, so that neither the rig's wake-up on the frame nor the
bus reader's on the Sync Write waits for a halted CPU (docs/measurements.md, issue 36).

The request's side is checked on a pipe standing for the device (what is written, in
what order); what the kernel does with it is measured by ``python -m bench felt``
(``HANDRIG_BENCH_AWAKE=false,true``). A scripted clock stands for the host: the
compute-only lane.
"""

from __future__ import annotations

import contextlib
import os
import struct
from pathlib import Path

import pytest

from handrig.loop.trigger import GloveTrigger, Tick
from handrig.realtime import CpuWake, cpus_awake_around_frames
from tests.handrig.loop.test_warm_up_wake import LateWakeClock
from tests.helpers.pipe_glove import PipeGlove

AWAKE, ASLEEP = 0, 2_000_000_000


def _requests(fd: int) -> list[int]:
    """The values written to the device since the last look (4-byte native ints)."""
    try:
        data = os.read(fd, 4096)
    except BlockingIOError:
        return []
    assert len(data) % 4 == 0, data
    return [v for (v,) in struct.iter_unpack("i", data)]


@pytest.fixture
def device():
    r, w = os.pipe()
    os.set_blocking(r, False)
    yield r, w
    for fd in (r, w):
        with contextlib.suppress(OSError):
            os.close(fd)


def test_a_hold_asks_for_no_wake_up_latency_once_and_a_release_gives_it_back(device) -> None:
    r, w = device
    wake = CpuWake(w)
    wake.hold()
    wake.hold()  # held already: nothing more written
    assert _requests(r) == [AWAKE] and wake.held and wake.holds == 1
    wake.release()
    wake.release()
    assert _requests(r) == [ASLEEP] and not wake.held
    wake.hold()
    assert _requests(r) == [AWAKE] and wake.holds == 2
    wake.close()  # closing the device drops the request (the kernel's side)
    assert wake.fd is None and not wake.held
    wake.hold()
    wake.release()
    with pytest.raises(OSError):  # closed: the pipe's write end is gone
        os.fstat(w)


def test_a_write_the_device_refuses_turns_the_request_off_with_its_reason(device) -> None:
    r, w = device
    os.close(r)  # a write now fails (EPIPE)
    wake = CpuWake(w)
    wake.hold()
    assert wake.fd is None and not wake.held
    assert wake.error  # the reason kept, for whoever asks
    wake.hold()  # off: nothing is tried again
    assert wake.holds == 1


def test_without_the_device_or_switched_off_the_rig_runs_as_before(tmp_path: Path) -> None:
    said: list[str] = []
    with cpus_awake_around_frames(True, said.append, device=str(tmp_path / "none")) as wake:
        wake.hold()
        assert wake.fd is None and not wake.held
    assert said == []  # no such device (not Linux, a container): nothing to say
    target = tmp_path / "dev"
    target.write_bytes(b"")
    with cpus_awake_around_frames(False, said.append, device=str(target)) as wake:
        wake.hold()
        assert wake.fd is None
    assert target.read_bytes() == b"" and said == []
    # there but not writable (a directory stands for it: refused to root too)
    with cpus_awake_around_frames(True, said.append, device=str(tmp_path)) as wake:
        assert wake.fd is None
    assert len(said) == 1 and "cannot keep the CPUs awake" in said[0], said
    assert "keep_cpus_awake = false" in said[0]
    # said once in a process: a second hand's loop asks too
    with cpus_awake_around_frames(True, said.append, device=str(tmp_path)) as wake:
        assert wake.fd is None
    assert len(said) == 1, said


def test_the_device_is_held_for_the_block_and_closed_after_it(tmp_path: Path) -> None:
    target = tmp_path / "dev"
    target.write_bytes(b"")
    with cpus_awake_around_frames(True, None, device=str(target)) as wake:
        wake.hold()
        wake.release()
        fd = wake.fd
        assert fd is not None
    assert wake.fd is None
    with pytest.raises(OSError):
        os.fstat(fd)
    assert [v for (v,) in struct.iter_unpack("i", target.read_bytes())] == [AWAKE, ASLEEP]


@pytest.fixture
def trigger(monkeypatch: pytest.MonkeyPatch, device):
    """A glove trigger with a warm-up and a poll window, on a scripted clock (as in
    test_warm_up_wake.py), its ``_readable`` counting the looks that do not sleep."""
    import handrig.loop.trigger as trigger_module

    clock = LateWakeClock()
    glove = PipeGlove(clock)
    real_readable = trigger_module._readable
    looks = {"polls": 0}

    def readable(fd: int, timeout_s: float) -> bool:
        got = real_readable(fd, 0.0)
        if timeout_s > 0.0 and not got:
            clock.t += timeout_s
        elif timeout_s <= 0.0:
            looks["polls"] += 1
        return got

    monkeypatch.setattr(trigger_module, "_readable", readable)
    trig = GloveTrigger(clock, glove, floor_hz=5.0, ceiling_hz=1000.0, poll_s=150e-6,
                        warm_up_s=150e-6)
    trig.warm_up.rehearse_with(lambda: None)
    yield trig, clock, looks, device
    glove.close()


def _idle_wait_for(trig: GloveTrigger, clock: LateWakeClock, frame_s: float) -> None:
    trig._anchor, trig.frame_period_s = frame_s - 0.005, 0.005
    trig._idle_wait(trig.glove.fileno(), frame_s + 0.001, frame_s + 0.001 - clock.t)


def test_the_trigger_holds_from_the_warm_up_until_the_write_is_out_and_then_sleeps(
        trigger) -> None:
    trig, clock, looks, (r, w) = trigger
    # without the request (not given, or refused): the poll window looks at the port
    _idle_wait_for(trig, clock, clock.t + 0.005)
    assert looks["polls"] > 0
    assert _requests(r) == []
    trig.keep_awake(CpuWake(w))
    looks["polls"] = 0
    frame = clock.t + 0.005
    _idle_wait_for(trig, clock, frame)
    # held from the warm-up on; the CPUs awake, the frame is slept for (a wake-up is
    # quick), not polled for
    assert _requests(r) == [AWAKE]
    assert looks["polls"] == 0
    assert trig.warm_up.keep_awake.held
    # the frame's write is out: the read schedule settles the tick, the CPUs may halt
    trig.settle(Tick())
    assert _requests(r) == [ASLEEP]
    # the next wait releases it too (a cycle that did not settle), and holds again at
    # the next frame's warm-up
    trig.warm_up.keep_awake.hold()
    assert _requests(r) == [AWAKE]
    trig.wait(Tick())
    assert _requests(r)[0] == ASLEEP
