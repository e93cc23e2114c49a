"""A glove port is one reader's: opened exclusively, and a busy port is reported as busy,
in-process and between real processes (a second ``handrig run`` on the same glove)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable

import pytest

from handrig.clock import MonotonicClock
from handrig.devices.glove import SerialGlove
from handrig.devices.glove_recording import read_glove_recording
from handrig.errors import DeviceError
from sim.demo_recording import DEMO_RECORDING
from sim.glove_emulator import GloveEmulator

CLI = [sys.executable, "-m", "handrig.cli"]


def _wait_for(cond: Callable[[], bool], timeout_s: float = 5.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


@pytest.mark.parametrize("reader", ["thread", "poll"])
def test_a_second_reader_is_refused_and_the_first_keeps_every_frame(reader: str) -> None:
    rec = read_glove_recording(DEMO_RECORDING)
    with GloveEmulator(rec, "frames", rate_hz=200.0, loop=True) as emu:
        first = SerialGlove(emu.port_path, clock=MonotonicClock(),
                            reader="poll" if reader == "poll" else "thread")
        with first:
            second = SerialGlove(emu.port_path, clock=MonotonicClock())
            with pytest.raises(DeviceError) as err:
                second.start()
            assert str(err.value).startswith(f"glove port {emu.port_path} is busy: another"
                                             " program")
            assert "close that one first" in str(err.value)

            def enough() -> bool:
                first.latest()  # the poll reader reads here
                return first.stats().frames_ok >= 100

            assert _wait_for(enough)
            stats = first.stats()
            assert stats.seq_gaps == 0 and stats.frames_lost == 0 and stats.errors == 0
        # once the first has let go, the port is free again
        with second:
            assert _wait_for(lambda: (second.latest(), second.stats().frames_ok)[1] >= 5)


def test_a_second_handrig_run_on_a_busy_glove_says_so_before_torque(tmp_path) -> None:
    rec = read_glove_recording(DEMO_RECORDING)
    with GloveEmulator(rec, "frames", rate_hz=200.0, loop=True) as emu:
        holder = subprocess.Popen(
            [sys.executable, "-c",
             "import sys, time\n"
             "from handrig.clock import MonotonicClock\n"
             "from handrig.devices.glove import SerialGlove\n"
             f"g = SerialGlove({emu.port_path!r}, clock=MonotonicClock())\n"
             "g.start()\nprint('open', flush=True)\nsys.stdin.read()\n"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        try:
            assert holder.stdout is not None and holder.stdout.readline().strip() == "open"
            out = subprocess.run([*CLI, "run", "--glove", emu.port_path, "--bus", "sim",
                                  "--seconds", "2", "--json"],
                                 capture_output=True, text=True, timeout=180)
        finally:
            holder.kill()
            holder.wait()
    assert out.returncode == 2, out.stderr
    summary = json.loads(out.stdout)
    assert summary["error"].startswith(f"glove port {emu.port_path} is busy")
    assert f"handrig: error: glove port {emu.port_path} is busy" in out.stderr
    assert summary["torque_off"] is None and summary["frames"] == 0  # torque never went on
    assert "commissioned" not in out.stderr  # the glove is opened before the servos are set
