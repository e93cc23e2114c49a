"""The firmware's portable core (firmware/glove/glove_core.c), compiled natively.

Its frame encoder must reproduce SPEC.md's golden bytes; the C test program also
checks the debounce, rail detection, BNO055 quaternion and LED logic.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT / "firmware_protocol" / "SPEC.md"


def golden_wires() -> list[str]:
    return re.findall(r"^wire\s+((?:[0-9a-f]{2} ?)+)$", SPEC.read_text(), flags=re.M)


@pytest.fixture(scope="module")
def core_test(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler on this machine")
    exe = tmp_path_factory.mktemp("fwcore") / "test_core"
    subprocess.run(
        [cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", f"-I{ROOT / 'firmware/glove'}",
         "-o", str(exe), str(ROOT / "firmware/tests/test_core.c"),
         str(ROOT / "firmware/glove/glove_core.c")],
        check=True, capture_output=True)
    return exe


def test_the_firmware_encoder_sends_the_golden_bytes_of_the_spec(core_test: Path):
    done = subprocess.run([str(core_test)], capture_output=True, text=True, timeout=10)
    assert done.returncode == 0, done.stderr
    wires = golden_wires()
    assert len(wires) == 3
    assert done.stdout.split("\n")[:3] == [w.strip() for w in wires]
