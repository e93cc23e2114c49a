"""A sound card's LTC through ``arecord``: the real subprocess path, with an ``arecord``
of the test's own first on PATH (one that plays raw audio out, one that fails as ALSA
does when the card is missing)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from handrig.clock import MonotonicClock
from handrig.devices.timecode.audio import AlsaAudio, open_audio
from handrig.devices.timecode.ltc import RATES, Timecode
from handrig.devices.timecode.ltc_encode import Segment, render
from handrig.devices.timecode.reader import LtcReader
from handrig.errors import DeviceError


def fake_arecord(folder: Path, body: str, monkeypatch: pytest.MonkeyPatch) -> None:
    exe = folder / "arecord"
    exe.write_text("#!/bin/sh\n" + body)
    exe.chmod(0o755)
    monkeypatch.setenv("PATH", f"{folder}{os.pathsep}{os.environ.get('PATH', '')}")


def test_ltc_from_arecord_is_read_frame_for_frame(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    r = render([Segment(Timecode(5, 0, 0, 0), 25, RATES["25"], 1.0)], 48000)
    raw = tmp_path / "ltc.raw"
    raw.write_bytes(np.round(r.samples * 32767).astype("<i2").tobytes())
    fake_arecord(tmp_path, f'case "$*" in *"-D hw:9,0"*"-r 48000"*) exec cat "{raw}";; esac\n'
                 "exit 3\n", monkeypatch)
    clock = MonotonicClock()
    audio = open_audio("alsa:hw:9,0", clock)
    assert isinstance(audio, AlsaAudio)
    with LtcReader(audio, clock) as reader:
        assert reader.join(timeout_s=10.0)
    st = reader.stats()
    assert st.frames == 25 and st.failure == "" and st.bad_frames == 0
    fix = reader.latest()
    assert fix is not None and str(fix.timecode) == "05:00:00:24"


def test_a_card_that_cannot_be_opened_is_said_with_alsa_s_words(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fake_arecord(tmp_path, 'echo "arecord: main:831: audio open error: No such file or'
                 ' directory" >&2\nexit 1\n', monkeypatch)
    clock = MonotonicClock()
    with LtcReader(open_audio("alsa:hw:9,0", clock), clock) as reader:
        assert reader.join(timeout_s=10.0)
    failure = reader.stats().failure
    assert "alsa:hw:9,0" in failure and "audio open error" in failure
    assert any("audio open error" in e for e in reader.drain_events())


def test_no_arecord_says_what_to_install(tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(DeviceError, match="alsa-utils"):
        open_audio("alsa:default", MonotonicClock())
