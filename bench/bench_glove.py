"""Glove input cost: decoding, calibration and filtering per frame, and the time from a
frame's last byte read to the sample being visible to the loop (over a real pty)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import timeit
from pathlib import Path

import numpy as np

from firmware_protocol.glove import FrameDecoder, GloveFrame, decode_frame, encode_frame
from firmware_protocol.opengloves import LineDecoder, OpenGlovesLine, encode_line
from handrig.clock import MonotonicClock
from handrig.devices.glove import SerialGlove
from handrig.devices.glove_calibration import GloveControls, load_glove_config
from handrig.devices.glove_recording import sweep_recording, write_glove_recording
from handrig.pose.filters import OneEuroFilter


def _per_call_us(fn: object, number: int) -> float:
    runs = timeit.repeat(fn, number=number, repeat=5)  # type: ignore[arg-type]
    return min(runs) / number * 1e6


def main() -> None:
    frame = GloveFrame(1, 1000, (2048, 1024, 3072, 500, 3500), (0.0, 0.0, 0.0, 1.0), 0)
    wire = encode_frame(frame)
    dec = FrameDecoder()
    n = 20_000
    print(f"frame decode (COBS + CRC + unpack, 5 channels): "
          f"{_per_call_us(lambda: decode_frame(wire[:-1]), n):.2f} us")
    print(f"FrameDecoder.feed, one whole frame per chunk:   "
          f"{_per_call_us(lambda: dec.feed(wire), n):.2f} us")
    chunk = wire * 10
    print(f"FrameDecoder.feed, 10 frames per chunk:         "
          f"{_per_call_us(lambda: dec.feed(chunk), n // 10) / 10:.2f} us per frame")
    line = encode_line(OpenGlovesLine((100, 2000, 3000, 4000, 4095), (2048, 2048), 0))
    ldec = LineDecoder(4095)
    print(f"OpenGloves LineDecoder.feed, one line:          "
          f"{_per_call_us(lambda: ldec.feed(line), n):.2f} us")

    ctl = GloveControls.from_config(load_glove_config(), ("riThumbCMCx", "riThumbCMCy",
                                    "riThumbCMCz", "riIndexMCPy", "riPinkyMCPy"))
    raw = np.array([2000.0, 2100.0, 1900.0, 2500.0, 1500.0])
    out = np.empty(5)
    t = [0.0]

    def step() -> None:
        t[0] += 0.005
        ctl(raw, t[0], out)

    print(f"GloveControls (calibrate + One Euro + reorder): {_per_call_us(step, n):.2f} us")
    f = OneEuroFilter(5, 1.0, 0.02)
    t2 = [0.0]

    def fstep() -> None:
        t2[0] += 0.005
        f(raw, t2[0], out)

    print(f"OneEuroFilter step, 5 channels:                 {_per_call_us(fstep, n):.2f} us")

    cal = ctl.calibration
    print(f"GloveCalibration.calibrate, 5 channels:         "
          f"{_per_call_us(lambda: cal.calibrate(raw, out), n):.2f} us")

    # A 200 Hz loop (MonotonicClock.sleep_until) takes the newest sample each cycle; the
    # glove emulator streams at 200 Hz over a pty from another process (as a USB glove
    # would: no GIL shared with it). "age" = now - host_time_s when the loop picks a
    # sample up; "latest() cost" = time spent inside latest() on cycles that got one.
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sweep.csv"
        write_glove_recording(path, sweep_recording(5.0, 200.0, 5))
        for reader in ("thread", "poll"):
            _loop_figures(path, reader)


def _loop_figures(path: Path, reader: str) -> None:
    code = ("import sys\n"
            "from handrig.devices.glove_recording import read_glove_recording\n"
            "from sim.glove_emulator import GloveEmulator\n"
            "with GloveEmulator(read_glove_recording(sys.argv[1])) as e:\n"
            "    print(e.port_path, flush=True)\n"
            "    e.done.wait(30)\n")
    proc = subprocess.Popen([sys.executable, "-c", code, str(path)], stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout is not None
        port = proc.stdout.readline().strip()
        clock = MonotonicClock()
        ages, costs = [], []
        with SerialGlove(port, "frames", clock=clock, reader=reader) as glove:  # type: ignore[arg-type]
            period = 1 / 200.0
            t0 = clock.now() + 0.1
            for k in range(700):
                clock.sleep_until(t0 + k * period)
                a = clock.now()
                s = glove.latest()
                b = clock.now()
                if s is not None:
                    ages.append(b - s.host_time_s)
                    costs.append(b - a)
            st = glove.stats()
    finally:
        proc.kill()
        proc.wait()
    age = np.array(ages[10:]) * 1e6
    cost = np.array(costs[10:]) * 1e6
    print(f"200 Hz loop, reader={reader:<6}: latest() cost p50 {np.percentile(cost, 50):.1f}"
          f" us, p99 {np.percentile(cost, 99):.1f} us; sample age at pickup p50 "
          f"{np.percentile(age, 50):.0f} us, p99 {np.percentile(age, 99):.0f} us "
          f"(samples {len(ages)}, frames {st.frames_ok}, errors {st.errors})")
