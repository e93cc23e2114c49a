"""VMC output: Unity bone names, the quaternion convention, python-osc compatibility, UDP."""

from __future__ import annotations

import re
import socket
from typing import Any

import numpy as np
import pytest
from pythonosc import osc_bundle_builder, osc_message_builder
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer
from scipy.spatial.transform import Rotation

from handrig import hand
from handrig.clock import FakeClock
from handrig.errors import ConfigError
from handrig.outputs import vmc


def _random_pose(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lim = hand.curve_limits_deg()
    pose = rng.uniform(lim[:, 0], lim[:, 1])
    wrist = rng.uniform([-70, -30, -70, -30], [80, 20, 80, 20])
    return pose, wrist


def _driven_slots() -> np.ndarray:
    return np.unique([s for b in vmc.BONES for s in (b.abd, b.flex, b.twist) if s < 54])


def test_bone_names_are_unity_humanbodybones() -> None:
    pattern = re.compile(
        r"^(Left|Right)(Hand|(Thumb|Index|Middle|Ring|Little)(Proximal|Intermediate|Distal))$"
    )
    assert len(vmc.BONE_NAMES) == 32 == len(set(vmc.BONE_NAMES))
    assert all(pattern.match(n) for n in vmc.BONE_NAMES)
    assert "RightLittleDistal" in vmc.BONE_NAMES and "LeftThumbProximal" in vmc.BONE_NAMES


def test_every_curve_and_wrist_dof_drives_exactly_one_bone_axis() -> None:
    slots = [s for b in vmc.BONES for s in (b.abd, b.flex, b.twist) if s < 54]
    assert sorted(slots) == list(range(54))


@pytest.mark.parametrize(
    ("curve", "bone", "tip_unity"),
    [
        # palms down in T-pose: flexion takes the tips down (-Y), on both hands
        ("riIndexMCPy", "RightIndexProximal", (0, -1, 0)),
        ("leIndexMCPy", "LeftIndexProximal", (0, -1, 0)),
        ("riPinkyPIPy", "RightLittleIntermediate", (0, -1, 0)),
        ("leRingDIPy", "LeftRingDistal", (0, -1, 0)),
    ],
)
def test_flexion_curls_toward_the_palm(curve: str, bone: str, tip_unity: tuple) -> None:
    v = np.zeros(55)
    v[hand.curve_index(curve)] = 90.0
    q = vmc.bone_quaternions(v)[vmc.BONE_NAMES.index(bone)]
    distal = np.array([1.0 if bone.startswith("Right") else -1.0, 0, 0])
    np.testing.assert_allclose(Rotation.from_quat(q).apply(distal), tip_unity, atol=1e-12)


def test_abduction_radial_positive_swings_tips_forward() -> None:
    v = np.zeros(55)
    v[hand.curve_index("riIndexMCPx")] = 20.0
    v[hand.curve_index("leIndexMCPx")] = 20.0
    q = vmc.bone_quaternions(v)
    for bone, sign in (("RightIndexProximal", 1.0), ("LeftIndexProximal", -1.0)):
        tip = Rotation.from_quat(q[vmc.BONE_NAMES.index(bone)]).apply([sign, 0, 0])
        assert tip[2] == pytest.approx(np.sin(np.radians(20.0)))  # Unity +Z: forward


def test_left_hand_is_the_mirror_of_the_right() -> None:
    pose, wrist = _random_pose(3)
    v = np.concatenate([hand.mirror_pose(pose), wrist[[2, 3, 0, 1]], [0.0]])
    q = vmc.bone_quaternions(np.concatenate([pose, wrist, [0.0]]))
    qm = vmc.bone_quaternions(v)
    # mirroring across the sagittal plane (Unity x -> -x): q -> (qx, -qy, -qz, qw)
    right = [i for i, n in enumerate(vmc.BONE_NAMES) if n.startswith("Right")]
    left = [vmc.BONE_NAMES.index("Left" + vmc.BONE_NAMES[i][5:]) for i in right]
    mirrored = q[right] * np.array([1, -1, -1, 1])
    dots = np.abs(np.sum(mirrored * qm[left], axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-12)


def test_quaternions_decode_back_to_the_pose() -> None:
    slots = _driven_slots()
    for seed in range(5):
        pose, wrist = _random_pose(seed)
        v = np.concatenate([pose, wrist, [0.0]])
        back = vmc.decode_bones(vmc.bone_quaternions(v))
        np.testing.assert_allclose(back[slots], v[slots], atol=1e-9)


def _python_osc_bundle(quats: np.ndarray, t_s: float) -> bytes:
    b = osc_bundle_builder.OscBundleBuilder(osc_bundle_builder.IMMEDIATELY)

    def msg(address: str, *args: Any) -> None:
        m = osc_message_builder.OscMessageBuilder(address)
        for a in args:
            m.add_arg(a)
        b.add_content(m.build())

    msg("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    for bone, q in zip(vmc.BONES, quats, strict=True):
        msg("/VMC/Ext/Bone/Pos", bone.name, *bone.offset_m, *(float(x) for x in q))
    msg("/VMC/Ext/OK", 1)
    msg("/VMC/Ext/T", t_s)
    return b.build().dgram


def test_bundle_bytes_equal_python_osc_builder() -> None:
    pose, wrist = _random_pose(7)
    with vmc.VmcSender("127.0.0.1", 9, clock=FakeClock()) as sender:
        data = bytes(sender.encode(pose, wrist, 12.5))
    quats = vmc.bone_quaternions(np.concatenate([pose, wrist, [0.0]]))
    assert data == _python_osc_bundle(quats, 12.5)


def _receiver() -> tuple[BlockingOSCUDPServer, dict[str, list[tuple]]]:
    got: dict[str, list[tuple]] = {}
    d = Dispatcher()
    d.set_default_handler(lambda address, *args: got.setdefault(address, []).append(args))
    server = BlockingOSCUDPServer(("127.0.0.1", 0), d)
    server.timeout = 2.0
    return server, got


def test_real_udp_round_trip_through_python_osc_server() -> None:
    server, got = _receiver()
    port = server.server_address[1]
    pose, wrist = _random_pose(11)
    try:
        with vmc.VmcSender("127.0.0.1", port, rate_hz=60, clock=FakeClock()) as sender:
            assert sender.send(pose, wrist, 1.25)
            server.handle_request()
            assert sender.bundles_sent == 1 and sender.errors == 0
    finally:
        server.server_close()
    assert got["/VMC/Ext/OK"] == [(1,)]
    assert got["/VMC/Ext/T"][0][0] == pytest.approx(1.25)
    assert got["/VMC/Ext/Root/Pos"][0][0] == "root"
    bones = got["/VMC/Ext/Bone/Pos"]
    assert [a[0] for a in bones] == list(vmc.BONE_NAMES)
    quats = np.array([a[4:8] for a in bones])
    back = vmc.decode_bones(quats)
    slots = _driven_slots()
    v = np.concatenate([pose, wrist])
    # float32 on the wire: about 1e-7 relative per component, a few 1e-5 deg
    np.testing.assert_allclose(back[slots], v[slots], atol=2e-3)
    offsets = np.array([a[1:4] for a in bones])
    np.testing.assert_allclose(offsets, [b.offset_m for b in vmc.BONES], atol=1e-7)


def test_rate_limit_on_injected_clock() -> None:
    clock = FakeClock()
    pose = np.zeros(50)
    with vmc.VmcSender("127.0.0.1", 9, rate_hz=60, clock=clock) as sender:
        sent = 0
        for _ in range(200):  # one second of a 200 Hz loop
            sent += sender.send(pose, None, clock.now())
            clock.advance(0.005)
        assert sent == 60
        assert sender.skipped == 140
        assert sender.stats()["bundles_sent"] == 60 and sender.stats()["vmc"] == "127.0.0.1:9"
        # after a stall the sender does not burst to catch up
        clock.advance(1.0)
        assert sender.send(pose, None, clock.now())
        assert not sender.send(pose, None, clock.now())


def test_closed_port_or_closed_socket_counts_errors_not_raises() -> None:
    clock = FakeClock()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    sender = vmc.VmcSender("127.0.0.1", port, rate_hz=1000, clock=clock)
    sender.close()
    assert not sender.send(np.zeros(50), None, 0.0)
    assert sender.errors == 1 and "failed" in sender.last_error


@pytest.mark.parametrize("text", ["localhost:0", "host:notaport", "1.2.3.4:70000"])
def test_bad_destination_is_a_config_error(text: str) -> None:
    with pytest.raises(ConfigError, match="--vmc"):
        vmc.parse_host_port(text)


def test_parse_host_port_defaults() -> None:
    assert vmc.parse_host_port("10.0.0.2") == ("10.0.0.2", 39539)
    assert vmc.parse_host_port(":9000") == ("127.0.0.1", 9000)
    assert vmc.parse_host_port("pc.local:39540") == ("pc.local", 39540)


def test_bad_rate_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="rate"):
        vmc.VmcSender("127.0.0.1", 9, rate_hz=0)


def test_closed_form_quaternions_equal_scipy_composition() -> None:
    for seed in range(5):
        pose, wrist = _random_pose(seed)
        v = np.concatenate([pose, wrist, [0.0]])
        fast = vmc.bone_quaternions(v)
        ref = vmc.bone_quaternions_reference(v)
        dots = np.abs(np.sum(fast * ref, axis=1))  # q and -q are the same rotation
        np.testing.assert_allclose(dots, 1.0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(fast, axis=1), 1.0, atol=1e-12)


def test_rig_output_hook_takes_the_54_pose() -> None:
    assert hand.ALL_JOINT_NAMES[50:] == vmc.WRIST_NAMES
    pose, wrist = _random_pose(13)
    server, got = _receiver()
    try:
        with vmc.VmcSender("127.0.0.1", server.server_address[1], clock=FakeClock()) as sender:
            sender(0.5, np.concatenate([pose, wrist]))
            server.handle_request()
    finally:
        server.server_close()
    quats = np.array([a[4:8] for a in got["/VMC/Ext/Bone/Pos"]])
    back = vmc.decode_bones(quats)
    np.testing.assert_allclose(back[:54], np.concatenate([pose, wrist]), atol=2e-3)


def test_hand_length_scales_bone_positions() -> None:
    server, got = _receiver()
    try:
        with vmc.VmcSender("127.0.0.1", server.server_address[1], clock=FakeClock(),
                           hand_length_m=0.095) as sender:
            sender.send(np.zeros(50), None, 0.0)
            server.handle_request()
    finally:
        server.server_close()
    offsets = np.array([a[1:4] for a in got["/VMC/Ext/Bone/Pos"]])
    np.testing.assert_allclose(offsets, 0.5 * np.array([b.offset_m for b in vmc.BONES]),
                               atol=1e-7)
    with pytest.raises(ConfigError, match="hand length"):
        vmc.VmcSender("127.0.0.1", 9, hand_length_m=1.9)


@pytest.mark.parametrize("side", ["Right", "Left"])
def test_thumb_flexion_crosses_the_palm_and_abduction_leaves_it(side: str) -> None:
    prefix = "ri" if side == "Right" else "le"
    out = 1.0 if side == "Right" else -1.0
    rest_tip = np.array([out, 0.0, 1.0]) / np.sqrt(2.0)  # Unity: out and forward
    bone = vmc.BONE_NAMES.index(f"{side}ThumbProximal")
    v = np.zeros(55)
    v[hand.curve_index(f"{prefix}ThumbCMCz")] = 30.0
    tip = Rotation.from_quat(vmc.bone_quaternions(v)[bone]).apply(rest_tip)
    assert tip[2] < rest_tip[2] - 0.1 and tip[1] < -0.1  # toward the little finger, palmar
    v[:] = 0.0
    v[hand.curve_index(f"{prefix}ThumbCMCy")] = 30.0
    tip = Rotation.from_quat(vmc.bone_quaternions(v)[bone]).apply(rest_tip)
    assert tip[1] < -0.3 and abs(tip[0]) < abs(rest_tip[0])  # out of the palm plane
