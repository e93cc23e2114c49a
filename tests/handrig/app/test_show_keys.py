"""The show keys in a real pseudo-terminal: `handrig run` draws its panel, space relaxes
and resumes the puppet, q stops it (ease, then torque off), e stops it at once.

pexpect runs the command in an 80x24 pty as a puppeteer's terminal would; the test
reads the panel (mode and events) between key presses and the summary at the end.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

import pytest

pexpect = pytest.importorskip("pexpect")

CHECKOUT = Path(__file__).resolve().parents[3]
RECORDING = "replay:config/recordings/demo_glove.csv"
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
START_S = 120  # the simulated bus starts and is commissioned (slow on a busy machine)
STEP_S = 30


def _spawn(tmp_path: Path) -> pexpect.spawn:
    env = {**os.environ, "TERM": "xterm", "COLUMNS": "80", "LINES": "24",
           "XDG_CONFIG_HOME": str(tmp_path / "config"), "XDG_DATA_HOME": str(tmp_path / "data")}
    child = pexpect.spawn(
        sys.executable, ["-m", "handrig.cli", "run", "--bus", "sim", "--glove", RECORDING,
                         "--seconds", "40"],
        cwd=str(CHECKOUT), env=env, dimensions=(24, 80), encoding="utf-8",
        codec_errors="replace", timeout=STEP_S)
    child.logfile_read = _Transcript()
    return child


class _Transcript:
    """What the terminal showed, kept for the failure message."""

    def __init__(self) -> None:
        self.text = ""

    def write(self, data: str) -> None:
        self.text += data

    def flush(self) -> None:
        pass

    def tail(self) -> str:
        return ANSI.sub("", self.text).replace("\r", "")[-3000:]


def _finish(child: pexpect.spawn) -> tuple[int, str]:
    child.expect(pexpect.EOF, timeout=60)
    child.close()
    text = ANSI.sub("", child.logfile_read.text).replace("\r", "")
    return child.exitstatus, text


@pytest.mark.slow
def test_space_relaxes_and_resumes_then_q_eases_and_turns_torque_off(tmp_path: Path) -> None:
    child = _spawn(tmp_path)
    try:
        child.expect("RUNNING", timeout=START_S)
        child.expect("relax/resume")  # the keys are offered, so they are read
        child.send(" ")
        child.expect("RELAXING")
        child.expect("relax key: relaxed until it is pressed again")
        child.send(" ")
        child.expect("relax key: resuming")
        child.expect("RUNNING")
        child.send("q")
        child.expect("STOPPING")
        child.expect("q pressed")
        status, text = _finish(child)
    finally:
        if child.isalive():
            child.terminate(force=True)
    assert status == 0, child.logfile_read.tail()
    summary = text[text.rindex("frames  "):]
    assert re.search(r"stopped: q pressed", summary), summary
    # the key's relax is counted beside the resume it led to (it is no glove loss)
    assert re.search(r"0 relax events \(glove lost or servos\s+silent\), 1 by the relax key,"
                     r"\s+1 resumes", summary), summary
    assert "includes the 1 s ease to the relaxed pose" in summary
    assert re.search(r"torque off +True", summary), summary


@pytest.mark.slow
def test_e_stops_at_once_with_torque_off(tmp_path: Path) -> None:
    child = _spawn(tmp_path)
    try:
        child.expect("RUNNING", timeout=START_S)
        child.expect("relax/resume")
        child.send("e")
        status, text = _finish(child)
    finally:
        if child.isalive():
            child.terminate(force=True)
    assert status == 0, child.logfile_read.tail()
    assert "e-stop key: torque off now, no easing" in text
    summary = text[text.rindex("frames  "):]
    assert "ended at once, no ease" in summary, summary
    assert re.search(r"e-stop pressed, stopped: e-stop key", summary), summary
    assert re.search(r"torque off +True", summary), summary
