"""A glove that vanishes and comes back on the same path is reopened and the puppet
resumes, in every loop mode: the glove on a pty behind a symlink that goes away with
it and comes back pointing at a new pty (as udev removes /dev/ttyACM0 on unplug and
makes it again for the replugged glove), the loop and the emulated bus."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import threading
import time
from pathlib import Path

import pytest

from handrig.app import factory as app
from handrig.app import parts as app_parts
from handrig.clock import MonotonicClock
from handrig.devices.glove_recording import read_glove_recording
from sim.demo_recording import DEMO_RECORDING
from sim.glove_emulator import GloveEmulator

REOPEN_WAIT_S = 30.0  # for the glove to be reopened and the loop to resume


def _point(link: Path, target: str) -> None:
    tmp = link.with_name(link.name + ".new")
    os.symlink(target, tmp)
    os.replace(tmp, link)  # atomically, as udev does


@pytest.mark.parametrize("mode", ["glove", "fixed"])
def test_a_glove_unplugged_and_plugged_back_is_reopened_and_the_puppet_resumes(
        tmp_path: Path, mode: str) -> None:
    parts = app_parts.build_parts()
    loop = dataclasses.replace(parts.rig_config.loop, mode=mode)  # type: ignore[arg-type]
    parts = dataclasses.replace(parts, rig_config=dataclasses.replace(parts.rig_config,
                                                                      loop=loop))
    rec = read_glove_recording(DEMO_RECORDING)
    clock = MonotonicClock()
    events: list[str] = []
    link = tmp_path / "ttyACM0"
    first = GloveEmulator(rec, "frames", rate_hz=200.0, loop=True).start()
    second: GloveEmulator | None = None
    _point(link, first.port_path)
    try:
        with contextlib.ExitStack() as stack:
            opened = stack.enter_context(app.servo_bus("sim", parts, clock, log=events.append))
            glove = app.open_glove(str(link), parts.glove_config, clock)
            stack.enter_context(glove)
            opened.bus.connect()
            rig = app.build_rig(parts, glove, opened.bus, clock, log=events.append)

            gone_at, back_seen_at = [math.nan], [math.nan]

            def unplug_and_replug() -> None:
                nonlocal second
                try:
                    time.sleep(1.0)
                    gone_at[0] = time.monotonic()
                    first.hang_up()  # the glove is gone, and so is its device node
                    link.unlink()
                    time.sleep(1.0)
                    second = GloveEmulator(rec, "frames", rate_hz=200.0, loop=True).start()
                    _point(link, second.port_path)  # back, on another pty behind the same name
                    # the run goes on until the glove is reopened, has sent 1 s of frames
                    # since, and the loop has resumed (waited for: a loaded machine)
                    end = time.monotonic() + REOPEN_WAIT_S
                    while glove.stats().reconnects < 1 and time.monotonic() < end:
                        time.sleep(0.01)
                    back_seen_at[0] = time.monotonic()
                    frames = glove.stats().frames_ok
                    while time.monotonic() < end and (
                            glove.stats().frames_ok < frames + 200
                            or rig.machine.resumes < rig.machine.relax_events):
                        time.sleep(0.01)
                finally:
                    rig.request_stop("the test's script is done")

            rig.prepare()
            with opened.bus.torque(handle_signals=False):
                script = threading.Thread(target=unplug_and_replug)
                script.start()
                stats = rig.run()
                script.join()
            glove_stats = glove.stats()
    finally:
        first.close()
        if second is not None:
            second.close()
    said = f"{glove_stats}\n{stats}\n" + "\n".join(events)
    assert glove_stats.disconnects == 1, said
    assert glove_stats.reconnects == 1, said
    # the node was gone for 1 s: the outage is about that, and no longer than from its
    # going to the reopen being seen
    assert 0.5 <= glove_stats.last_outage_s <= back_seen_at[0] - gone_at[0], said
    # relaxed for the outage and resumed after it (a host stall on a loaded machine may
    # add a relax of its own, and its resume)
    assert stats.relax_events >= 1 and stats.resumes == stats.relax_events, said
    assert any("is back after" in e for e in events), said
    assert stats.frames > 0 and glove_stats.frames_ok > 400, said  # before and after


def test_handrig_run_reopens_a_glove_that_comes_back_and_counts_it(tmp_path: Path) -> None:
    import json
    import signal
    import subprocess
    import sys

    rec = read_glove_recording(DEMO_RECORDING)
    link = tmp_path / "ttyACM0"
    first = GloveEmulator(rec, "frames", rate_hz=200.0, loop=True).start()
    second: GloveEmulator | None = None
    _point(link, first.port_path)
    # gone 1 s into the run, back 1 s later; the run is ended (Ctrl-C) once it says the
    # glove is back (--seconds: a bound, waited for on a loaded machine)
    proc = subprocess.Popen([sys.executable, "-m", "handrig.cli", "run", "--glove", str(link),
                             "--bus", "sim", "--seconds", "60", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr is not None
        lines: list[str] = []
        for line in proc.stderr:  # the loop runs once the servos are commissioned
            lines.append(line)
            if "commissioned" in line:
                break
        time.sleep(1.0)
        first.hang_up()
        link.unlink()
        time.sleep(1.0)
        second = GloveEmulator(rec, "frames", rate_hz=200.0, loop=True).start()
        _point(link, second.port_path)
        back = following = False
        for line in proc.stderr:  # reopened, and the loop follows the glove again
            lines.append(line)
            back = back or "is back after" in line
            # in either order: the port's line is drained a cycle or more after it
            # reopened, the loop's as soon as enough frames came in a row
            following = following or "glove is back: following it again" in line
            if back and following:
                proc.send_signal(signal.SIGINT)
                break
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
        first.close()
        if second is not None:
            second.close()
    assert proc.returncode == 0, "".join(lines) + err
    summary = json.loads(out)
    g = summary["glove"]
    assert g["disconnects"] == 1 and g["reconnects"] == 1, summary
    assert summary["relax_events"] >= 1, summary
    assert summary["resumes"] == summary["relax_events"], summary
    assert summary["torque_off"] is True and "SIGINT" in summary["stop_reason"], summary
    assert f"glove port {link} is back after" in "".join(lines)
