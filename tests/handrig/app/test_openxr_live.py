"""``handrig run --openxr``: a short run on the simulated rig streams both hands' OpenXR
joints over UDP, each datagram the joints of the pose the run recorded at that time."""

from __future__ import annotations

import contextlib
import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from handrig.outputs.openxr import DEFAULT_FOREARMS, decode
from handrig.outputs.recorder import load_performance
from handrig.pose.openxr_hand import TIPS, WRIST, both_hands
from sim.demo_recording import DEMO_RECORDING

CLI = [sys.executable, "-m", "handrig.cli"]


def test_run_streams_openxr_hand_joints(tmp_path: Path) -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.05)
    port = rx.getsockname()[1]
    take = tmp_path / "take.csv"
    proc = subprocess.Popen(
        [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", "sim", "--frames", "200",
         "--openxr", f"127.0.0.1:{port}", "--record", str(take), "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    got = []
    deadline = time.monotonic() + 90
    while proc.poll() is None and time.monotonic() < deadline:
        with contextlib.suppress(TimeoutError):
            got.append(decode(rx.recv(4096)))
    out, err = proc.communicate(timeout=30)
    with rx:
        rx.settimeout(0.2)
        try:
            while True:
                got.append(decode(rx.recv(4096)))
        except TimeoutError:
            pass
    assert proc.returncode == 0, err
    summary = json.loads(out)
    sent = summary["outputs"]["openxr"]
    assert sent["errors"] == 0 and sent["hands"] == ["ri", "le"]
    # 1.5 s of the 200 Hz glove at the sender's 90 Hz, both hands each frame, none lost
    assert sent["frames_sent"] > 60
    assert len(got) == 2 * sent["frames_sent"]
    frames = [g[1] for g in got if g[0] == "ri"]
    assert frames == list(range(len(frames)))
    # each datagram is the joints of the pose the recorder took at the same time
    t, curves, wrist = load_performance(take)
    assert wrist is not None
    checked = 0
    for side, _, t_s, joints in got[::15]:
        row = int(np.argmin(np.abs(t - t_s)))
        if abs(t[row] - t_s) > 1e-4:
            continue
        expected = both_hands(np.concatenate([curves[row], wrist[row]]),
                              forearms=DEFAULT_FOREARMS)[side]
        assert np.allclose(joints[:, :3], expected.positions_m, atol=2e-4)  # 0.2 mm
        checked += 1
    assert checked >= 5
    # metres: every fingertip within a hand's length of its wrist, and the fingers move
    right = np.stack([g[3] for g in got if g[0] == "ri"])
    reach = np.linalg.norm(right[:, list(TIPS), :3] - right[:, [WRIST], :3], axis=2)
    assert reach.max() < 0.2 and reach.min() > 0.03
    assert np.ptp(reach[:, 1:], axis=0).max() > 0.005  # a finger's tip moved over 5 mm
