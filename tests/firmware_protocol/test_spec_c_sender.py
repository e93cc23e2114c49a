"""The C in SPEC.md, compiled as a firmware author would use it, produces the golden
bytes and a stream the host decodes: the spec alone is enough to write a glove."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from firmware_protocol.glove import FrameDecoder, GloveFrame

SPEC = Path(__file__).resolve().parents[2] / "firmware_protocol" / "SPEC.md"

MAIN = r"""
#include <stdio.h>
static void show(const uint8_t *w, size_t n) {
    for (size_t i = 0; i < n; i++) printf(i ? " %02x" : "%02x", w[i]);
    printf("\n");
}
int main(int argc, char **argv) {
    uint8_t wire[GLOVE_MAX_WIRE];
    const uint16_t c1[] = {2048, 1024, 3072, 500, 3500};
    const int16_t q1[] = {0, 0, 0, 16384};
    show(wire, glove_frame_build(wire, 1, 1000, 0, 5, c1, q1));
    const uint16_t c2[] = {0, 65535, 256};
    show(wire, glove_frame_build(wire, 65535, 4294967000u, 1, 3, c2, NULL));
    const uint16_t c3[] = {1000, 2000, 3000, 100, 4095};
    const int16_t q3[] = {8192, -8192, 8192, 8192};
    show(wire, glove_frame_build(wire, 42, 123456789u, 5, 5, c3, q3));
    if (argc > 1) {  /* a stream: 300 frames with a 16-channel ramp, binary on stdout */
        for (uint32_t k = 0; k < 300; k++) {
            uint16_t ch[16];
            for (int i = 0; i < 16; i++) ch[i] = (uint16_t)(k * 200 + i);
            size_t n = glove_frame_build(wire, (uint16_t)(65500 + k), k * 5000u,
                                         (uint8_t)(k & 1), (uint8_t)(k % 17), ch, NULL);
            fwrite(wire, 1, n, stdout);
        }
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def sender(build_spec_c) -> Path:
    return build_spec_c(MAIN, "glove")


def test_the_c_sender_writes_the_golden_bytes(sender: Path) -> None:
    lines = subprocess.run([str(sender)], check=True, capture_output=True,
                           text=True).stdout.splitlines()
    spec = re.sub(r"\s+", " ", SPEC.read_text())
    assert len(lines) == 3
    for line in lines:
        assert f"wire {line}" in spec


def test_the_host_decodes_a_c_stream(sender: Path) -> None:
    out = subprocess.run([str(sender), "stream"], check=True, capture_output=True).stdout
    stream = out[out.index(b"\n", out.index(b"\n", out.index(b"\n") + 1) + 1) + 1:]
    dec = FrameDecoder()
    frames: list[GloveFrame] = dec.feed(stream)
    assert len(frames) == 300 and dec.stats.errors == 0 and dec.stats.seq_gaps == 0
    k = 123
    f = frames[k]
    assert f.seq == (65500 + k) % 65536 and f.timestamp_us == k * 5000
    assert f.channels == tuple((k * 200 + i) % 65536 for i in range(k % 17))
    assert f.relax == bool(k & 1) and f.quat_xyzw is None
