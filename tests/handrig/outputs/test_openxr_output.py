"""The OpenXR hand-joint stream: its fixed layout, a real UDP round trip, the rate limit,
and the flags and show key that select it."""

from __future__ import annotations

import socket
import struct

import numpy as np
import pytest

from handrig import hand
from handrig.app.parts import check_outputs
from handrig.clock import FakeClock
from handrig.config.show import load_show
from handrig.errors import ConfigError
from handrig.outputs.openxr import (
    DATAGRAM_BYTES,
    DEFAULT_FOREARMS,
    OpenXrSender,
    decode,
    parse_target,
)
from handrig.pose.openxr_hand import XrPose, both_hands, hand_joints


def _receiver() -> tuple[socket.socket, int]:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    return rx, int(rx.getsockname()[1])


def _full_pose(rng: np.random.Generator) -> np.ndarray:
    lim = np.vstack([hand.curve_limits_deg(), [[-30, 30]] * 4])
    return rng.uniform(lim[:, 0], lim[:, 1])


def test_layout_is_the_documented_one() -> None:
    rng = np.random.default_rng(5)
    pose = _full_pose(rng)
    with OpenXrSender("127.0.0.1", 9, clock=FakeClock()) as sender:
        right, left = (bytes(d) for d in sender.encode(1.25, pose))
    assert len(right) == len(left) == DATAGRAM_BYTES == 24 + 26 * 8 * 4
    # the header by hand, as a peer in another language reads it (docs/openxr.md)
    assert right[:4] == b"HRXR" and struct.unpack_from("<H", right, 4) == (1,)
    assert right[6] == 0 and left[6] == 1 and right[7] == 26
    assert struct.unpack_from("<I", right, 8) == (0,)
    assert struct.unpack_from("<d", right, 16) == (1.25,)
    floats = np.frombuffer(right, dtype="<f4", offset=24).reshape(26, 8)
    expected = both_hands(pose, forearms=DEFAULT_FOREARMS)
    assert np.allclose(floats[:, :7], expected["ri"].poses, atol=1e-6)
    assert np.allclose(floats[:, 7], expected["ri"].radii_m, atol=1e-7)
    side, frame, t_s, joints = decode(left)
    assert (side, frame, t_s) == ("le", 0, 1.25)
    assert np.allclose(joints[:, :7], expected["le"].poses, atol=1e-6)
    with pytest.raises(ConfigError, match="not an OpenXR hand datagram"):
        decode(b"#bundle\x00" + bytes(DATAGRAM_BYTES - 8))


def test_udp_round_trip_both_hands_one_frame_number() -> None:
    rx, port = _receiver()
    clock = FakeClock()
    rng = np.random.default_rng(9)
    forearm = XrPose((0.3, 1.2, -0.4))
    with rx, OpenXrSender("127.0.0.1", port, clock=clock, forearms={"ri": forearm}) as tx:
        poses = [_full_pose(rng) for _ in range(3)]
        for k, pose in enumerate(poses):
            tx(0.01 * k, pose)
            clock.advance(1.0)
        got = [decode(rx.recv(4096)) for _ in range(6)]
        assert tx.status().frames_written == 3 and tx.errors == 0
        assert tx.status().bytes_written == 6 * DATAGRAM_BYTES
    for k, pose in enumerate(poses):
        by_hand = {g[0]: g for g in got if g[1] == k}
        assert set(by_hand) == {"ri", "le"}
        right = hand_joints(pose[:25], "ri", wrist_deg=pose[50:52], forearm=forearm)
        assert np.allclose(by_hand["ri"][3][:, :7], right.poses, atol=1e-6)
        assert by_hand["ri"][2] == pytest.approx(0.01 * k)


def test_rate_limit_on_injected_clock() -> None:
    clock = FakeClock()
    with OpenXrSender("127.0.0.1", 9, rate_hz=50.0, clock=clock) as tx:
        for _ in range(100):  # 1 s of a 100 Hz loop
            tx(clock.now(), np.zeros(54))
            clock.advance(0.01)
        assert tx.status().frames_written == 50 and tx.skipped == 50


def test_closed_socket_counts_errors_not_raises() -> None:
    tx = OpenXrSender("127.0.0.1", 9, clock=FakeClock())
    tx.close()
    tx(0.0, np.zeros(54))
    assert tx.errors == 2 and "OpenXR send to 127.0.0.1:9" in tx.last_error
    key, figures = tx.summary(1.0)
    assert key == "openxr" and figures["errors"] == 2 and figures["frames_sent"] == 0


@pytest.mark.parametrize("text", ["127.0.0.1:0", "127.0.0.1:70000", "host:port", ":"])
def test_bad_destination_is_a_config_error(text: str) -> None:
    with pytest.raises(ConfigError, match="--openxr"):
        parse_target(text)


def test_flag_without_port_is_refused_before_any_device() -> None:
    with pytest.raises(ConfigError, match="--openxr") as err:
        check_outputs(None, None, "127.0.0.1")
    assert "39540" in str(err.value)
    check_outputs(None, None, "127.0.0.1:39540")


def test_show_file_outputs_openxr(tmp_path) -> None:
    show = tmp_path / "show.toml"
    show.write_text('[show]\nrig = "puppet_two_hands"\n[outputs]\nopenxr = "127.0.0.1:39540"\n')
    assert load_show(show).outputs.openxr == "127.0.0.1:39540"
    show.write_text('[show]\nrig = "puppet_two_hands"\n[outputs]\nopenxr = "127.0.0.1"\n')
    with pytest.raises(ConfigError, match="openxr"):
        load_show(show)
