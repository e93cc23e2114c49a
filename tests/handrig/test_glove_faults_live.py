"""Glove faults in a live run: frames with another channel count do not end the show."""

from __future__ import annotations

import os
import threading
import time
import tty

from firmware_protocol.glove import GloveFrame, encode_frame
from handrig.app.parts import build_parts
from handrig.app.session import LiveOptions, run_live


def test_valid_frames_with_the_wrong_channel_count_are_dropped_not_fatal() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    go = threading.Event()
    stop = threading.Event()

    def glove() -> None:  # the shipped calibration reads 5 channels
        go.wait(60)
        k = 0
        while not stop.is_set():
            n = 7 if k in (100, 101) else 3 if k == 150 else 5
            frame = GloveFrame(k & 0xFFFF, k * 5000, tuple([2000] * n), (0.0, 0.0, 0.0, 1.0))
            try:
                os.write(master, encode_frame(frame))
            except OSError:
                return
            k += 1
            time.sleep(0.005)

    def log(line: str) -> None:
        if "commissioned" in line:
            go.set()

    writer = threading.Thread(target=glove, daemon=True)
    writer.start()
    try:
        result = run_live(build_parts(), LiveOptions(glove=port, bus="sim", frames=400,
                                                     log=log))
    finally:
        stop.set()
        go.set()
        writer.join(5)
        os.close(master)
        os.close(slave)
    s = result.summary
    assert "error" not in s, s.get("error")
    assert s["torque_off"] is True
    assert s["glove"]["crc_errors"] == 0 and s["glove"]["decode_errors"] == 3
