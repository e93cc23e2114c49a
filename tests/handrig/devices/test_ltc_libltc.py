"""handrig's LTC against libltc's (Debian's libltc11, `make ltc-deps`; skipped without
it): libltc's encoder read by handrig's decoder, handrig's encoder read by libltc's
decoder, frame for frame."""

from __future__ import annotations

import ctypes
import ctypes.util

import numpy as np
import pytest

from handrig.devices.timecode.ltc import RATES, LtcDecoder, Timecode, unpack
from handrig.devices.timecode.ltc_encode import Segment, render

SR = 48000
_NAME = ctypes.util.find_library("ltc")
pytestmark = pytest.mark.skipif(_NAME is None, reason="libltc not installed (make ltc-deps)")
TV_STANDARD = {"24": 3, "25": 1, "29.97": 0, "30": 0}  # enum LTC_TV_STANDARD


class SMPTETimecode(ctypes.Structure):
    _fields_ = [("timezone", ctypes.c_char * 6), ("years", ctypes.c_ubyte),
                ("months", ctypes.c_ubyte), ("days", ctypes.c_ubyte),
                ("hours", ctypes.c_ubyte), ("mins", ctypes.c_ubyte),
                ("secs", ctypes.c_ubyte), ("frame", ctypes.c_ubyte)]


def _lib() -> ctypes.CDLL:
    assert _NAME is not None
    lib = ctypes.CDLL(_NAME)
    lib.ltc_encoder_create.restype = ctypes.c_void_p
    lib.ltc_encoder_create.argtypes = [ctypes.c_double, ctypes.c_double, ctypes.c_int,
                                       ctypes.c_int]
    for name in ("ltc_encoder_set_timecode", "ltc_encoder_get_buffer"):
        getattr(lib, name).argtypes = [ctypes.c_void_p, ctypes.c_void_p]
    for name in ("ltc_encoder_encode_frame", "ltc_encoder_inc_timecode", "ltc_encoder_free",
                 "ltc_decoder_free"):
        getattr(lib, name).argtypes = [ctypes.c_void_p]
    lib.ltc_decoder_create.restype = ctypes.c_void_p
    lib.ltc_decoder_create.argtypes = [ctypes.c_int, ctypes.c_int]
    lib.ltc_decoder_write_float.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t,
                                            ctypes.c_longlong]
    lib.ltc_decoder_read.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
    return lib


def libltc_encode(label: str, start: Timecode, frames: int) -> np.ndarray:
    lib = _lib()
    fps = RATES[label]
    enc = lib.ltc_encoder_create(SR, float(fps.rate) if fps.drop else fps.nominal,
                                 TV_STANDARD[label], 0)
    tc = SMPTETimecode(b"+0000", 0, 0, 0, start.hours, start.minutes, start.seconds,
                       start.frames)
    lib.ltc_encoder_set_timecode(enc, ctypes.byref(tc))
    buf = (ctypes.c_ubyte * 8192)()
    chunks = []
    for _ in range(frames + 1):  # one more: the last frame's closing edge
        lib.ltc_encoder_encode_frame(enc)
        n = lib.ltc_encoder_get_buffer(enc, buf)
        chunks.append(np.frombuffer(bytes(buf[:n]), dtype=np.uint8).copy())
        lib.ltc_encoder_inc_timecode(enc)
    lib.ltc_encoder_free(enc)
    return (np.concatenate(chunks).astype(np.float32) - 128.0) / 128.0


@pytest.mark.parametrize("label", list(RATES))
def test_handrig_reads_every_frame_libltc_writes(label: str) -> None:
    fps = RATES[label]
    start = Timecode(0, 9, 59, 25, True) if fps.drop else Timecode(1, 0, 0, 0)
    samples = libltc_encode(label, start, 50)
    d = LtcDecoder(SR)
    got = []
    for i in range(0, samples.size, 480):
        got += [f.timecode for f in d.feed(samples[i:i + 480])]
    n0 = start.frame_number(fps.nominal)
    assert got == [Timecode.from_frame_number(n0 + k, fps) for k in range(50)]


@pytest.mark.parametrize("label", list(RATES))
def test_libltc_reads_every_frame_handrig_writes(label: str) -> None:
    lib = _lib()
    fps = RATES[label]
    start = Timecode(0, 9, 59, 25, True) if fps.drop else Timecode(23, 59, 59, 0)
    r = render([Segment(start, 50, fps, 1.0)], SR)
    dec = lib.ltc_decoder_create(int(SR / fps.rate_hz), 64)
    x = np.ascontiguousarray(r.samples, dtype=np.float32)
    lib.ltc_decoder_write_float(dec, x.ctypes.data, x.size, 0)
    ext = (ctypes.c_ubyte * 2048)()  # an LTCFrameExt: its LTCFrame (80 bits) first
    words = []
    while lib.ltc_decoder_read(dec, ext):
        words.append(int.from_bytes(bytes(ext[:10]), "little"))
    lib.ltc_decoder_free(dec)
    got = [d[0] if d else None for d in (unpack(w) for w in words)]
    # libltc's decoder learns the bit period on the first frame it hears and may drop it
    assert len(got) >= len(r.timecodes) - 1
    assert got == list(r.timecodes)[len(r.timecodes) - len(got):]
