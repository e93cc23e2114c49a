"""A host stall's backlog is the host's, not the glove's (issue 24.6).

A real ``handrig run`` follows a glove on a pty (frames one by one, every 5 ms,
from this process) and drives emulated servos on another pty (this process's
SimBus, so both keep going while the rig does not). The rig is stopped with
SIGSTOP for 0.4 s, as a host stall would, then continued: the ~80 frames that came
one by one meanwhile are counted as left waiting by a host stall, not as lost in
the glove's own bursts, and the summary line says so.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

from firmware_protocol.glove import GloveFrame, encode_frame
from handrig.app.summary import format_summary
from handrig.config.rig import load_rig_config
from sim.dxl_bus import SimBus

CLI = [sys.executable, "-m", "handrig.cli"]
FRAME_S = 0.005
STALL_S = 0.4


def test_a_sigstopped_rig_counts_the_gloves_frames_as_the_hosts_backlog(
        tmp_path: Path) -> None:
    rig = load_rig_config()
    master, slave = os.openpty()
    tty.setraw(slave)
    stop = threading.Event()

    sent: list[float] = []  # when each frame went out

    def glove() -> None:  # one frame at a time, on a 5 ms grid: never a burst
        k = 0
        start = time.monotonic()
        while not stop.is_set():
            frame = GloveFrame(k & 0xFFFF, (k * 5000) & 0xFFFFFFFF, (2000,) * 5,
                               (0.0, 0.0, 0.0, 1.0))
            try:
                os.write(master, encode_frame(frame))
            except OSError:
                return
            sent.append(time.monotonic())
            k += 1
            late = time.monotonic() - (start + k * FRAME_S)
            if late > FRAME_S:  # this thread was held up (a loaded machine): no catching
                start += late  # up with frames back to back, which would be a burst
            time.sleep(max(0.0, start + k * FRAME_S - time.monotonic()))

    env = {**os.environ, "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path / "cfg"),
           "MUJOCO_GL": "egl"}
    writer = threading.Thread(target=glove, daemon=True)
    with SimBus.from_rig(rig) as sim:
        writer.start()
        proc = subprocess.Popen(
            [*CLI, "run", "--glove", os.ttyname(slave), "--bus", sim.port_path,
             "--seconds", "60", "--json"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
            start_new_session=True)
        try:
            servos = [sim.servo(s.id) for s in rig.servos]
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and proc.poll() is None and not all(
                    s.torque_enabled for s in servos):
                time.sleep(0.01)
            assert all(s.torque_enabled for s in servos), "the rig never turned torque on"
            time.sleep(0.5)  # following the glove, past the 0.3 s ease-in
            os.kill(proc.pid, signal.SIGSTOP)
            stopped = time.monotonic()
            time.sleep(STALL_S)
            continued = time.monotonic()
            os.kill(proc.pid, signal.SIGCONT)
            time.sleep(0.5)  # the backlog is met on the first cycles after the stall
            os.kill(proc.pid, signal.SIGTERM)
            out, _err = proc.communicate(timeout=30)
        finally:
            stop.set()
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
            writer.join(5)
            os.close(master)
            os.close(slave)
    summary = json.loads(out.strip().splitlines()[-1])
    assert "error" not in summary, summary.get("error")
    assert summary["torque_off"] is True
    expected = sum(1 for t in sent if stopped <= t < continued)  # about STALL_S / FRAME_S
    assert expected >= 0.5 * STALL_S / FRAME_S, f"the glove thread sent {expected} frames"
    stalled = summary["frames_in_host_stalls"]
    bursts = summary["frames_in_bursts"]
    assert stalled >= 0.6 * expected, (stalled, bursts, summary["frames_skipped"])
    assert bursts < 0.2 * expected, (stalled, bursts)
    line = next(ln for ln in format_summary(summary).splitlines()
                if ln.startswith("frame losses"))
    assert f"{stalled} left waiting by host stalls" in line, line
    assert f"{bursts} lost in the glove's own bursts" in line, line
