"""The README's LeRobot example, run as written by bash in a scratch folder: LeRobot's
own `lerobot-record` and `lerobot-replay` find handrig's plugins by their discovery
and run on the simulated glove and LEAP hand. The home, Hugging Face and LeRobot
folders point into the scratch folder, and the Hub is offline (a push would fail)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from tests.helpers.lerobot import skip_without_lerobot

README = Path(__file__).resolve().parents[4] / "README.md"

skip_without_lerobot()


def example() -> str:
    block = re.search(r"<!-- lerobot example -->\n```bash\n(.*?)```\n<!-- /lerobot example -->",
                      README.read_text(), re.S)
    assert block, "the README lost its LeRobot example"
    return block.group(1)


def test_the_readme_lerobot_example_records_and_replays_as_written(tmp_path: Path) -> None:
    script = example()
    assert "lerobot-record" in script and "lerobot-replay" in script
    home = tmp_path / "home"
    env = dict(os.environ, HOME=str(home), XDG_CONFIG_HOME=str(home / ".config"),
               XDG_DATA_HOME=str(home / ".local/share"), XDG_CACHE_HOME=str(home / ".cache"),
               HF_HOME=str(home / "hf"), HF_LEROBOT_HOME=str(home / "hf/lerobot"),
               HF_HUB_OFFLINE="1", PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    work = tmp_path / "work"
    work.mkdir()
    done = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=work, env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    info = json.loads((work / "handrig_demo_dataset" / "meta" / "info.json").read_text())
    assert info["robot_type"] == "handrig_leap" and info["fps"] == 30
    assert info["total_episodes"] == 1 and info["total_frames"] >= 30
    assert info["features"]["action"]["names"][:2] == ["if_rot.pos", "if_mcp.pos"]
    assert "Replaying episode" in done.stderr  # lerobot-replay's loop ran to its end
    assert not list(home.glob("**/handrig_demo_dataset"))  # the dataset is where asked
