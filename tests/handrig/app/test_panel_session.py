"""`handrig run` on a real 80x24 pseudo-terminal draws the panel, and ends with torque off."""

from __future__ import annotations

import fcntl
import os
import re
import select
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest

CHECKOUT = Path(__file__).resolve().parents[3]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


@pytest.mark.slow
def test_run_draws_the_panel_on_a_terminal(tmp_path: Path) -> None:
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    env = {**os.environ, "TERM": "xterm", "COLUMNS": "80", "LINES": "24",
           "XDG_CONFIG_HOME": str(tmp_path / "config"), "XDG_DATA_HOME": str(tmp_path / "data")}
    # 300 frames: 1.5 s at 200 Hz, six of the panel's redraws at 4 a second, and the ease
    proc = subprocess.Popen(
        [sys.executable, "-m", "handrig.cli", "run", "--glove",
         "replay:config/recordings/demo_glove.csv", "--bus", "sim", "--frames", "300"],
        stdin=slave, stdout=slave, stderr=slave, env=env, cwd=CHECKOUT,
        start_new_session=True)
    os.close(slave)
    raw = b""
    try:
        end = time.monotonic() + 180
        while time.monotonic() < end:
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:
                    break
                if not chunk:
                    break
                raw += chunk
            elif proc.poll() is not None:
                break
        status = proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        os.close(master)
    text = ANSI.sub("", raw.decode(errors="replace")).replace("\r", "")
    assert status == 0, text[-3000:]
    assert re.search(r"handrig +(RUNNING|STOPPING)", text), text[-3000:]
    assert "glove  " in text and "latency p50" in text and "stale " in text
    assert re.search(r"id joint +goal +now +°C +mA er", text)
    assert "e-stop" in text or "keys off: Ctrl-C stops" in text
    assert re.search(r"torque off +True", text)
