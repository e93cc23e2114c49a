"""The ORCA hand preset: a robot rig made only of data (model, rig file, retarget table),
its emulated servos as a plain dynamixel-sdk client sees them, and the demo end to end."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from firmware_protocol.dynamixel import ErrorCode, Reg
from handrig.devices.servo.models import current_limit_units, resolve_servo_settings
from handrig.pose.robot_rig import RobotRigConfig, load_rig, robot_retarget
from sim.dxl_bus import SimBus

ROOT = Path(__file__).resolve().parents[2]
MODEL_DIR = ROOT / "data" / "robots" / "orca_hand"


def test_the_rig_holds_the_published_servos() -> None:
    rig = load_rig("orca")
    assert isinstance(rig, RobotRigConfig) and rig.robot is not None
    assert [s.id for s in sorted(rig.servos, key=lambda s: s.id)] == list(range(1, 18))
    by_id = {s.id: s for s in rig.servos}
    # the wrist is the XC430 orca_core knows (1080), not one its scan rejects (issue 38)
    assert by_id[1].joint == "right_wrist" and by_id[1].model == "XC430-T240BB"
    assert {s.model for s in rig.servos if s.id != 1} == {"XC330-T288"}
    assert rig.bus.baud == 1_000_000
    wrist = resolve_servo_settings(rig.servo_settings, 1)
    finger = resolve_servo_settings(rig.servo_settings, 3)
    assert (wrist.operating_mode, finger.operating_mode) == (4, 5)
    assert finger.current_limit_ma == 300
    assert current_limit_units(wrist.current_limit_ma, "XC430-T240BB") is None  # no sensing
    # orca_core's map: index MCP on 3, ring MCP on 7 reversed
    assert by_id[3].joint == "right_i-mcp" and by_id[7].direction == -1
    rt = robot_retarget(rig)
    assert set(rt.joint_names) == {s.joint for s in rig.servos}


def test_the_model_ships_its_meshes_licence_and_notice() -> None:
    root = ET.parse(MODEL_DIR / "right_hand.xml").getroot()
    meshdir = MODEL_DIR / root.find("compiler").get("meshdir")  # type: ignore[union-attr]
    files = [m.get("file") for m in root.iter("mesh") if m.get("file")]
    assert len(files) >= 20
    for f in files:
        assert (meshdir / str(f)).stat().st_size > 1000, f
    assert "MIT License" in (MODEL_DIR / "LICENSE").read_text()
    notice = (MODEL_DIR / "NOTICE.md").read_text()
    assert "orcahand/orcahand_description" in notice and "Changes made" in notice
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(MODEL_DIR / "right_hand.xml"))
    assert m.nmesh == len(files) and m.nu == 17


def _answered(call: Callable[[], tuple[Any, ...]], at: int) -> tuple[Any, ...]:
    """An SDK call's result, asked again (up to 5 times) while its communication result
    (item ``at``) is not a success: the SDK waits a latency timer's worth for a reply,
    and this file's tests run at nice 10 beside others, where the in-process emulator's
    reply can come later than that. What the servos answer is checked, not how fast."""
    for _ in range(4):
        out = call()
        if out[at] == COMM_SUCCESS:
            return out
    return call()


def test_a_plain_sdk_client_sees_the_orca_servos() -> None:
    with SimBus.from_rig("orca") as bus:
        port = PortHandler(bus.port_path)
        assert port.openPort() and port.setBaudRate(1_000_000)
        ph = PacketHandler(2.0)
        try:
            found, result = _answered(lambda: ph.broadcastPing(port), 1)
            assert result == COMM_SUCCESS and sorted(found) == list(range(1, 18))
            assert found[1][0] == 1080 and {found[i][0] for i in range(2, 18)} == {1220}
            result, err = _answered(
                lambda: ph.write2ByteTxRx(port, 1, Reg.CURRENT_LIMIT, 300), 0)
            assert result == COMM_SUCCESS
            assert err & 0x7F == ErrorCode.ACCESS  # the XC430 has no Current Limit
            assert _answered(lambda: ph.write2ByteTxRx(port, 2, Reg.CURRENT_LIMIT, 300),
                             0) == (COMM_SUCCESS, 0)
        finally:
            port.closePort()
        # at 57600 nobody answers: the hand is at 1 Mbps
        assert port.openPort() and port.setBaudRate(57_600)
        assert not ph.broadcastPing(port)[0]
        port.closePort()


# both over the demo's first half (7.5 s), its first grip included, which LEAP's fingers
# are the slower to follow: LEAP 1.3-2.0 deg rms there at load 11 (1.9 over the whole
# demo on a quiet machine), ORCA 0.9
@pytest.mark.parametrize("rig, frames", [("orca", ["--frames", "1500"]),
                                         ("leap", ["--frames", "1500"])])
def test_demo_robot_tracks_within_3_degrees_and_ends_with_torque_off(
        rig: str, frames: list[str]) -> None:
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    out = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "demo", "--rig", rig, *frames, "--json"],
        capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    assert summary["torque_off"] is True
    assert summary["reads"] > 50
    assert summary["tracking_rms_deg"] <= 3.0, summary["tracking_rms_deg"]


@pytest.mark.parametrize("rig", ["orca", "leap"])
def test_retarget_check_reports_fists_and_pinches_through_the_model(rig: str) -> None:
    # issue 38: the shipped tables close the robot's fist at the human's and bring
    # its tips together at the human's pinches (issue 28 asked that the demo cover 60 % of
    # the index MCP's range; the fitted tables follow the human's kinematics instead)
    out = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "retarget", "check", "--rig", rig,
         "--no-capture", "--json"], capture_output=True, text=True, timeout=300)
    report = json.loads(out.stdout)
    joints = {j["joint"]: j for j in report["joints"]}
    # exit 1 exactly when a joint is flagged (the demo or capture past its range)
    flagged = any({"demo", "capture"} & set(j["flags"]) for j in joints.values())
    assert out.returncode == (1 if flagged else 0), out.stderr[-2000:]
    assert min(report["fist_closure"].values()) >= 0.9
    assert max(report["pinch_gap_mm"].values()) <= 10.0
