"""The view's server without a browser: addresses, the token, a port in use, bad
input on the socket, closing; the scene export from the real MuJoCo models."""

from __future__ import annotations

import base64
import dataclasses
import itertools
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from handrig.app import simulator
from handrig.app.parts import build_parts
from handrig.app.view import ModelScene, build_server, is_loopback, parse_view_address
from handrig.errors import ConfigError
from tests.helpers.view import Controls


def test_address_parsing() -> None:
    assert parse_view_address("8765") == ("127.0.0.1", 8765)
    assert parse_view_address("0.0.0.0:9000") == ("0.0.0.0", 9000)
    assert parse_view_address("[::1]:9000") == ("::1", 9000)
    assert parse_view_address(":0") == ("127.0.0.1", 0)
    for bad in ("x", "1:2:x", "70000", "-1"):
        with pytest.raises(ConfigError, match="--view"):
            parse_view_address(bad)
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.0.2.1")


def test_loopback_has_no_token_other_hosts_do(human_rig) -> None:  # type: ignore[no-untyped-def]
    assert build_server("127.0.0.1:0", human_rig).token is None
    server = build_server("0.0.0.0:0", human_rig)
    assert server.token and len(server.token) >= 16
    assert f"?token={server.token}" in server.url


def test_token_guards_page_and_socket(human_rig) -> None:  # type: ignore[no-untyped-def]
    with build_server("0.0.0.0:0", human_rig) as server:
        base = f"http://127.0.0.1:{server.port}/"
        with pytest.raises(urllib.error.HTTPError) as denied:
            urllib.request.urlopen(base, timeout=5)
        assert denied.value.code == 403
        with pytest.raises(Exception, match="403"):
            connect(f"ws://127.0.0.1:{server.port}/ws?token=wrong", open_timeout=5)
        page = urllib.request.urlopen(f"{base}?token={server.token}", timeout=5).read()
        assert b"handrig view" in page
        with connect(f"ws://127.0.0.1:{server.port}/ws?token={server.token}") as ws:
            assert json.loads(ws.recv(timeout=5))["type"] == "scene"


def test_another_sites_page_cannot_open_the_socket(human_rig) -> None:  # type: ignore[no-untyped-def]
    """On loopback there is no token, so the browser's Origin is what keeps another site's
    page (open in the same browser) from pressing relax or stop; the view's own page,
    at whatever host name it was opened, gets in."""
    with build_server("127.0.0.1:0", human_rig) as server:
        url = f"ws://127.0.0.1:{server.port}/ws"
        with pytest.raises(Exception, match="403"):
            connect(url, origin="http://evil.example", open_timeout=5)  # type: ignore[arg-type]
        with connect(url, origin=f"http://127.0.0.1:{server.port}") as ws:  # type: ignore[arg-type]
            assert json.loads(ws.recv(timeout=5))["type"] == "scene"
        with connect(url) as ws:  # a program on this machine sends no Origin
            assert json.loads(ws.recv(timeout=5))["type"] == "scene"


def test_page_and_vendored_files_served(human_rig) -> None:  # type: ignore[no-untyped-def]
    with build_server("127.0.0.1:0", human_rig) as server:
        base = f"http://127.0.0.1:{server.port}"
        page = urllib.request.urlopen(base + "/", timeout=5).read().decode()
        for path in ("/static/view.js", "/static/vendor/three/three.module.js",
                     "/static/vendor/three/OrbitControls.js"):
            assert path in page
            with urllib.request.urlopen(base + path, timeout=5) as reply:
                assert reply.headers["Content-Type"] == "text/javascript"
                assert len(reply.read()) > 1000
        assert "http://" not in page and "https://" not in page  # nothing from the internet
        with pytest.raises(urllib.error.HTTPError) as missing:
            urllib.request.urlopen(base + "/static/../server.py", timeout=5)
        assert missing.value.code == 404


def test_port_in_use_names_the_port(human_rig) -> None:  # type: ignore[no-untyped-def]
    with build_server("127.0.0.1:0", human_rig) as first:
        second = build_server(f"127.0.0.1:{first.port}", human_rig)
        with pytest.raises(ConfigError, match=f"port {first.port} on 127.0.0.1 is in use"):
            second.start()


def test_garbage_and_disconnects_cost_nothing(human_rig) -> None:  # type: ignore[no-untyped-def]
    controls = Controls()
    with build_server("127.0.0.1:0", human_rig) as server:
        server.attach(lambda: None, controls)
        url = f"ws://127.0.0.1:{server.port}/ws"
        with connect(url) as ws:
            ws.recv(timeout=5)
            for junk in ("not json", "[1, 2]", '{"action": "selfdestruct"}', b"\x00\xff" * 8,
                         '{"action": 5}'):
                ws.send(junk)
        with connect(url) as ws:  # a message over the limit closes only that socket
            ws.recv(timeout=5)
            ws.send("x" * 5000)
            with pytest.raises(Exception):  # noqa: B017  closed by the server (1009)
                ws.recv(timeout=5)
        for _ in range(5):  # browsers that vanish mid-handshake or without a close
            raw = socket.create_connection(("127.0.0.1", server.port), timeout=5)
            raw.sendall(b"GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n")
            raw.close()
        with connect(url) as ws:
            assert json.loads(ws.recv(timeout=5))["type"] == "scene"
            ws.send(json.dumps({"action": "relax"}))
            ws.send(json.dumps({"action": "estop"}))
            deadline = time.monotonic() + 5
            while len(controls.calls) < 2 and time.monotonic() < deadline:
                time.sleep(0.01)
        assert controls.calls == ["relax", "estop"]
        assert server.stats.bad_messages == 5


def test_close_frees_the_port(human_rig) -> None:  # type: ignore[no-untyped-def]
    server = build_server("127.0.0.1:0", human_rig).start()
    port = server.port
    with connect(f"ws://127.0.0.1:{port}/ws") as ws:
        ws.recv(timeout=5)
        server.close()
        with pytest.raises(Exception):  # noqa: B017  the server closed the socket
            ws.recv(timeout=5)
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port), timeout=2).close()
    build_server(f"127.0.0.1:{port}", human_rig).start().close()  # the port is free again


class _StalledBrowser:
    """A WebSocket client on a raw socket with a small receive buffer, that reads only
    when told to (a frozen tab, or a phone whose network went away)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        self.sock.settimeout(5)
        self.sock.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n".encode())
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            self.buf += self._recv()
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        assert head.startswith(b"HTTP/1.1 101"), head

    def _recv(self) -> bytes:
        data = self.sock.recv(65536)
        if not data:
            raise EOFError
        return data

    def _need(self, n: int) -> bytes:
        while len(self.buf) < n:
            self.buf += self._recv()
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def message(self) -> dict:
        """The next text message (the server's are unmasked and unfragmented)."""
        b0, b1 = self._need(2)
        assert b0 == 0x81 and b1 & 0x80 == 0, (b0, b1)  # FIN + text, not masked
        n = b1 & 0x7F
        if n == 126:
            n = int.from_bytes(self._need(2), "big")
        elif n == 127:
            n = int.from_bytes(self._need(8), "big")
        return json.loads(self._need(n))


def test_a_browser_that_stops_reading_skips_frames_and_cannot_hold_the_close(human_rig) -> None:  # type: ignore[no-untyped-def]
    """A browser that stops reading has at most a few frames on their way to it (left to
    the kernel, 4 MB: 20 s of stale frames), gets the newest frame when it reads again,
    and cannot hold the server's close: its socket is cut after the close's grace, and
    the server's thread ends (it used to wait on that browser for ever)."""
    base = _snapshot(human_rig, positions=True)
    seqs = itertools.count(1)
    server = build_server("127.0.0.1:0", human_rig).start()
    server.attach(lambda: dataclasses.replace(base, seq=next(seqs)))
    stalled = _StalledBrowser(server.port)
    try:
        assert stalled.message()["type"] == "scene"

        def behind(frames: int) -> None:  # frames encoded that the browser did not get
            deadline = time.monotonic() + 10
            start = server.stats.frames_encoded
            while server.stats.frames_encoded - start < frames:
                assert time.monotonic() < deadline, server.stats
                time.sleep(0.05)
        behind(30)  # 1 s at 30 frames a second, not read
        newest = server.stats.frames_encoded
        assert server.stats.frames_sent < newest - 10, server.stats  # the sender waits
        stale = 0
        while (seq := stalled.message()["seq"]) < newest:
            stale += 1
        assert stale <= 25, f"{stale} stale frames were on their way to the browser"
        assert server.stats.frames_skipped > 0  # it got the newest, not every frame
        assert seq >= newest

        behind(30)  # stalled again, then the run ends
        server.close()
        threads = [t.name for t in threading.enumerate() if t.name == "handrig-view"]
        assert threads == [], "the view's thread still waits on the stalled browser"
        with pytest.raises((EOFError, ConnectionResetError)):
            while True:  # what was queued, then the cut
                stalled.message()
    finally:
        stalled.sock.close()
        server.close()


@pytest.mark.parametrize("rig", [None, "leap", "orca"])
def test_scene_from_the_rigs_model(rig: str | None) -> None:
    cfg = build_parts(rig).rig_config
    models = simulator.view_models(cfg)
    scene = ModelScene(models["ri"])
    geometry = scene.geometry()
    assert len(geometry["bodies"]) == models["ri"].nbody
    assert len(geometry["geoms"]) >= 10
    if rig is not None:  # a robot hand is drawn from its meshes, not its collision geoms
        assert {g["kind"] for g in geometry["geoms"]} == {"mesh"}
        assert len(geometry["meshes"]) == models["ri"].nmesh >= 10
        assert all(len(m["vertices"]) % 3 == 0 and len(m["faces"]) % 3 == 0
                   and max(m["faces"]) < len(m["vertices"]) // 3
                   for m in geometry["meshes"].values())
        palm_body = {"leap": "palm", "orca": "right_R-Carpals_8d1f1041"}[rig]
        palm = [i for i, b in enumerate(geometry["bodies"]) if b["name"] == palm_body]
        assert palm and any(g["body"] == palm[0] for g in geometry["geoms"])  # the palm's mesh
    joint = cfg.servos[1].joint
    rest, bent = scene.pose({}), scene.pose({joint: 40.0})
    nbody = models["ri"].nbody
    assert len(rest["pos"]) == 3 * nbody and len(rest["quat"]) == 4 * nbody
    moved = (np.abs(np.subtract(rest["quat"], bent["quat"])).reshape(nbody, 4) > 1e-3).any(1)
    assert moved.any() and not moved.all()  # the bodies below that joint, not the root


def test_skeleton_bends_with_the_pose() -> None:
    models = simulator.human_hand_models()
    hand = ModelScene(models["le"])
    straight = np.reshape(hand.skeleton({}), (-1, 2, 3))
    bent = np.reshape(hand.skeleton({"leIndexPIPy": 80.0, "leIndexDIPy": 60.0}), (-1, 2, 3))
    assert straight.shape == bent.shape and straight.shape[0] >= 19  # every bone and tip
    assert 0 < np.count_nonzero(np.abs(straight - bent).max(axis=(1, 2)) > 1e-4) <= 3


def test_demo_on_a_port_in_use_says_which_and_starts_nothing() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = subprocess.run(
            [sys.executable, "-m", "handrig.cli", "demo", "--frames", "10", "--view",
             str(port)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert f"--view '{port}': port {port} on 127.0.0.1 is in use" in done.stderr
    assert "glove emulator streaming" not in done.stdout  # nothing started


def _snapshot(cfg, *, positions: bool, nan_pose: bool = False):  # type: ignore[no-untyped-def]
    from handrig.loop.telemetry import LoopSnapshot
    from handrig.outputs.base import OutputStatus
    from handrig.pose.pipeline import POSE_NAMES

    n = len(cfg.servos)
    goals = tuple(30.0 if "PIP" in s.joint else 0.0 for s in cfg.servos)
    return LoopSnapshot(
        t_s=1.0, seq=3, mode="running", mode_reason="following the glove", rate_hz=200.0,
        latency_p50_us=150.0, latency_p99_us=float("nan"), frames_lost=2, cycles=400,
        overruns=1, controls=(0.5,), raw=(2000.0,), control_names=("riIndexMCPy",),
        inclination_deg=-20.0, rotation_deg=5.0, glove_connected=True,
        pose_deg=tuple(float("nan") if nan_pose else 10.0 for _ in POSE_NAMES),
        curve_names=POSE_NAMES, servo_ids=tuple(s.id for s in cfg.servos),
        servo_joints=tuple(s.joint for s in cfg.servos), goals_deg=goals,
        positions_deg=tuple(g - 5.0 for g in goals) if positions else (None,) * n,
        temperatures_c=(31.0,) * n, hardware_errors=(0,) * (n - 1) + (0x20,),
        stale=(False,) * n, outputs=(OutputStatus(kind="vmc", name="VMC",
                                                   address="127.0.0.1:39539"),))


def test_frame_from_a_snapshot(human_rig) -> None:  # type: ignore[no-untyped-def]
    encoder = build_server("127.0.0.1:0", human_rig).encoder
    read = json.loads(encoder.frame(_snapshot(human_rig, positions=True)))
    (hand,) = read["hands"]  # one loop driving the whole rig: a frame of one hand
    assert (hand["hand"], hand["label"]) == ("", "")
    assert hand["source"] == "positions" and read["ghost"] is not None
    assert hand["latency_p99_us"] is None  # NaN is not JSON: sent as null
    assert hand["servos"]["errors"][-1] == 0x20 and hand["servos"]["position_deg"][0] == -5.0
    assert read["outputs"][0]["kind"] == "vmc" and read["outputs"][0]["address"]
    assert set(read["skeleton"]) == {"ri", "le"}  # the pose holds both hands
    assert read["bodies"]["ri"]["pos"] != read["ghost"]["ri"]["pos"]  # 5 degrees apart
    unread = json.loads(encoder.frame(_snapshot(human_rig, positions=False, nan_pose=True)))
    assert unread["hands"][0]["source"] == "goals" and unread["ghost"] is None
    assert all(len(s) > 0 for s in unread["skeleton"].values())  # at rest, not NaN
    scene = json.loads(encoder.scene())
    assert scene["type"] == "scene" and set(scene["rest"]) == set(scene["models"]) == {"ri"}


def test_two_hand_frame_has_each_hands_part_and_poses_each_from_its_own() -> None:
    """A two-hand run's frame: each hand's figures, its own glove controls and servos;
    each hand of the model posed from its own loop's snapshot (the right from its
    readings with a ghost, the left, without readings, from its goals)."""
    import dataclasses

    from handrig.app.view import HandsSnapshot
    from handrig.config.rig import hand_rig

    cfg = build_parts("puppet_two_hands").rig_config
    encoder = build_server("127.0.0.1:0", cfg).encoder
    right = dataclasses.replace(_snapshot(hand_rig(cfg, "ri"), positions=True),
                                control_names=("riIndexMCPy", "leIndexMCPy"),
                                controls=(0.5, -0.25), raw=(2000.0, math.nan))
    left = dataclasses.replace(_snapshot(hand_rig(cfg, "le"), positions=False), seq=5,
                               mode="relaxing", mode_reason="the left glove is silent",
                               control_names=("riIndexMCPy", "leIndexMCPy"),
                               controls=(0.5, -0.25), raw=(math.nan, 1800.0))
    both = HandsSnapshot({"ri": right, "le": left})
    assert both.seq == 8  # changes when either hand's does
    read = json.loads(encoder.frame(both))
    ri, le = read["hands"]
    assert (ri["hand"], ri["label"], le["hand"], le["label"]) == ("ri", "right", "le", "left")
    assert (ri["mode"], le["mode"], le["mode_reason"]) == ("running", "relaxing",
                                                          "the left glove is silent")
    assert (ri["source"], le["source"]) == ("positions", "goals")
    assert ri["glove"]["names"] == ["riIndexMCPy"] and ri["glove"]["controls"] == [0.5]
    assert le["glove"]["names"] == ["leIndexMCPy"] and le["glove"]["controls"] == [-0.25]
    # raw is in control order (each control's own channel; the other hand's: none)
    assert ri["glove"]["raw"] == [2000.0] and le["glove"]["raw"] == [1800.0]
    assert all(j.startswith("ri") for j in ri["servos"]["joints"])
    assert all(j.startswith("le") for j in le["servos"]["joints"])
    assert len(ri["servos"]["ids"]) + len(le["servos"]["ids"]) == len(cfg.servos)
    assert set(read["bodies"]) == {"ri", "le"} and set(read["ghost"]) == {"ri"}
    assert set(read["skeleton"]) == {"ri", "le"}
    # the left hand is posed from its goals: the same as a one-hand frame of its snapshot
    alone = json.loads(encoder.frame(left))
    assert read["bodies"]["le"] == alone["bodies"]["le"]
    assert read["bodies"]["ri"] != alone["bodies"]["ri"]  # the right from its readings
    assert len(read["outputs"]) == 2  # both loops' outputs


def view_port(proc: subprocess.Popen[str]) -> int:
    """The port of the view a ``handrig ... --view 127.0.0.1:0`` run prints at its start."""
    assert proc.stderr is not None
    url = ""
    deadline = time.monotonic() + 120
    while not url and time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        if line.startswith("view: "):
            url = line.split()[1]
    assert url.startswith("http://127.0.0.1:"), url
    return int(url.rsplit(":", 1)[1].strip("/"))


@pytest.mark.parametrize("end", ["estop", "ctrl-c"])
def test_run_view_streams_real_telemetry_and_ends_with_the_run(end: str) -> None:
    """Without a browser: ``handrig run --view`` on the simulated rig; a WebSocket
    client gets the scene and frames of the real loop; its e-stop ends the run, or a
    Ctrl-C at the terminal (to the run's process group) eases it down; either way the
    view's server is closed when the run has ended."""
    recording = simulator.demo_recording()
    proc = subprocess.Popen(
        [sys.executable, "-m", "handrig.cli", "run", "--bus", "sim", "--glove",
         f"replay:{recording}", "--frames", "20000", "--json", "--view", "127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        port = view_port(proc)
        # max_queue=None: the client takes in every frame while the run eases down, as a
        # browser does; with the default bound it stops reading after 16 unread frames and
        # misses the server's close, which then waits its grace (1 s) and cuts the socket
        # (test_a_browser_that_stops_reading_skips_frames_and_cannot_hold_the_close)
        with connect(f"ws://127.0.0.1:{port}/ws", max_queue=None) as ws:
            assert json.loads(ws.recv(timeout=30))["type"] == "scene"
            frames = [json.loads(ws.recv(timeout=30)) for _ in range(5)]
            assert [f["type"] for f in frames] == ["frame"] * 5
            assert frames[-1]["seq"] > frames[0]["seq"]
            (hand,) = frames[-1]["hands"]  # one glove: one hand, the whole rig
            assert hand["mode"] in ("running", "waiting", "resuming")
            assert len(hand["servos"]["ids"]) == 20
            ws.send("garbage")
            if end == "estop":
                ws.send(json.dumps({"action": "estop"}))
            else:
                os.killpg(proc.pid, signal.SIGINT)
            out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["torque_off"] is True
    if end == "estop":
        assert summary["estop"] is True and summary["stop_reason"] == "e-stop button (view)"
    else:
        assert summary["estop"] is False and summary["signals"]
    with pytest.raises(OSError):  # the run's exit closed the view's server
        socket.create_connection(("127.0.0.1", port), timeout=2).close()


def test_two_bus_run_view_streams_both_hands_and_its_estop_ends_both() -> None:
    """Without a browser: ``handrig run --rig puppet_two_buses --bus sim --bus-left sim``
    with a glove per hand and ``--view``: the frames carry both hands, each with its
    own bus's servos read back; the socket's e-stop ends both loops with torque off on
    both buses."""
    recording = simulator.demo_recording()
    proc = subprocess.Popen(
        [sys.executable, "-m", "handrig.cli", "run", "--rig", "puppet_two_buses", "--bus",
         "sim", "--bus-left", "sim", "--glove", f"replay:{recording}", "--glove-left",
         f"replay:{recording}", "--frames", "20000", "--json", "--view", "127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = view_port(proc)
        with connect(f"ws://127.0.0.1:{port}/ws", max_queue=None) as ws:  # reads all, as above
            scene = json.loads(ws.recv(timeout=30))
            assert set(scene["models"]) == {"ri", "le"}
            frame: dict = {}
            for _ in range(100):  # until both hands' servos have answered
                try:
                    frame = json.loads(ws.recv(timeout=30))
                except ConnectionClosed:  # the run ended on its own (seen once in 10)
                    _, err = proc.communicate(timeout=30)
                    raise AssertionError("the run ended before both hands' servos "
                                         f"answered; it said:\n{err[-3000:]}") from None
                if all(h["source"] == "positions" for h in frame["hands"]):
                    break
            assert [h["label"] for h in frame["hands"]] == ["right", "left"]
            for h in frame["hands"]:
                assert len(h["servos"]["ids"]) == 20
                assert all(j.startswith(h["hand"]) for j in h["servos"]["joints"])
                assert any(p is not None for p in h["servos"]["position_deg"])
                assert h["cycles"] > 0 and h["rate_hz"] is not None
            assert set(frame["bodies"]) == {"ri", "le"} and set(frame["ghost"]) == {"ri", "le"}
            ws.send(json.dumps({"action": "estop"}))
            out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["buses"] == "two" and summary["torque_off"] is True
    for hand in ("right", "left"):
        s = summary["hands"][hand]
        assert s["estop"] is True and s["stop_reason"] == "e-stop button (view)", hand


def _may_use_fifo() -> bool:
    """Whether a thread of this process may take SCHED_FIFO here (root, CAP_SYS_NICE)."""
    import threading

    from handrig.realtime import realtime_priority

    got: list[bool] = []

    def probe() -> None:
        with realtime_priority(1) as ok:
            got.append(ok)

    t = threading.Thread(target=probe)
    t.start()
    t.join()
    return got[0]


def test_view_process_feeder_below_the_loop_child_off_its_cpu(human_rig) -> None:  # type: ignore[no-untyped-def]
    """The feeder shares the GIL with the loop: it runs one SCHED_FIFO priority below the
    loop's (where the host allows), so a browser cannot preempt it while it holds the
    lock; the view's process stays off the loop's CPU, niced."""
    from handrig.app.view.process import CHILD_NICE, ViewProcess
    from handrig.realtime import cpu_split

    assert human_rig.loop.realtime_priority > 1
    snap = _snapshot(human_rig, positions=True)
    with ViewProcess("127.0.0.1:0", human_rig) as view:
        assert view.feeder_priority() == human_rig.loop.realtime_priority - 1
        view.attach(lambda: snap)
        tid = view.feeder_thread_id
        assert tid is not None and view.pid is not None
        fifo = _may_use_fifo()
        deadline = time.monotonic() + 5
        while os.sched_getscheduler(tid) != os.SCHED_FIFO and time.monotonic() < deadline:
            time.sleep(0.01)
        if fifo:
            assert os.sched_getscheduler(tid) == os.SCHED_FIFO
            assert os.sched_getparam(tid).sched_priority == view.feeder_priority()
        else:
            assert os.sched_getscheduler(tid) == os.SCHED_OTHER
        loop_cpu, others = cpu_split()
        if loop_cpu is not None:
            assert os.sched_getaffinity(view.pid) == set(others)
        assert os.getpriority(os.PRIO_PROCESS, view.pid) >= CHILD_NICE
        with connect(view.url.replace("http://", "ws://").rstrip("/") + "/ws") as ws:
            assert json.loads(ws.recv(timeout=30))["type"] == "scene"
            assert json.loads(ws.recv(timeout=30))["seq"] == snap.seq
