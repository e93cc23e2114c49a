"""Rewriting config files the way a person would: comments and layout kept, a dated
backup of every write, and an undo that restores the last one byte for byte.

Edits go through ``tomlkit`` (a style-preserving TOML library): only the values
changed are rewritten, every comment, blank line and key order of the file stays.

Backups: before a file is written, its current bytes are copied to
``backups/NAME.YYYYMMDDTHHMMSS.ffffffZ`` beside it (UTC); when there was no file
yet, an empty ``backups/NAME.STAMP.absent`` records that. :func:`undo` puts the
newest backup back (or removes the file, for ``.absent``) and deletes that backup,
so a second undo goes one write further back.
"""

from __future__ import annotations

import datetime as dt
import os
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import tomlkit
import tomlkit.exceptions
from tomlkit.toml_document import TOMLDocument

from handrig.config.paths import is_installed
from handrig.errors import ConfigError

BACKUP_DIR = "backups"
ABSENT = ".absent"


def parse(text: str, file: str | None = None) -> TOMLDocument:
    """The document of ``text``; ConfigError naming ``file`` when it is not TOML."""
    try:
        return tomlkit.parse(text)
    except tomlkit.exceptions.ParseError as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=file) from None


def edit(text: str, change: Callable[[TOMLDocument], None], file: str | None = None) -> str:
    """``text`` after ``change`` edited its document in place (comments kept)."""
    doc = parse(text, file)
    change(doc)
    return tomlkit.dumps(doc)


def update_servos(text: str, changes: Mapping[int, Mapping[str, Any]],
                  file: str | None = None) -> str:
    """A rig file's ``text`` with keys of the ``[[servos]]`` of the given IDs set,
    e.g. ``{19: {"zero_ticks": 2959, "direction": -1}}``; everything else as it was."""

    def change(doc: TOMLDocument) -> None:
        servos = doc.get("servos")
        by_id = {int(s["id"]): s for s in servos} if servos is not None else {}
        for servo_id, values in changes.items():
            if servo_id not in by_id:
                raise ConfigError("no [[servos]] block with this id", file=file,
                                  key="servos.id", value=servo_id)
            for key, value in values.items():
                by_id[servo_id][key] = value

    return edit(text, change, file)


def _stamp(now: dt.datetime | None = None) -> str:
    return (now or dt.datetime.now(dt.UTC)).strftime("%Y%m%dT%H%M%S.%fZ")


def backups_of(path: Path) -> list[Path]:
    """Backups of ``path``, oldest first."""
    folder = path.parent / BACKUP_DIR
    if not folder.is_dir():
        return []
    prefix = f"{path.name}."
    return sorted(p for p in folder.iterdir()
                  if p.name.startswith(prefix) and p.name[len(prefix):][:1].isdigit())


def write_with_backup(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` after keeping its current bytes as a dated backup;
    returns the backup's path. An installed (shipped) file is never written."""
    if is_installed(path):
        raise ConfigError("the installed configuration is never rewritten", file=str(path),
                          allowed="write to your own copy (the default --out)")
    folder = path.parent / BACKUP_DIR
    folder.mkdir(parents=True, exist_ok=True)
    stamp = _stamp()
    while any(p.name.startswith(f"{path.name}.{stamp}") for p in backups_of(path)):
        stamp = _stamp()  # two writes within one microsecond: the next one is later
    if path.exists():
        backup = folder / f"{path.name}.{stamp}"
        shutil.copyfile(path, backup)
    else:
        backup = folder / f"{path.name}.{stamp}{ABSENT}"
        backup.touch()
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return backup


def undo(path: Path) -> str:
    """Put back the newest backup of ``path``; returns what was done."""
    found = backups_of(path)
    if not found:
        raise ConfigError("no backup to restore: nothing was written here by handrig, or "
                          "every write was undone", file=str(path),
                          allowed=f"backups live in {path.parent / BACKUP_DIR}")
    last = found[-1]
    if last.name.endswith(ABSENT):
        path.unlink(missing_ok=True)
        last.unlink()
        return f"removed {path} (there was no such file before the last write)"
    shutil.copyfile(last, path)
    last.unlink()
    return f"restored {path} from {last.name}"
