"""Where LTC audio comes from: :class:`AudioInput` and its two kinds, a WAV file played
in real time (:class:`WavAudio`, what the tests use) and a sound card through ALSA's
``arecord`` (:class:`AlsaAudio`). :func:`open_audio` reads a ``--ltc SOURCE``."""

from __future__ import annotations

import shutil
import subprocess
import wave
from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig.clock import Clock
from handrig.errors import ConfigError, DataError, DeviceError

BLOCK_S = 0.01
"""Audio handed to the decoder at a time (a sound card's period)."""
CARD_RATE_HZ = 48000


class AudioInput(ABC):
    """Mono audio in blocks, each with the clock time its last sample arrived."""

    sample_rate_hz: int
    name: str

    @abstractmethod
    def read(self) -> tuple[NDArray[np.float32], float] | None:
        """The next block and when its last sample arrived (clock time), blocking until
        it has; None at the end (a file played through, a card closed)."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release the device. Idempotent."""


class WavAudio(AudioInput):
    """A PCM WAV file (8, 16, 24 or 32-bit; ``channel`` of a multichannel one) played
    against ``clock`` as if a sound card delivered it: block by block, each when its last
    sample comes due after :meth:`read` was first called."""

    def __init__(self, path: str | Path, clock: Clock, *, channel: int = 0,
                 block_s: float = BLOCK_S) -> None:
        self.path = Path(path)
        self.name = str(self.path)
        self.clock = clock
        self.samples, self.sample_rate_hz = read_wav(self.path, channel)
        self._block = max(1, round(block_s * self.sample_rate_hz))
        self._at = 0
        self._t0: float | None = None
        self._closed = False

    @property
    def duration_s(self) -> float:
        return self.samples.size / self.sample_rate_hz

    def read(self) -> tuple[NDArray[np.float32], float] | None:
        if self._closed or self._at >= self.samples.size:
            return None
        if self._t0 is None:
            self._t0 = self.clock.now()
        end = min(self._at + self._block, self.samples.size)
        due = self._t0 + end / self.sample_rate_hz
        self.clock.sleep_until(due)
        block = self.samples[self._at:end]
        self._at = end
        return block, due

    def close(self) -> None:
        self._closed = True


def read_wav(path: Path, channel: int = 0) -> tuple[NDArray[np.float32], int]:
    """One channel of a PCM WAV as floats in -1..1, and its sample rate; DataError naming
    the file when it is not one."""
    try:
        with wave.open(str(path), "rb") as w:
            n_ch, width, rate = w.getnchannels(), w.getsampwidth(), w.getframerate()
            raw = w.readframes(w.getnframes())
    except FileNotFoundError:
        raise DataError(f"{path}: LTC audio file not found") from None
    except (wave.Error, EOFError) as exc:
        raise DataError(f"{path}: not a PCM WAV file ({exc}); save the timecode track as"
                        " 16- or 24-bit PCM WAV") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read the LTC audio: {exc.strerror or exc}") from None
    if not 0 <= channel < n_ch:
        raise ConfigError(f"{path} has {n_ch} channel(s)", key="channel", value=channel,
                          allowed=f"0..{n_ch - 1}")
    if width == 3:
        b = np.frombuffer(raw, dtype=np.uint8).reshape(-1, 3)
        ints = (b[:, 0].astype(np.int32) | (b[:, 1].astype(np.int32) << 8)
                | (b[:, 2].astype(np.int8).astype(np.int32) << 16))
        x = ints.astype(np.float32) / 8388608.0
    elif width == 1:
        x = (np.frombuffer(raw, dtype=np.uint8).astype(np.float32) - 128.0) / 128.0
    else:
        dt = {2: "<i2", 4: "<i4"}[width]
        x = np.frombuffer(raw, dtype=dt).astype(np.float32) / float(2 ** (8 * width - 1))
    x = x[: x.size - x.size % n_ch].reshape(-1, n_ch)[:, channel]
    if x.size == 0:
        raise DataError(f"{path}: the WAV file holds no audio")
    return np.ascontiguousarray(x), rate


class AlsaAudio(AudioInput):
    """A sound card's input through ``arecord`` (alsa-utils): 16-bit mono at 48 kHz, the
    clock time of each block taken when it is read."""

    def __init__(self, device: str, clock: Clock, *, block_s: float = BLOCK_S) -> None:
        exe = shutil.which("arecord")
        if exe is None:
            raise DeviceError(f"alsa:{device}: `arecord` was not found; install alsa-utils"
                              " (`sudo apt install alsa-utils`) or give a WAV file")
        self.name = f"alsa:{device}"
        self.clock = clock
        self.sample_rate_hz = CARD_RATE_HZ
        self._bytes = 2 * max(1, round(block_s * CARD_RATE_HZ))
        self._argv = [exe, "-q", "-D", device, "-t", "raw", "-f", "S16_LE", "-c", "1",
                      "-r", str(CARD_RATE_HZ), "--buffer-time=20000"]
        self._proc: subprocess.Popen[bytes] | None = None
        self._closed = False

    def read(self) -> tuple[NDArray[np.float32], float] | None:
        if self._closed:
            return None
        if self._proc is None:  # started by the first read: nothing runs before the show
            self._proc = subprocess.Popen(self._argv, stdout=subprocess.PIPE,
                                          stderr=subprocess.PIPE)
        out = self._proc.stdout
        if out is None:
            return None
        data = out.read(self._bytes)
        now = self.clock.now()
        if not data:  # the card went away, or arecord could not open it
            try:
                code = self._proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                code = None
            if self._closed or not code:
                return None
            err = self._proc.stderr.read(400) if self._proc.stderr is not None else b""
            said = err.decode(errors="replace").strip() or f"exit status {code}"
            raise DeviceError(f"{self.name}: arecord stopped: {said}; check the device"
                              " with `arecord -l`")
        data = data[: len(data) - len(data) % 2]
        return np.frombuffer(data, dtype="<i2").astype(np.float32) / 32768.0, now

    def close(self) -> None:
        self._closed = True
        if self._proc is not None and self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()


def open_audio(source: str, clock: Clock, *, key: str = "--ltc",
               channel: int = 0) -> AudioInput:
    """``FILE.wav`` or ``alsa:DEVICE`` (``alsa:default``, ``alsa:hw:1,0``); ConfigError
    naming ``key`` otherwise."""
    if source.startswith("alsa:"):
        device = source.removeprefix("alsa:") or "default"
        return AlsaAudio(device, clock)
    if Path(source).suffix.lower() == ".wav":
        return WavAudio(source, clock, channel=channel)
    raise ConfigError("not an LTC source", key=key, value=source,
                      allowed="a .wav file or alsa:DEVICE (e.g. alsa:default, alsa:hw:1,0)")
