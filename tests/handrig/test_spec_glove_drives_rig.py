"""A glove written from firmware_protocol/SPEC.md alone drives the rig.

The C code blocks of SPEC.md are compiled with a small firmware ``main`` that
closes the index and little fingers over two seconds, sending frames at 200 Hz
into a pty; the live rig reads that pty and the simulated puppet's index MCP
must follow.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.app.session import LiveOptions, run_live

FIRMWARE = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>
int main(int argc, char **argv) {
    int fd = atoi(argv[1]);
    uint8_t wire[GLOVE_MAX_WIRE];
    const int16_t palm_down[] = {0, 0, 0, 16384};
    if (getchar() == EOF) return 2;  /* start when the host says go */
    for (uint32_t k = 0; k < 700; k++) {
        uint32_t ramp = k < 100 ? 0 : (k > 500 ? 400 : k - 100);
        uint16_t v = (uint16_t)(1000 + ramp * 2200 / 400);   /* open -> closed */
        uint16_t ch[5] = {2000, 2100, 2000, v, v};
        size_t n = glove_frame_build(wire, (uint16_t)k, k * 5000u, 0, 5, ch, palm_down);
        if (write(fd, wire, n) < 0) return 1;
        const struct timespec period = {0, 5000000L};  /* 200 Hz */
        nanosleep(&period, NULL);
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def firmware(build_spec_c) -> Path:
    return build_spec_c(FIRMWARE, "fw", posix=True)


def test_a_spec_only_glove_drives_the_puppet(firmware: Path):
    master, slave = os.openpty()
    import tty

    tty.setraw(slave)
    port = os.ttyname(slave)
    proc = subprocess.Popen([str(firmware), str(master)], pass_fds=(master,),
                            stdin=subprocess.PIPE)

    def go_when_commissioned(line: str) -> None:
        if "commissioned" in line and proc.stdin is not None:
            proc.stdin.write(b"g")  # the servos are about to hold: start the glove
            proc.stdin.flush()

    try:
        parts = build_parts()
        result = run_live(parts, LiveOptions(glove=port, bus="sim", frames=700,
                                             snapshot_every=20, log=go_when_commissioned))
    finally:
        proc.kill()
        proc.wait()
        os.close(master)
        os.close(slave)
    s = result.summary
    assert s["torque_off"] is True
    assert s["glove"]["frames_ok"] > 500 and s["glove"]["crc_errors"] == 0
    idx = result.joint_names.index("riIndexMCPy")
    positions = np.array([snap[idx] for snap in result.snapshots])  # every 20 cycles
    # the glove holds the hand open for its first 100 frames, then closes it to a fist by
    # frame 600: the puppet opens (under 20 deg), and later makes the fist (over 65 deg).
    # Found in the snapshots, not at fixed cycles: a loaded machine can start the glove's
    # process late, and the loop's first cycles then have no frame yet (a CI run beside a
    # busy core: still 46 deg at cycles 40-100). The relaxed pose the run ends in has the
    # joint near 50 deg, so neither figure comes from it.
    seen = (positions.round(1).tolist(), s["events"], s["glove"], s["bus"]["timeouts"])
    opened = np.flatnonzero(positions < 20.0)
    assert opened.size, seen
    assert (positions[opened[0]:] > 65.0).any(), seen
