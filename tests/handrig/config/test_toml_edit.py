"""The style-preserving writer: values change, comments stay; backups and undo."""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig.config.paths import installed_config
from handrig.config.toml_edit import backups_of, undo, update_servos, write_with_backup
from handrig.errors import ConfigError


def test_only_the_values_change(tmp_path: Path) -> None:
    text = installed_config("rig.toml").read_text()
    new = update_servos(text, {19: {"zero_ticks": 2959, "direction": -1}})
    changed = [(a, b) for a, b in zip(text.splitlines(), new.splitlines(), strict=True)
               if a != b]
    assert changed == [("zero_ticks = 2048", "zero_ticks = 2959"),
                       ("direction = 1", "direction = -1")]
    with pytest.raises(ConfigError, match="no \\[\\[servos\\]\\] block"):
        update_servos(text, {99: {"zero_ticks": 1}})


def test_each_write_keeps_a_backup_and_undo_walks_back(tmp_path: Path) -> None:
    path = tmp_path / "rig.toml"
    first = write_with_backup(path, "a = 1  # one\n")  # there was no file
    assert first.name.endswith(".absent")
    write_with_backup(path, "a = 2\n")
    write_with_backup(path, "a = 3\n")
    assert len(backups_of(path)) == 3 and path.read_text() == "a = 3\n"
    assert "restored" in undo(path) and path.read_text() == "a = 2\n"
    assert "restored" in undo(path) and path.read_bytes() == b"a = 1  # one\n"
    assert "removed" in undo(path) and not path.exists()
    with pytest.raises(ConfigError, match="no backup to restore"):
        undo(path)


def test_the_installed_configuration_is_never_written() -> None:
    with pytest.raises(ConfigError, match="never rewritten"):
        write_with_backup(installed_config("rig.toml"), "")
