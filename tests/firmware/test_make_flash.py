"""``make flash PORT=...`` (issue 37): the firmware is built, then avrdude writes it through
the Arduino bootloader on PORT; ``make firmware-deps`` installs avrdude. Checked with
``make -n`` (what would run, nothing run): avrdude's own dry run (``-n``) still talks to
the bootloader, so it needs a board (firmware/README.md says so)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="no make here")


def make_n(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["make", "-n", "--no-print-directory", "-C", str(ROOT), *args],
                          capture_output=True, text=True, timeout=60)


def test_make_flash_builds_then_runs_avrdude_on_the_port() -> None:
    res = make_n("flash", "PORT=/dev/serial/by-id/usb-1a86_glove", "FLASH_BAUD=115200",
                 "AVRDUDE_FLAGS=-n")
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    flash = [line for line in lines if line.startswith("avrdude ")]
    assert flash == ["avrdude -p atmega328p -c arduino -P /dev/serial/by-id/usb-1a86_glove "
                     "-b 115200 -D -n -U flash:w:build/firmware/glove.hex:i"]
    # the hex is built first when it is missing or stale (make -n lists its recipe)
    hex_built = any("avr-objcopy" in line and "glove.hex" in line for line in lines)
    assert hex_built or (ROOT / "build" / "firmware" / "glove.hex").exists()
    assert lines.index(flash[0]) == len(lines) - 1


def test_make_flash_without_a_port_names_it() -> None:
    res = make_n("flash")
    assert res.returncode != 0
    assert "make flash needs the glove's port: make flash PORT=/dev/ttyUSB0" in res.stderr


def test_make_firmware_deps_installs_avrdude() -> None:
    res = make_n("firmware-deps")
    assert res.returncode == 0, res.stderr
    assert "apt-get install" in res.stdout and " avrdude" in res.stdout
