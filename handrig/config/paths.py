"""Where handrig reads its installed files and where commands write the user's own.

The installed files (``config/`` of the checkout or package: ``rig.toml``,
``glove.toml``, the maps, the baked sag grid) are read, never written. A command
that produces a file writes it to the path it is given or, by default, into
the user's directories of the XDG Base Directory Specification:

* configuration, :func:`user_config_dir`: ``$XDG_CONFIG_HOME/handrig``
  (``~/.config/handrig`` when the variable is unset): calibrated ``glove.toml``
  and ``rig.toml``;
* data, :func:`user_data_dir`: ``$XDG_DATA_HOME/handrig``
  (``~/.local/share/handrig``): baked grids and their plots.

A user file that starts from an installed one begins as a copy of it
(:func:`user_copy`); later runs start from the user's file
(:func:`config_file`). The specification ignores a variable that is empty or
not an absolute path, and so does this module.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
"""The checkout (an editable install reads ``config/`` and ``data/`` from here)."""
CONFIG_DIR = REPO_ROOT / "config"
INSTALLED_CONFIG_DIR = CONFIG_DIR
"""The installed configuration (read only)."""

APP = "handrig"
CONFIG_HOME_HELP = "$XDG_CONFIG_HOME/handrig, default ~/.config/handrig"
DATA_HOME_HELP = "$XDG_DATA_HOME/handrig, default ~/.local/share/handrig"


def _xdg_dir(variable: str, fallback: str, env: Mapping[str, str] | None) -> Path:
    environ = os.environ if env is None else env
    value = environ.get(variable, "")
    if value and os.path.isabs(value):
        return Path(value) / APP
    home = environ.get("HOME") or str(Path.home())
    return Path(home) / fallback / APP


def user_config_dir(env: Mapping[str, str] | None = None) -> Path:
    """``$XDG_CONFIG_HOME/handrig`` (``~/.config/handrig`` by default); not created here."""
    return _xdg_dir("XDG_CONFIG_HOME", ".config", env)


def user_data_dir(env: Mapping[str, str] | None = None) -> Path:
    """``$XDG_DATA_HOME/handrig`` (``~/.local/share/handrig`` by default); not created here."""
    return _xdg_dir("XDG_DATA_HOME", ".local/share", env)


def installed_config(name: str) -> Path:
    """The installed file ``name`` (relative to ``config/``)."""
    return INSTALLED_CONFIG_DIR / name


def user_config(name: str, env: Mapping[str, str] | None = None) -> Path:
    """The user's file ``name`` in :func:`user_config_dir` (it may not exist yet)."""
    return user_config_dir(env) / name


def user_data(name: str, env: Mapping[str, str] | None = None) -> Path:
    """The user's file ``name`` in :func:`user_data_dir` (it may not exist yet)."""
    return user_data_dir(env) / name


def config_file(name: str, env: Mapping[str, str] | None = None) -> Path:
    """The file ``name`` a command reads by default: the user's copy when there is
    one, else the installed file."""
    mine = user_config(name, env)
    return mine if mine.is_file() else installed_config(name)


def is_installed(path: str | Path) -> bool:
    """Whether ``path`` lies in the installed configuration (which is never written)."""
    try:
        Path(path).resolve().relative_to(INSTALLED_CONFIG_DIR.resolve())
    except ValueError:
        return False
    return True


def user_copy(name: str, env: Mapping[str, str] | None = None) -> Path:
    """The user's file ``name``, copied from the installed one first if it does not
    exist yet (directories created). Returns its path."""
    mine = user_config(name, env)
    if not mine.exists():
        mine.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(installed_config(name), mine)
    return mine


def output_for(source: Path, name: str, env: Mapping[str, str] | None = None) -> Path:
    """Where a command that updates the config file ``source`` writes by default:
    back to ``source`` when it is the user's own file, to the user's copy
    (:func:`user_config`) when ``source`` is installed."""
    return user_config(name, env) if is_installed(source) else source
