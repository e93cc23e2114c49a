"""Which rig file a name means: the one rule every command and the emulator use.

``--rig NAME`` is a preset (``config/rigs/NAME.toml``: ``leap``, ``puppet_two_hands``,
...), ``--rig FILE`` a rig file (a path, or a name ending in ``.toml``). Without
either: your ``rig.toml`` ($XDG_CONFIG_HOME/handrig, written by ``handrig calibrate
servos``) when there is one, else the shipped ``config/rig.toml``. The glove file,
map and sag grid a rig file names in ``[loop]`` are relative to its folder.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from handrig.config.loading import CONFIG_DIR
from handrig.config.paths import config_file, installed_config, is_installed, user_config
from handrig.errors import ConfigError

RIGS_DIR = CONFIG_DIR / "rigs"
"""Shipped rig presets (``config/rigs/<name>.toml``)."""
RIG_FILE_NAME = "rig.toml"
SHIPPED_RIG = installed_config(RIG_FILE_NAME)
"""The shipped rig file: the default when you have no ``rig.toml`` (the only default is
:func:`resolve_rig_file`'s, which :func:`handrig.config.rig.load_rig_config` with no path
follows too), and the fixed rig the benches and the emulator's examples name."""


@dataclass(frozen=True)
class RigFile:
    """The rig file a run reads, and why this one (for the run's list of sources)."""

    path: Path
    why: str
    preset: str = ""  # the preset's name when ``--rig`` named one


def presets() -> list[str]:
    """The shipped rig presets' names."""
    return sorted(p.stem for p in RIGS_DIR.glob("*.toml") if not p.stem.endswith("_retarget"))


def resolve_rig_file(name_or_path: str | Path | None) -> RigFile:
    """The rig file ``name_or_path`` means (see the module docstring): a preset, a path,
    or (None or empty) the default, your ``rig.toml`` else the shipped one. ConfigError
    naming the presets for a bare name that is none of them."""
    if not name_or_path:
        path = config_file(RIG_FILE_NAME)
        if is_installed(path):
            return RigFile(path, "shipped default; no rig.toml of yours at "
                           f"{user_config(RIG_FILE_NAME)}")
        return RigFile(path, "your rig.toml, written by `handrig setup` or `handrig "
                       "calibrate servos`")
    text = str(name_or_path)
    if "/" in text or text.endswith(".toml"):
        return RigFile(Path(text), "--rig")
    preset = RIGS_DIR / f"{text}.toml"
    if not preset.exists():
        raise ConfigError(f"no rig preset {text!r}", file=str(preset),
                          allowed=f"a preset ({', '.join(presets())}) or a path to a rig file")
    return RigFile(preset, f"preset {text!r}, --rig", preset=text)


def rig_file_path(name_or_path: str | Path | None) -> Path:
    """:func:`resolve_rig_file`'s path."""
    return resolve_rig_file(name_or_path).path
