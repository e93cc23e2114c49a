"""The README's record-then-play example, run as written (``handrig`` is the CLI in this
process; the commands run in a scratch folder where ``config/`` is the checkout's)."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest

from handrig.cli import main
from handrig.config.paths import CONFIG_DIR
from handrig.devices.glove_recording import read_glove_recording
from handrig.outputs.recorder import load_performance

README = Path(__file__).resolve().parents[2] / "README.md"


def example() -> list[str]:
    text = README.read_text()
    block = re.search(r"<!-- takes example -->\n```sh\n(.*?)```\n<!-- /takes example -->",
                      text, re.S)
    assert block, "the README lost its takes example"
    return [line for line in block.group(1).splitlines() if line.strip()]


def test_the_readme_record_then_play_example_works_as_written(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "config").symlink_to(CONFIG_DIR)
    monkeypatch.chdir(tmp_path)
    lines = example()
    assert [shlex.split(line)[:2] for line in lines] == [
        ["handrig", "run"], ["handrig", "play"], ["handrig", "record"]]
    for line in lines:
        argv = shlex.split(line)
        status = main([*argv[1:], "--json"])
        out = capsys.readouterr().out
        assert status == 0, (line, out[-2000:])
        summary = json.loads(out.strip().splitlines()[-1])
        if argv[1] in ("run", "play"):
            assert summary["torque_off"] is True and summary["glove"]["frames_used"] > 100
    t_s, _, _ = load_performance("take1.csv")
    assert t_s[-1] - t_s[0] == pytest.approx(3.0, abs=0.15)  # 2 s and the 1 s ease
    glove1 = read_glove_recording("glove1.csv")
    assert glove1.duration_s == pytest.approx(3.0, abs=0.15)
    assert read_glove_recording("glove2.csv").duration_s == pytest.approx(1.0, abs=0.05)
