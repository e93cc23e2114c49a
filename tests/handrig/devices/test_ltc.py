"""The LTC codec and reader: timecode numbering, the codeword, the decoder on every rate
(drift, jumps, stops, varispeed, noise, either polarity), the reader's fixes and
position against the known signal, on a fake clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from handrig.clock import FakeClock
from handrig.devices.timecode.audio import WavAudio, open_audio
from handrig.devices.timecode.ltc import (
    RATES,
    SYNC_WORD,
    LtcDecoder,
    LtcFrame,
    Timecode,
    frame_rate,
    pack,
    unpack,
)
from handrig.devices.timecode.ltc_encode import Rendered, Segment, render, write_wav
from handrig.devices.timecode.reader import LtcReader, TimecodeFix
from handrig.errors import ConfigError, DataError

SR = 48000


def decode(samples: np.ndarray, block: int = 480, **kw: object) -> list[LtcFrame]:
    d = LtcDecoder(SR, **kw)  # type: ignore[arg-type]
    out: list[LtcFrame] = []
    for i in range(0, samples.size, block):
        out += d.feed(samples[i:i + block])
    return out


def test_drop_frame_numbering_skips_two_numbers_a_minute_but_each_tenth() -> None:
    df = RATES["29.97"]
    assert str(Timecode.from_frame_number(1800, df)) == "00:01:00;02"
    assert str(Timecode.from_frame_number(1799, df)) == "00:00:59;29"
    assert str(Timecode.from_frame_number(17982, df)) == "00:10:00;00"
    for n in range(0, 30 * 60 * 12, 7):
        assert Timecode.from_frame_number(n, df).frame_number(30) == n
    assert Timecode.from_frame_number(0, df) == Timecode(0, 0, 0, 0, True)
    # a day of drop-frame: 24 h less 108 frames an hour
    assert Timecode(24, 0, 0, 0, True).frame_number(30) == 24 * 3600 * 30 - 24 * 108


def test_codeword_round_trips_and_keeps_an_even_count_of_zeros() -> None:
    for tc, fps25 in ((Timecode(23, 59, 59, 24), True), (Timecode(1, 2, 3, 4), False),
                      (Timecode(12, 34, 56, 29, True), False)):
        w = pack(tc, user_bits=0x89ABCDEF, fps25=fps25)
        assert (w >> 64) == SYNC_WORD
        assert (80 - bin(w).count("1")) % 2 == 0
        assert unpack(w) == (tc, 0x89ABCDEF)
    assert unpack(pack(Timecode(1, 0, 0, 0)) | 0xA) is None  # frame units 10: not BCD


def test_bad_timecodes_and_rates_name_the_key() -> None:
    with pytest.raises(ConfigError, match=r"start.*HH:MM:SS:FF"):
        Timecode.parse("1:00:00", key="start")
    with pytest.raises(ConfigError, match=r"fps.*24, 25, 29.97"):
        frame_rate("23.976")
    assert frame_rate(29.97).drop and frame_rate("25").nominal == 25
    assert str(Timecode.parse("01:00:00;10")) == "01:00:00;10"


@pytest.mark.parametrize("label", list(RATES))
def test_every_frame_at_every_rate_with_drift_a_jump_and_a_stop(label: str) -> None:
    fps = RATES[label]
    start = Timecode(0, 9, 59, 20, True) if fps.drop else Timecode(1, 0, 0, 0)
    r = render([Segment(start, 40, fps, 1.001),
                Segment(Timecode(2, 0, 0, 0, fps.drop), 15, fps, 0.999),
                Segment(None, silence_s=0.2),
                Segment(Timecode(3, 0, 0, 0, fps.drop), 10, fps, 1.0)], SR)
    out = decode(r.samples)
    assert [f.timecode for f in out] == list(r.timecodes)
    starts_s = np.array([f.start_sample for f in out]) / SR
    assert np.abs(starts_s - r.starts_s).max() < 3 / SR  # a sample or two


def test_varispeed_noise_and_inverted_polarity_still_read() -> None:
    fps = RATES["25"]
    r = render([Segment(Timecode(10, 0, 0, 0), 30, fps, 1.08),
                Segment(Timecode(10, 0, 1, 5), 30, fps, 0.92)], SR, amplitude=0.1)
    noise = np.random.default_rng(7).normal(0.0, 0.01, r.samples.size).astype(np.float32)
    for samples in (r.samples + noise, -r.samples):
        assert [f.timecode for f in decode(samples, block=333)] == list(r.timecodes)


def test_silence_and_noise_alone_decode_nothing() -> None:
    rng = np.random.default_rng(1)
    assert decode(np.zeros(SR, dtype=np.float32)) == []
    assert decode(rng.normal(0, 0.3, SR).astype(np.float32)) == []


def brief_signal() -> tuple[Rendered, list[tuple[float, float, int, float]]]:
    """25 fps from 01:00:00:00, 0.1 % fast; a jump to 01:00:10:00; a stop; it comes back
    at 01:00:20:00. And the truth: (from_s, to_s, first frame, frames a second)."""
    fps = RATES["25"]
    segs = [Segment(Timecode(1, 0, 0, 0), 30, fps, 1.001),
            Segment(Timecode(1, 0, 10, 0), 20, fps, 1.001),
            Segment(None, silence_s=0.4),
            Segment(Timecode(1, 0, 20, 0), 15, fps, 1.0)]
    r = render(segs, SR)
    return r, list(r.stretches)


def test_reader_on_a_wav_gives_each_frame_its_time_and_follows_jumps_and_stops(
        tmp_path: Path) -> None:
    r, truth = brief_signal()
    wav = tmp_path / "ltc.wav"
    write_wav(wav, r.samples, SR)
    clock = FakeClock(100.0)
    audio = open_audio(str(wav), clock)
    assert isinstance(audio, WavAudio)
    reader = LtcReader(audio, clock, fps=RATES["25"])
    fixes: list[TimecodeFix] = []
    at, pos = [], []
    while (got := audio.read()) is not None:
        reader.feed(*got)
        fix = reader.latest()
        if fix is not None and (not fixes or fixes[-1] is not fix):
            fixes.append(fix)
        p = reader.position(clock.now())
        at.append(clock.now() - 100.0)
        pos.append(np.nan if p is None else p)
    assert [f.timecode for f in fixes] == list(r.timecodes)
    assert np.abs(np.array([f.start_s - 100.0 for f in fixes]) - r.starts_s).max() < 1e-4
    t, p = np.array(at), np.array(pos)
    true = r.frame_at(t)  # held at the end of a stretch: a stop
    jump_s, stop_s, back_s = truth[1][0], truth[1][1], truth[2][0]
    # a jump is heard once the first frame after it has come whole (+ a 10 ms block)
    hearing = (t >= jump_s) & (t < jump_s + 0.04 + 0.011)
    locked = np.isfinite(p)
    assert np.abs(p - true)[locked & ~hearing].max() <= 1.0 + 1e-9  # within one frame
    # locked from a frame after each start to the stop, lost 3 frames after it until back
    for a, b, _, _ in truth:
        assert locked[(t > a + 0.09) & (t < b)].all()
    assert not locked[(t > stop_s + 3 / 25 + 0.011) & (t < back_s)].any()
    st = reader.stats()
    assert (st.frames, st.jumps, st.losses) == (65, 1, 1)
    assert reader.drain_events() == [
        "timecode locked at 01:00:00:00 (25 fps)",
        "timecode jumped from 01:00:01:04 to 01:00:10:00",
        "timecode stopped or lost after 01:00:10:19",
        "timecode back at 01:00:20:00 (25 fps)"]
    assert fixes[29].speed == pytest.approx(1.001, abs=2e-4)  # the drift measured


def test_a_bad_source_says_what_to_give(tmp_path: Path) -> None:
    clock = FakeClock()
    with pytest.raises(ConfigError, match=r"--ltc.*alsa:DEVICE"):
        open_audio("timecode.mp3", clock)
    with pytest.raises(DataError, match="not found"):
        open_audio(str(tmp_path / "missing.wav"), clock)
    (tmp_path / "bad.wav").write_bytes(b"RIFF....WAVEjunk")
    with pytest.raises(DataError, match="not a PCM WAV"):
        open_audio(str(tmp_path / "bad.wav"), clock)


def test_the_reader_thread_reads_a_wav_to_its_end(tmp_path: Path) -> None:
    r, _ = brief_signal()
    wav = tmp_path / "ltc.wav"
    write_wav(wav, r.samples, SR)
    clock = FakeClock()
    reader = LtcReader(WavAudio(wav, clock), clock)  # the rate from the signal
    with reader:
        assert reader.join(timeout_s=10.0)
    st = reader.stats()
    assert st.finished and st.frames == 65 and st.failure == ""
    fix = reader.latest()
    assert fix is not None and fix.fps.label == "25"
    # the file has ended: no frame is still to come, the timecode is lost at once
    assert reader.position(clock.now()) is None
    assert reader.describe(clock.now()) == "lost (last 01:00:20:14)"


def test_a_rate_asked_for_that_the_signal_does_not_have_is_said_and_nothing_is_read(
        tmp_path: Path) -> None:
    r, _ = brief_signal()  # 25 fps
    wav = tmp_path / "ltc.wav"
    write_wav(wav, r.samples, SR)
    clock = FakeClock()
    audio = WavAudio(wav, clock)
    reader = LtcReader(audio, clock, fps=RATES["30"])
    while (got := audio.read()) is not None:
        reader.feed(*got)
    assert reader.latest() is None and reader.stats().bad_frames == 65
    assert reader.drain_events() == ["timecode at 25 fps, but 30 fps was asked for"
                                     " ([timecode] fps, --ltc-fps): frames dropped"]
