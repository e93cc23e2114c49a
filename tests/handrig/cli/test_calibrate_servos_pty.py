"""``handrig calibrate servos`` driven in a pseudo-terminal, as a puppeteer would, against
the emulated bus and its MuJoCo puppet: with torque off the wrist hangs under gravity,
about +80 degrees from its zero (the reading that once went into rig.toml on one Enter).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

pexpect = pytest.importorskip("pexpect")

from handrig.config.paths import installed_config  # noqa: E402

pytestmark = pytest.mark.slow


def spawn(args: list[str], home: Path) -> pexpect.spawn:
    env = {**os.environ, "XDG_CONFIG_HOME": str(home / "config"),
           "XDG_DATA_HOME": str(home / "data"), "HANDRIG_CPUS": ""}
    return pexpect.spawn(sys.executable, ["-m", "handrig.cli", *args], env=env,
                         encoding="utf-8", timeout=90, dimensions=(50, 200))


def finish(child: pexpect.spawn) -> int:
    child.expect(pexpect.EOF)
    child.close()
    return int(child.exitstatus)


def my_rig(home: Path) -> Path:
    """A rig.toml of the user's own, with a comment and spacing of their own."""
    path = home / "config" / "handrig" / "rig.toml"
    path.parent.mkdir(parents=True)
    shipped = installed_config("rig.toml").read_bytes()
    path.write_bytes(b"# my puppet, tuned by hand  \r\n" + shipped)
    return path


def test_an_80_degree_shift_is_not_written_without_typed_yes_and_q_exits_0(
        tmp_path: Path) -> None:
    rig = my_rig(tmp_path)
    before = rig.read_bytes()
    child = spawn(["calibrate", "servos", "--bus", "sim", "--ids", "19"], tmp_path)
    child.expect("files in use:")
    child.expect(r"rig\s+" + str(rig))
    child.expect("Enter reads it")  # step one: nothing is read until Enter
    child.sendline("")
    child.expect(r"zero_ticks 2048 -> (\d+) \(\+(\d+)\.\d deg\)")
    assert 75 <= int(child.match.group(2)) <= 85  # the hanging wrist
    child.expect("needs a confirmation: the zero moves")
    child.expect("max_zero_shift_deg = 20")
    child.expect("type yes to accept")
    child.sendline("")  # Enter is not a confirmation: it reads again
    child.expect("Enter reads it")
    child.sendline("")
    child.expect("type yes to accept")
    child.sendline("q")
    child.expect("calibration stopped: nothing was written")
    assert finish(child) == 0
    assert rig.read_bytes() == before
    assert not (rig.parent / "backups").exists()


def test_typed_yes_writes_keeps_a_backup_and_undo_restores_the_file_byte_for_byte(
        tmp_path: Path) -> None:
    rig = my_rig(tmp_path)
    before = rig.read_bytes()
    child = spawn(["calibrate", "servos", "--bus", "sim", "--ids", "19,20"], tmp_path)
    child.expect("Enter reads it")
    child.sendline("")
    child.expect("type yes to accept")
    child.sendline("yes")
    child.expect(r"accepted")
    child.expect("direction check: flex the joint by hand")
    child.sendline("s")
    child.expect(r"servo 20 \(riWristDeviation\): at \d+ ticks")
    child.sendline("s")  # skip the second servo
    child.expect(r"wrote 1 servo calibration\(s\) to " + str(rig))
    child.expect(r"backup of what was there: (\S+)")
    backup = Path(child.match.group(1))
    assert finish(child) == 0
    after = rig.read_bytes()
    assert after != before and backup.read_bytes() == before
    assert b"# my puppet, tuned by hand" in after  # the user's comments stay
    assert after.count(b"#") == before.count(b"#")

    undo = spawn(["calibrate", "undo"], tmp_path)
    undo.expect(f"restored {rig}")
    assert finish(undo) == 0
    assert rig.read_bytes() == before
    assert not backup.exists()


def test_q_at_the_first_prompt_writes_nothing_and_exits_0(tmp_path: Path) -> None:
    child = spawn(["calibrate", "servos", "--bus", "sim", "--ids", "7"], tmp_path)
    child.expect("Enter reads it")
    child.sendline("q")
    child.expect("nothing was written")
    assert finish(child) == 0
    assert not (tmp_path / "config").exists()
