"""``handrig play TAKE --openxr HOST:PORT`` without a bus: the take's hands as OpenXR
joints beside the VMC bundles, each datagram the joints of a recorded frame."""

from __future__ import annotations

import contextlib
import json
import socket
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.cli import main
from handrig.outputs.openxr import decode
from handrig.outputs.recorder import Recorder
from handrig.pose.openxr_hand import TIPS, hand_joints


def _recording(path: Path, n: int = 30, rate_hz: float = 100.0) -> np.ndarray:
    """A take whose index finger closes from 0 to 90 deg at every joint over 0.3 s."""
    poses = np.zeros((n, 50))
    for j in ("MCPy", "PIPy", "DIPy"):
        poses[:, hand.curve_index(f"riIndex{j}")] = np.linspace(0.0, 90.0, n)
    with Recorder(path, rate_hz=rate_hz) as rec:
        for i in range(n):
            rec.add(i / rate_hz, poses[i])
    return poses


def test_play_sends_openxr_joints_beside_vmc(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    poses = _recording(tmp_path / "take.csv")
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.5)
    with rx:
        port = rx.getsockname()[1]
        status = main(["play", str(tmp_path / "take.csv"), "--vmc", "127.0.0.1:9",
                       "--openxr", f"127.0.0.1:{port}", "--rate", "50", "--json"])
        got = []
        with contextlib.suppress(TimeoutError):
            while True:
                got.append(decode(rx.recv(4096)))
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    sent = summary["openxr"]
    assert sent["errors"] == 0 and 10 <= sent["frames_sent"] <= 20  # 0.3 s at 50 Hz
    right = [g for g in got if g[0] == "ri"]
    assert len(right) == sent["frames_sent"] and len(got) == 2 * len(right)
    # each right hand is one of the take's frames; the index tip comes back toward the palm
    reach = []
    candidates = [hand_joints(p[:25], "ri").positions_m for p in poses]
    for _, _, _, joints in right:
        local = joints[:, :3] - joints[1, :3]  # from the wrist (the stream's sits at +0.1 m x)
        err = [np.abs(local - (c - c[1])).max() for c in candidates]
        assert min(err) < 1e-5
        reach.append(np.linalg.norm(local[TIPS[1]]))
    assert reach[-1] < reach[0] - 0.05


def test_play_refuses_an_openxr_target_without_port(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _recording(tmp_path / "take.csv")
    status = main(["play", str(tmp_path / "take.csv"), "--vmc", "127.0.0.1:9",
                   "--openxr", "127.0.0.1", "--json"])
    assert status == 2
    assert "--openxr '127.0.0.1': no port given" in capsys.readouterr().err
