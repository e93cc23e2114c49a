"""orca_core itself (the ORCA hand's own driver, from PyPI, in a venv of its own made by
``make orca-core``) against ``handrig sim-bus --rig orca``: its scan knows every servo,
and its connect, calibration and init pass and leave the hand at orca_core's neutral.

Skipped when ``.venv-orca`` is absent (orca_core pins dynamixel-sdk < 4, handrig needs
>= 4.1, so it cannot share handrig's venv). Its calibration sweeps every joint to its
limits at orca_core's own pace: about 25 s.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from handrig.pose.robot_rig import RobotRigConfig, load_rig, robot_retarget

ROOT = Path(__file__).resolve().parents[2]
ORCA_PYTHON = ROOT / ".venv-orca" / "bin" / "python"
NEEDS_ORCA_CORE = pytest.mark.skipif(
    not ORCA_PYTHON.exists(), reason="orca_core is not installed: run `make orca-core`")

# orca_core's joint names -> the model's (data/robots/orca_hand/right_hand.xml)
JOINTS = {"wrist": "right_wrist", "thumb_cmc": "right_t-cmc", "thumb_abd": "right_t-abd",
          "thumb_mcp": "right_t-mcp", "thumb_dip": "right_t-pip"} | {
    f"{finger}_{j}": f"right_{finger[0]}-{j}"
    for finger in ("index", "middle", "ring", "pinky") for j in ("abd", "mcp", "pip")}

DRIVER = '''
import json, sys
from orca_core import OrcaHand
from orca_core.hardware.dynamixel_client import DynamixelClient

port, config_path = sys.argv[1], sys.argv[2]
found = DynamixelClient(list(range(1, 18)), port, 1_000_000).scan_for_motors(
    port, (1, 17), [1_000_000])
out = {"scan": {str(m["id"]): m["model_name"] for m in found}}
hand = OrcaHand(config_path=config_path)
ok, msg = hand.connect(interactive=False)
out["connect"] = [ok, msg]
try:
    if ok:
        hand.calibrate()
        out["calibrated"] = bool(hand.calibrated)
        hand.init_joints()
        out["joints"] = {k: float(v) for k, v in hand.get_joint_position().data.items()}
finally:
    if ok:
        hand.disable_torque()
        hand.disconnect()
print(json.dumps(out))
'''


def _orca_config() -> dict:
    """orca_core's v2 right-hand config.yaml, read by its own venv (which has yaml)."""
    read = ("import json, pathlib, yaml, orca_core; p = pathlib.Path(orca_core.__file__)"
            ".parent / 'models/v2/orcahand-right/config.yaml'; "
            "print(json.dumps(yaml.safe_load(p.read_text())))")
    run = subprocess.run([str(ORCA_PYTHON), "-c", read], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0, run.stderr[-2000:]
    return dict(json.loads(run.stdout))


@pytest.fixture
def orca_bus() -> Iterator[str]:
    # --wire-timing: replies at their 1 Mbaud wire time, as on the real hand. orca_core
    # takes a joint as stalled after calibration_num_stable (10) equal position reads,
    # however fast they come. Answering instantly, the emulator let 10 reads pass in
    # about 10 ms, less than its motors need to show motion (their present state is
    # refreshed every 10 ms on a bus that is never idle), so sweeps "stalled" where they
    # began: limits rejected as degenerate, calibrated False.
    proc = subprocess.Popen([sys.executable, "-m", "handrig.cli", "sim-bus", "--rig", "orca",
                             "--wire-timing"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("port: /dev/"), first
        path = first.split()[1]
        _wait_until_answering(path)
        yield path
    finally:
        proc.kill()
        proc.wait()


def _wait_until_answering(path: str, timeout_s: float = 10.0) -> None:
    """Until every servo answers a ping (a just-started emulator, on a loaded machine,
    can miss the first packets while its physics catches up)."""
    import time

    from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

    port = PortHandler(path)
    assert port.openPort() and port.setBaudRate(1_000_000)
    ph = PacketHandler(2.0)
    deadline = time.monotonic() + timeout_s
    try:
        while True:
            found, result = ph.broadcastPing(port)
            if result == COMM_SUCCESS and sorted(found) == list(range(1, 18)):
                return
            assert time.monotonic() < deadline, f"the emulated ORCA answers only {found}"
    finally:
        port.closePort()


@NEEDS_ORCA_CORE
def test_the_preset_agrees_with_orca_cores_right_hand() -> None:
    cfg = _orca_config()
    rig = load_rig("orca")
    assert isinstance(rig, RobotRigConfig)
    by_joint = {s.joint: s for s in rig.servos}
    rt = robot_retarget(rig)
    for name, model_joint in JOINTS.items():
        motor = cfg["joint_to_motor_map"][name]
        servo = by_joint[model_joint]
        assert servo.id == abs(motor), name
        assert servo.direction == (1 if motor > 0 else -1), name
        rom = [float(v) for v in cfg["joint_roms"][name]]
        assert [servo.min_deg, servo.max_deg] == rom, name
        k = rt.index(model_joint)
        assert [rt.low_deg[k], rt.high_deg[k]] == rom, name


@NEEDS_ORCA_CORE
def test_orca_core_scans_calibrates_and_inits_the_emulated_hand(
        orca_bus: str, tmp_path: Path) -> None:
    cfg = _orca_config() | {"port": orca_bus, "baudrate": 1_000_000,
                            "motor_type": "dynamixel"}
    (tmp_path / "config.yaml").write_text(json.dumps(cfg))  # JSON is YAML
    (tmp_path / "driver.py").write_text(DRIVER)
    run = subprocess.run([str(ORCA_PYTHON), str(tmp_path / "driver.py"), orca_bus,
                          str(tmp_path / "config.yaml")],
                         capture_output=True, text=True, timeout=240, cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    # every servo is a model orca_core knows: the wrist is its 1080, not Unknown(1070)
    assert sorted(int(i) for i in out["scan"]) == list(range(1, 18))
    assert out["scan"]["1"] == "XC430-T240BB-T"
    assert {out["scan"][str(i)] for i in range(2, 18)} == {"XC330-T288-T"}
    assert out["connect"][0], out["connect"][1]
    assert out["calibrated"] is True
    for joint, neutral in cfg["neutral_position"].items():
        assert out["joints"][joint] == pytest.approx(neutral, abs=3.0), joint
