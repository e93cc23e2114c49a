"""The glove firmware on an emulated ATmega328P, from Python.

:class:`AvrGlove` starts ``build/sim/avr_glove`` (``sim/avr_glove/harness.c``, built by
``make sim-avr-glove``) on the firmware ELF ``make firmware`` builds, with a glove
recording driving its sensors and IMU; the chip's UART is a pty at :attr:`AvrGlove.port`
that ``handrig run --glove`` reads like a USB glove. At exit the harness prints the
figures it measured from outside the firmware (:attr:`AvrGlove.figures`).

Needs Debian's ``gcc-avr``, ``avr-libc``, ``arduino-core-avr``, ``simavr`` and
``libsimavr-dev``: ``make firmware-deps`` installs them; :func:`toolchain_missing` says
what is missing.

Example::

    build()
    with AvrGlove("config/recordings/demo_glove.csv", imu_off_at_s=2.0) as chip:
        glove = SerialGlove(chip.port, "frames", clock=MonotonicClock())
"""

from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

from firmware_protocol.glove import FrameDecoder, GloveFrame
from handrig.errors import DataError

ROOT = Path(__file__).resolve().parents[2]
FIRMWARE_ELF = ROOT / "build" / "firmware" / "glove.elf"
HARNESS = ROOT / "build" / "sim" / "avr_glove"
ARDUINO_CORE = Path("/usr/share/arduino/hardware/arduino/avr/cores/arduino")
SIMAVR_HEADER = Path("/usr/include/simavr/sim_avr.h")
N_CHANNELS = 5


def toolchain_missing() -> str | None:
    """Why the firmware cannot be built and emulated here, or None when it can."""
    missing = [name for name, ok in (
        ("make", shutil.which("make") is not None),
        ("a C compiler (cc)", shutil.which("cc") is not None),
        ("avr-gcc (gcc-avr, avr-libc)", shutil.which("avr-gcc") is not None),
        ("the Arduino AVR core (arduino-core-avr)", ARDUINO_CORE.is_dir()),
        ("simavr (simavr, libsimavr-dev)", SIMAVR_HEADER.is_file()),
    ) if not ok]
    if not missing:
        return None
    return ("glove firmware toolchain missing: " + ", ".join(missing)
            + "; run `make firmware-deps` (as root) to install it")


def build() -> None:
    """``make firmware sim-avr-glove`` (incremental); raises DataError with make's output."""
    done = subprocess.run(["make", "-s", "firmware", "sim-avr-glove"], cwd=ROOT,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise DataError(f"make firmware sim-avr-glove failed:\n{done.stdout}{done.stderr}")


def build_variant(build_dir: str | Path, defines: Sequence[str] = (),
                  source: str | Path | None = None) -> tuple[Path, str]:
    """``make firmware FW_BUILD=build_dir FW_DEFS=defines [FW_SRC=source]``: the firmware
    with other settings (``-DGLOVE_RATE_HZ=500``) or from other sources (an older
    commit's ``firmware/glove``). Returns the ELF and make's flash and RAM report;
    raises DataError with make's output."""
    args = ["make", "-s", "firmware", f"FW_BUILD={build_dir}", f"FW_DEFS={' '.join(defines)}"]
    if source is not None:
        args.append(f"FW_SRC={source}")
    done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise DataError(f"{' '.join(args)} failed:\n{done.stdout}{done.stderr}")
    report = "\n".join(line for line in done.stdout.splitlines()
                       if line.startswith(("flash:", "RAM:")))
    return ROOT / build_dir / "glove.elf", report


def parse_figures(line: str) -> dict[str, float]:
    """The harness's last line, ``figures: key value ... key mean A min B max C ...``,
    as a dict (``sample_to_last_byte_us_mean``, ``burst_middle_to_last_byte_us_max`` and
    so on)."""
    words = line.split()[1:]
    out: dict[str, float] = {}
    i = 0
    while i + 1 < len(words):
        key = words[i]
        if words[i + 1] == "mean" and i + 6 < len(words):
            for j in range(3):
                out[f"{key}_{words[i + 1 + 2 * j]}"] = float(words[i + 2 + 2 * j])
            i += 7
            continue
        out[key] = float(words[i + 1])
        i += 2
    return out


class AvrGlove:
    """The emulated chip running the firmware (see the module docstring).

    ``seconds``: chip time after which the harness stops by itself (None: until
    :meth:`close`). ``imu``: a BNO055 on the bus; ``imu_off_at_s``: it stops answering
    then. ``pinned``: raw channel -> counts held there (a broken wire). ``timing``: a
    file for per-frame times. ``speed``: chip time per wall time. ``noise_mv``: the
    analog inputs' noise (standard deviation, mV). ``whole_frames``: the pty gets each
    frame in one write (default: byte by byte, as the UART sends them). ``firmware``:
    another ELF than ``make firmware``'s (a variant built with other settings).
    """

    def __init__(self, recording: str | Path, *, seconds: float | None = None, imu: bool = True,
                 imu_off_at_s: float | None = None, pinned: dict[int, int] | None = None,
                 timing: str | Path | None = None, speed: float = 1.0,
                 noise_mv: float = 2.0, whole_frames: bool = False,
                 firmware: str | Path | None = None) -> None:
        self.firmware = Path(firmware) if firmware is not None else FIRMWARE_ELF
        self.args = [str(HARNESS), str(self.firmware), str(recording)]
        if seconds is not None:
            self.args += ["--seconds", f"{seconds:g}"]
        if not imu:
            self.args.append("--no-imu")
        if imu_off_at_s is not None:
            self.args += ["--imu-off-at", f"{imu_off_at_s:g}"]
        for ch, counts in (pinned or {}).items():
            if not 0 <= ch < N_CHANNELS:
                raise DataError(f"pinned channel {ch}: the firmware has channels 0..4")
            self.args += ["--pin", f"{ch}={counts}"]
        if timing is not None:
            self.args += ["--timing", str(timing)]
        self.args += ["--speed", f"{speed:g}", "--noise", f"{noise_mv:g}"]
        if whole_frames:
            self.args.append("--whole-frames")
        self.port = ""
        self.figures: dict[str, float] = {}
        self.output: list[str] = []
        self._proc: subprocess.Popen[str] | None = None

    def start(self) -> AvrGlove:
        """Start the chip; returns once its UART's pty exists (:attr:`port`)."""
        for path in (HARNESS, self.firmware):
            if not path.is_file():
                raise DataError(f"{path} not built: run `make firmware sim-avr-glove`")
        self._proc = subprocess.Popen(self.args, stdout=subprocess.PIPE, text=True)
        out = self._proc.stdout
        if out is None:
            raise DataError("the emulated chip gave no output pipe")
        for line in out:
            self.output.append(line.rstrip("\n"))
            if line.startswith("port: "):
                self.port = line.split(maxsplit=1)[1].strip()
                return self
        self.close()
        raise DataError("the emulated chip stopped before opening its pty:\n"
                        + "\n".join(self.output))

    def read_frames(self) -> list[GloveFrame]:
        """Every SPEC.md frame the chip sends on its pty until it stops (give it
        ``seconds``), decoded; the frames before a reader opened the pty are lost."""
        fd = os.open(self.port, os.O_RDONLY | os.O_NOCTTY)
        data = b""
        try:
            while True:
                ready, _, _ = select.select([fd], [], [], 0.1)
                if ready:
                    try:
                        chunk = os.read(fd, 4096)
                    except OSError:
                        break
                    if not chunk:
                        break
                    data += chunk
                elif not self.running():
                    break
        finally:
            os.close(fd)
        return FrameDecoder().feed(data)

    def running(self) -> bool:
        """The chip has started and not stopped (``seconds`` of chip time not run out)."""
        return self._proc is not None and self._proc.poll() is None

    def pull_imu(self) -> None:
        """The BNO055 stops answering now (its wire pulled)."""
        if self._proc is not None and self._proc.poll() is None:
            self._proc.send_signal(signal.SIGUSR1)

    def close(self, timeout_s: float = 5.0) -> dict[str, float]:
        """Stop the chip (if still running) and return its figures. Idempotent."""
        proc = self._proc
        if proc is None:
            return self.figures
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            rest, _ = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            rest, _ = proc.communicate()
        self._proc = None
        for line in (rest or "").splitlines():
            self.output.append(line)
            if line.startswith("figures: "):
                self.figures = parse_figures(line)
        return self.figures

    def __enter__(self) -> AvrGlove:
        return self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
