"""Shared fixtures."""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

SPEC = Path(__file__).resolve().parents[1] / "firmware_protocol" / "SPEC.md"


@pytest.fixture(scope="session")
def build_spec_c(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """Compile the C code blocks of firmware_protocol/SPEC.md with a given ``main``,
    as a firmware author would (``posix=True`` for a host program that sleeps and
    writes to a file descriptor); skips the test where no C compiler is installed."""
    cc = shutil.which("cc") or shutil.which("gcc")

    def build(main: str, name: str, posix: bool = False) -> Path:
        if cc is None:
            pytest.skip("no C compiler on this machine")
        blocks = re.findall(r"```c\n(.*?)```", SPEC.read_text(), flags=re.S)
        assert len(blocks) == 3  # cobs_encode, crc16_ccitt_false, glove_frame_build
        prelude = "#define _POSIX_C_SOURCE 200809L\n" if posix else ""
        src = prelude + "#include <stdint.h>\n#include <stddef.h>\n" + "\n".join(blocks) + main
        d = tmp_path_factory.mktemp(name)
        (d / f"{name}.c").write_text(src)
        exe = d / name
        subprocess.run([cc, "-std=c99", "-Wall", "-Werror", "-O1", "-o", str(exe),
                        str(d / f"{name}.c")], check=True, capture_output=True)
        return exe

    return build


@pytest.fixture(autouse=True)
def _user_dirs(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test (and the commands it starts) gets empty XDG config and data dirs: a
    calibrated glove.toml or baked grid in the developer's home is never read."""
    base = tmp_path_factory.mktemp("xdg")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(base / "config"))
    monkeypatch.setenv("XDG_DATA_HOME", str(base / "data"))
