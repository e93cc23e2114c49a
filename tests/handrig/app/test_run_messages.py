"""What `handrig run` says: the summary in words, and messages that name the flag or the
file and key, with the fix, checked before any hardware is touched."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from handrig.app import parts as app_parts
from handrig.app import summary as run_summary
from handrig.app.parts import build_parts
from handrig.app.summary import format_summary
from handrig.config.loading import CONFIG_DIR
from handrig.devices.servo.bus import BusStats
from handrig.errors import ConfigError
from handrig.loop.stats import RunStats
from handrig.outputs.base import Output, OutputStatus

CLI = [sys.executable, "-m", "handrig.cli"]
CHECKOUT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def parts() -> app_parts.RigParts:
    return build_parts()


def _summary(**kw: object) -> dict:
    stats = RunStats(frames=2200, duration_s=11.0)
    bus = BusStats(20, reads=500, timeouts=19)
    bus.stale_readings[:] = 19
    return run_summary.summary_dict(stats, bus, None, True, **kw)  # type: ignore[arg-type]


# -- the summary ----------------------------------------------------------------------


def test_faults_are_words_and_counts_not_a_dict() -> None:
    text = format_summary(_summary(ease_s=1.0))
    line = next(x for x in text.splitlines() if x.startswith("faults"))
    assert line == "faults            19 read timeouts, 380 stale servo readings"
    assert "{" not in text
    clean = format_summary(run_summary.summary_dict(RunStats(), BusStats(20), None, True))
    assert "faults            none" in clean


def test_the_ease_is_stated_and_json_carries_the_same() -> None:
    summary = _summary(ease_s=1.0)
    assert "11.0 s" in format_summary(summary)
    assert "includes the 1 s ease to the relaxed pose at the end" in format_summary(summary)
    assert "ended at once, no ease" in format_summary(_summary(ease_s=0.0))
    back = json.loads(json.dumps(summary))
    assert back["ease_s"] == 1.0
    assert back["faults"] == {"read timeouts": 19, "stale servo readings": 380}
    assert back["outputs"] == {"vmc": None, "recording": None}


def test_clamps_say_what_they_mean_and_which_joints(parts: app_parts.RigParts) -> None:
    pipeline = parts.pipeline
    counts = pipeline.servo_clamps_by_servo
    saved = counts.copy()
    try:
        counts[:] = 0
        counts[3], counts[7], counts[1], counts[0] = 50, 900, 20, 5
        clamped = run_summary.clamped_joints(pipeline)
    finally:
        counts[:] = saved
    joints = pipeline.servo_joints
    assert clamped == [{"joint": joints[7], "clamps": 900}, {"joint": joints[3], "clamps": 50},
                       {"joint": joints[1], "clamps": 20}]
    text = format_summary(_summary(clamped=clamped))
    assert f"most at {joints[7]} (900), {joints[3]} (50), {joints[1]} (20)" in text
    assert "normal at a full fist or spread" in text


def test_outputs_are_listed(tmp_path: Path) -> None:
    """Each real output says its own part of the summary (Output.summary); the counts
    are set through status(), as if the run had sent them."""
    from handrig.outputs.recorder import Recorder
    from handrig.outputs.vmc import VmcSender

    class Sender(VmcSender):
        def status(self) -> OutputStatus:
            return dataclasses.replace(super().status(), frames_written=600)

    class Rec(Recorder):
        def status(self) -> OutputStatus:
            return dataclasses.replace(super().status(), frames_written=2200,
                                       bytes_written=123_456, duration_s=2200 / 200.0)

    class Other(Output):  # an output of a kind the summary does not know: its status
        def __call__(self, t_s: float, pose_deg: np.ndarray) -> None:
            pass

        def status(self) -> OutputStatus:
            return OutputStatus(kind="osc", name="OSC", address="10.0.0.2:9000",
                                frames_written=5)

    sender, rec = Sender("127.0.0.1", 39539), Rec(tmp_path / "take.bvh", log=lambda s: None)
    try:
        outputs = run_summary.outputs_summary([sender, rec, Other()], duration_s=10.0)
    finally:
        sender.close()
        rec.close()
    assert outputs["osc"]["address"] == "10.0.0.2:9000" and outputs["osc"]["frames"] == 5
    assert outputs["recording"]["path"] == str(tmp_path / "take.bvh")
    assert outputs["vmc"]["target"] == "127.0.0.1:39539" and outputs["vmc"]["rate_hz"] == 60.0
    assert outputs["recording"]["duration_s"] == 11.0
    text = format_summary(_summary(outputs=outputs))
    assert "outputs           VMC to 127.0.0.1:39539: 600 bundles, 60.0 Hz" in text
    assert f"recording {tmp_path / 'take.bvh'}: 2200 frames, 11.0 s, 123456 bytes" in text
    assert "                  OSC 10.0.0.2:9000: 5 frames" in text  # a kind it does not know
    assert "outputs           none" in format_summary(_summary())


# -- messages --------------------------------------------------------------------------


def test_a_recording_given_as_a_port_suggests_replay(parts: app_parts.RigParts,
                                                     tmp_path: Path) -> None:
    csv = tmp_path / "take.csv"
    csv.write_text("# handrig glove recording 1\n")
    for spec in (str(csv), "missing.csv"):
        with pytest.raises(ConfigError) as err:
            app_parts.glove_spec(spec, parts.glove_config)
        text = str(err.value)
        assert text.startswith(f"--glove {spec!r}: a file, not a serial port")
        assert f"--glove replay:{spec}" in text and "<config>" not in text
    with pytest.raises(ConfigError, match=r"--glove 'replay:nope.csv': glove recording not found"):
        app_parts.glove_spec("replay:nope.csv", parts.glove_config)
    with pytest.raises(ConfigError, match=r"--glove '/dev/ttyNOPE9': no such port"):
        app_parts.glove_spec("/dev/ttyNOPE9", parts.glove_config)


def test_a_missing_glove_port_names_the_glove_file_and_key(parts: app_parts.RigParts) -> None:
    cfg = parts.glove_config
    no_port = dataclasses.replace(cfg, glove=dataclasses.replace(cfg.glove, port=""))
    with pytest.raises(ConfigError) as err:
        app_parts.glove_spec(None, no_port, Path("/home/me/glove.toml"))
    text = str(err.value)
    assert text.startswith("/home/me/glove.toml: key 'glove.port': no glove port given")
    assert "--glove PORT (or replay:FILE.csv)" in text


def test_vmc_needs_a_port_and_record_a_known_suffix() -> None:
    with pytest.raises(ConfigError) as err:
        app_parts.check_outputs("localhost", None)
    assert str(err.value).startswith("--vmc 'localhost': no port given")
    assert "localhost:39539" in str(err.value)
    with pytest.raises(ConfigError, match=r"^--vmc 'localhost:http': not a UDP destination"):
        app_parts.check_outputs("localhost:http", None)
    with pytest.raises(ConfigError, match=r"^--record 'take.txt': unknown recording suffix '.txt'"):
        app_parts.check_outputs(None, "take.txt")
    app_parts.check_outputs("localhost:39539", "take.BVH")


def test_a_missing_map_names_the_key_and_that_it_is_relative_to_the_rig_file(
        tmp_path: Path) -> None:
    rig = tmp_path / "rig.toml"
    text = (CONFIG_DIR / "rig.toml").read_text().replace('map = ""', 'map = "maps/mine.toml"')
    rig.write_text(text)
    with pytest.raises(ConfigError) as err:
        build_parts(rig)
    message = str(err.value)
    assert message.startswith(f"{rig}: key 'loop.map' = 'maps/mine.toml': no such file: "
                              f"{tmp_path / 'maps' / 'mine.toml'}")
    assert f"relative to the rig file's folder {tmp_path}" in message


@pytest.mark.parametrize("flags, says", [
    (["--record", "take.txt"], "--record 'take.txt': unknown recording suffix"),
    (["--vmc", "localhost"], "--vmc 'localhost': no port given"),
    (["--glove", "config/recordings/demo_glove.csv"], "--glove replay:config/recordings/"),
])
def test_run_checks_what_needs_no_hardware_before_the_bus(flags: list[str], says: str) -> None:
    glove = [] if "--glove" in flags else ["--glove", "replay:config/recordings/demo_glove.csv"]
    out = subprocess.run([*CLI, "run", "--bus", "sim", *glove, *flags], capture_output=True,
                         text=True, timeout=60, cwd=CHECKOUT)
    assert out.returncode == 2, out.stderr
    assert says in out.stderr and "Traceback" not in out.stderr
    assert "Inappropriate ioctl" not in out.stderr
    said = (out.stdout + out.stderr).lower()
    # no emulator was started (a wall-clock bound here failed at nice 19 beside a busy core)
    assert "simulated servo bus" not in said and "commissioned" not in said


def test_run_reads_the_users_calibrated_glove_file(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    mine = tmp_path / "config" / "handrig" / "glove.toml"
    mine.parent.mkdir(parents=True)
    mine.write_text((CONFIG_DIR / "glove.toml").read_text())
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    assert build_parts().glove_file == mine
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "elsewhere"))
    assert build_parts().glove_file == CONFIG_DIR / "glove.toml"


def test_clamp_advice_names_the_cause_it_can_tell() -> None:
    from handrig.app.summary import clamp_advice
    from handrig.pose.expand import TrainingRangeReport

    ctrl = ("riIndexMCPy", "riPinkyMCPy")
    inside = TrainingRangeReport(True, 100, 0, {c: 0 for c in ctrl}, 2.0)
    outside = TrainingRangeReport(True, 100, 40, {"riIndexMCPy": 40, "riPinkyMCPy": 0}, 2.0)
    on_curve = {"limit_clamps": 50, "clamped_joints": [{"joint": "riIndexPIPy", "clamps": 50}]}
    on_ctrl = {"limit_clamps": 50, "clamped_joints": [{"joint": "riIndexMCPy", "clamps": 50}]}
    assert clamp_advice({"limit_clamps": 0}, "", ctrl, outside) == "no clamps"
    assert "recorded performance (demo.csv)" in clamp_advice(on_ctrl, "demo.csv", ctrl, inside)
    assert "glove past its calibration (riIndexMCPy" in clamp_advice(on_ctrl, "", ctrl, inside)
    assert "outside its training range" in clamp_advice(on_curve, "", ctrl, outside)
    assert "glove past" not in clamp_advice(on_curve, "", ctrl, outside)
    assert "handrig evaluate" in clamp_advice(on_curve, "", ctrl, inside)
    text = format_summary({**_summary(), "clamp_advice": "likely: a test"})
    assert "likely: a test" in text and "recalibrate the glove or check the map" not in text
