"""``handrig play``: a recording reaches a real python-osc VMC receiver over UDP."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer

from handrig import hand
from handrig.cli import main
from handrig.outputs import vmc
from handrig.outputs.recorder import Recorder


def _recording(path: Path, n: int = 30, rate_hz: float = 100.0) -> np.ndarray:
    rng = np.random.default_rng(5)
    lim = hand.curve_limits_deg()
    poses = rng.uniform(lim[:, 0], lim[:, 1], (n, 50))
    with Recorder(path, rate_hz=rate_hz) as rec:
        for i in range(n):
            rec.add(i / rate_hz, poses[i])
    return poses


def test_play_sends_the_recording_to_a_vmc_receiver(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    poses = _recording(tmp_path / "take.csv")  # 0.3 s
    bones: list[tuple] = []
    times: list[float] = []
    d = Dispatcher()
    d.map("/VMC/Ext/Bone/Pos", lambda _a, *args: bones.append(args))
    d.map("/VMC/Ext/T", lambda _a, t: times.append(t))
    server = BlockingOSCUDPServer(("127.0.0.1", 0), d)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.01})
    thread.start()
    try:
        port = server.server_address[1]
        status = main(["play", str(tmp_path / "take.csv"), "--vmc", f"127.0.0.1:{port}",
                       "--rate", "50", "--json"])
    finally:
        server.shutdown()
        thread.join()
        server.server_close()
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 30 and summary["errors"] == 0
    assert 10 <= summary["bundles_sent"] <= 20  # 0.3 s at 50 Hz
    assert len(times) == summary["bundles_sent"]
    assert all(np.diff(times) > 0)
    # every bundle carries the recorded frame due at its time stamp /VMC/Ext/T
    n = len(vmc.BONES)
    for k, t in enumerate(times):
        back = vmc.decode_bones(np.array([b[4:8] for b in bones[k * n:(k + 1) * n]]))
        err = np.abs(poses - back[:50]).max(axis=1)
        frame = int(np.argmin(err))
        assert err[frame] < 2e-3
        assert abs(frame - t * 100.0) <= 1.0


def test_play_bad_inputs_are_one_line_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["play", str(tmp_path / "missing.bvh")]) == 2
    assert "missing.bvh: recording not found" in capsys.readouterr().err
    _recording(tmp_path / "take.csv", n=2)
    assert main(["play", str(tmp_path / "take.csv"), "--vmc", "localhost:99999"]) == 2
    assert "--vmc" in capsys.readouterr().err
    assert main(["play", str(tmp_path / "take.csv"), "--rate", "0"]) == 2
    assert "--rate" in capsys.readouterr().err


def test_without_bus_a_glove_take_or_a_window_is_refused_saying_what_to_add(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from handrig.devices.glove_recording import sweep_recording, write_glove_recording

    glove = tmp_path / "glove.csv"
    write_glove_recording(glove, sweep_recording(0.2))
    assert main(["play", str(glove)]) != 0
    err = capsys.readouterr().err
    assert str(glove) in err and "--bus" in err
    _recording(tmp_path / "take.csv")
    assert main(["play", str(tmp_path / "take.csv"), "--from", "0.1"]) != 0
    assert "--from" in capsys.readouterr().err
