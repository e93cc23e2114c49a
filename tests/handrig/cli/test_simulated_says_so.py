"""A command on the simulated bus says so (issue 37): ``--port sim`` runs say SIMULATED
in their first line and their summary; ``demo --seconds`` counts the run.
(tests/handrig/cli/test_first_hour_messages.py: no port, no simulation.)"""

from __future__ import annotations

import os

import pytest

from handrig.cli import main


def test_servos_on_the_simulated_bus_say_so_first_and_last(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["servos", "check", "--port", "sim"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("SIMULATED rig (--port sim)"), lines[:3]
    assert any(line.startswith("20 servo(s) answered on the SIMULATED bus") for line in lines)
    assert "(emulated servos: not your hardware)" in lines[-1]
    assert any(line.startswith("SIMULATED: that was the emulated bus") for line in lines)


def test_demo_seconds_counts_the_run_and_says_it_is_simulated(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    # in this process (its emulators are processes of their own either way): the
    # command's parsing, first line and summary are what is checked
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    assert main(["demo", "--seconds", "0.5"]) == 0
    stdout = capsys.readouterr().out
    lines = stdout.splitlines()
    assert lines[0].startswith("SIMULATED rig (--port sim)"), lines[:3]
    summary = stdout[stdout.rindex("bus               SIMULATED"):]
    assert "stopped: 0.5 s done" in summary, summary
    frames = int(summary.split("frames ")[1].split()[0])
    assert 100 <= frames <= 400  # 0.5 s and the 1 s ease at 200 Hz, not --frames' 3000
