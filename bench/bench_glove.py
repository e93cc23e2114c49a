"""Glove input cost: decoding, calibration and filtering per frame, and the time from a
frame's last byte read to the sample being visible to the loop (over a real pty)."""

from __future__ import annotations

import time
import timeit

import numpy as np

from firmware_protocol.glove import FrameDecoder, GloveFrame, decode_frame, encode_frame
from firmware_protocol.opengloves import LineDecoder, OpenGlovesLine, encode_line
from handrig.clock import MonotonicClock
from handrig.filters import OneEuroFilter
from handrig.glove import SerialGlove
from handrig.glove_calibration import GloveControls, load_glove_config
from handrig.glove_recording import sweep_recording
from sim.glove_emulator import GloveEmulator


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

    # last byte read -> sample visible to latest(), over a pty, glove at 200 Hz
    clock = MonotonicClock()
    rec = sweep_recording(3.0, 200.0, 5)
    delays = []
    with GloveEmulator(rec, "frames") as emu, \
            SerialGlove(emu.port_path, "frames", clock=clock) as glove:
        end = time.perf_counter() + 2.5
        while time.perf_counter() < end:
            s = glove.latest()
            if s is not None:
                delays.append(clock.now() - s.host_time_s)
        st = glove.stats()
    d = np.array(delays[5:]) * 1e6
    print(f"read -> visible to latest() over a pty (n={d.size}, busy-polling loop): "
          f"p50 {np.percentile(d, 50):.1f} us, p99 {np.percentile(d, 99):.1f} us "
          f"(frames {st.frames_ok}, errors {st.errors})")
