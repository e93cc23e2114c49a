"""The glove reader under random and mutated bytes (hypothesis).

Streams are built from valid frames (the glove's 5 channels, sometimes another
count), mutated frames (bit flips, cuts, lost or doubled delimiters, inserted
bytes) and random garbage, cut into random read sizes, and fed to
:meth:`SerialGlove.feed`. Properties: nothing raises; every sample has the settled
channel count, raw values in 0..65535, a finite quaternion or none, one button
byte, and calibrates to controls inside each channel's degree range; after
garbage that ends in a zero byte the next valid frame comes out (resync within
one frame).

Size: ``HANDRIG_FUZZ=full`` runs enough examples for at least 10**6 bytes (the
volume test checks the count); by default a twentieth of that.
"""

from __future__ import annotations

import os

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_protocol.glove import MAX_CHANNELS, GloveFrame, encode_frame
from handrig.clock import FakeClock
from handrig.devices.glove import LOCK_FRAMES, SerialGlove
from handrig.devices.glove_calibration import GloveCalibration, load_glove_config

FULL = os.environ.get("HANDRIG_FUZZ") == "full"
TARGET_BYTES = 10**6
EXAMPLES = 600 if FULL else 30  # streams average about 2 kB
CHANNELS = 5
FED = {"bytes": 0, "streams": 0, "samples": 0}

CAL = GloveCalibration.from_config(load_glove_config())
LOW = np.minimum([c.open_deg for c in CAL.channels], [c.closed_deg for c in CAL.channels])
HIGH = np.maximum([c.open_deg for c in CAL.channels], [c.closed_deg for c in CAL.channels])

u16 = st.integers(0, 0xFFFF)
quat = st.one_of(st.none(), st.tuples(*[st.floats(-1.99, 1.99)] * 4))


@st.composite
def frames(draw: st.DrawFn, n: int | None = None) -> bytes:
    count = draw(st.sampled_from([CHANNELS] * 6 + list(range(MAX_CHANNELS + 1)))) if n is None \
        else n
    return encode_frame(GloveFrame(
        draw(u16), draw(st.integers(0, 2**32 - 1)), tuple(draw(u16) for _ in range(count)),
        draw(quat), draw(st.integers(0, 0xFF))))


@st.composite
def mutated(draw: st.DrawFn) -> bytes:
    b = bytearray(draw(frames()))
    kind = draw(st.sampled_from(["flip", "cut", "no_zero", "double_zero", "insert", "swap"]))
    if kind == "flip":
        for _ in range(draw(st.integers(1, 4))):
            b[draw(st.integers(0, len(b) - 1))] ^= 1 << draw(st.integers(0, 7))
    elif kind == "cut":
        b = b[: draw(st.integers(0, len(b) - 1))]
    elif kind == "no_zero":
        b = b[:-1]
    elif kind == "double_zero":
        b.insert(draw(st.integers(0, len(b))), 0)
    elif kind == "insert":
        b[draw(st.integers(0, len(b))):0] = draw(st.binary(min_size=1, max_size=8))
    else:
        i = draw(st.integers(0, len(b) - 2))
        b[i], b[i + 1] = b[i + 1], b[i]
    return bytes(b)


piece = st.one_of(frames(), mutated(), mutated(), st.binary(min_size=1, max_size=200))


def _glove() -> SerialGlove:
    glove = SerialGlove("fuzz", "frames", clock=FakeClock(), reader="poll")
    for seq in range(LOCK_FRAMES):  # settle the channel count as a real glove does
        glove.feed(encode_frame(GloveFrame(seq, 0, (2000,) * CHANNELS)), 0.0)
    assert glove.latest() is not None and glove.stats().expected_channels == CHANNELS
    return glove


def _check_sample(glove: SerialGlove, out: np.ndarray) -> None:
    s = glove.latest()
    if s is None:
        return
    FED["samples"] += 1
    assert s.raw.shape == (CHANNELS,) and s.raw.dtype == np.float64
    assert np.all((s.raw >= 0) & (s.raw <= 0xFFFF)) and np.all(s.raw == np.round(s.raw))
    assert s.quat is None or (s.quat.shape == (4,) and np.all(np.abs(s.quat) <= 2.0))
    assert 0 <= s.buttons <= 0xFF and s.estop == bool(s.buttons & 1)
    CAL.calibrate(s.raw, out)
    assert np.all(np.isfinite(out)) and np.all((out >= LOW) & (out <= HIGH))


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.data_too_large])
@given(pieces=st.lists(piece, min_size=40, max_size=150),
       cuts=st.lists(st.integers(1, 600), min_size=1, max_size=20),
       garbage=st.binary(max_size=300), last=frames(CHANNELS))
def test_random_and_mutated_bytes_never_escape_and_resync_in_one_frame(
        pieces: list[bytes], cuts: list[int], garbage: bytes, last: bytes) -> None:
    glove = _glove()
    out = np.empty(len(CAL))
    stream = b"".join(pieces)
    i, k = 0, 0
    while i < len(stream):  # reads of random sizes, as a serial port returns them
        n = cuts[k % len(cuts)]
        glove.feed(stream[i: i + n], 0.0)
        _check_sample(glove, out)
        i, k = i + n, k + 1
    glove.feed(garbage + b"\x00", 0.0)
    _check_sample(glove, out)
    glove.feed(last, 0.0)  # the first valid frame after the zero comes out
    s = glove.latest()
    assert s is not None and s.raw.tolist() == list(last_channels(last))
    FED["bytes"] += len(stream) + len(garbage) + 1 + len(last)
    FED["streams"] += 1


def last_channels(wire: bytes) -> tuple[int, ...]:
    from firmware_protocol.glove import decode_frame

    return decode_frame(wire[:-1]).channels


def test_fuzz_volume() -> None:
    """Runs after the property test (file order): how much it fed."""
    print(f"glove fuzz: {FED['bytes']} bytes in {FED['streams']} streams,"
          f" {FED['samples']} samples checked")
    if FULL:
        assert FED["bytes"] >= TARGET_BYTES, FED
