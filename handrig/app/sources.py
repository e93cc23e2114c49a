"""Which files a run uses, and why: the rig, glove, map, sag grid and joint limits.

The same choices :func:`handrig.app.parts.build_parts` makes, written out so that
``run``, ``demo``, ``calibrate`` and ``config show`` can print them before they
start:

* rig: ``--rig NAME`` (a preset, ``config/rigs/NAME.toml``) or ``--rig FILE``; else
  your ``rig.toml`` ($XDG_CONFIG_HOME/handrig, written by ``calibrate servos``) when
  there is one; else the shipped ``config/rig.toml``;
* glove: ``--glove-config FILE``; else the rig file's ``[loop] glove``; else your
  ``glove.toml`` (written by ``calibrate glove``); else the shipped one;
* map: the rig file's ``[loop] map``; else the shipped ``config/maps/default.toml``;
* sag grid: the rig file's ``[loop] sag_grid``; else your baked grid
  ($XDG_DATA_HOME/handrig/sag_grid.npz, written by ``handrig bake``); else the shipped
  ``config/sag_grid.npz``;
* joint limits: your ``joint_limits.toml`` when there is one, else the shipped one.

Paths in ``[loop]`` are relative to the rig file's folder.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from handrig.app.hands import SessionParts
from handrig.config.loading import CONFIG_DIR
from handrig.config.paths import (
    config_file,
    installed_config,
    is_installed,
    user_config,
    user_data,
)
from handrig.config.rig import RigConfig
from handrig.config.rig_files import resolve_rig_file
from handrig.pose import robot_rig as robots
from handrig.pose.sag import SAG_GRID

DEFAULT_MAP = CONFIG_DIR / "maps" / "default.toml"


@dataclass(frozen=True)
class Source:
    """One file a command uses: its role, its path and why this one."""

    role: str  # "rig", "glove", "map", "sag grid", "joint limits", ...
    path: Path
    why: str


def rig_file(rig: str | Path | None) -> Source:
    """The rig file ``--rig`` names (a preset or a path), else the default one
    (:func:`handrig.config.rig_files.resolve_rig_file`)."""
    found = resolve_rig_file(rig)
    return Source("rig", found.path, found.why)


def _from_loop(rig_path: Path, value: str) -> Path:
    p = Path(value)
    return p if p.is_absolute() else rig_path.resolve().parent / p


def glove_file(rig_path: Path, rig_cfg: RigConfig, glove: str | Path | None = None) -> Source:
    """The glove file a run with this rig reads."""
    if glove:
        return Source("glove", Path(glove), "--glove-config")
    if rig_cfg.loop.glove:
        return Source("glove", _from_loop(rig_path, rig_cfg.loop.glove),
                      f"[loop] glove of {rig_path.name}")
    mine = user_config("glove.toml")
    if mine.is_file():
        return Source("glove", mine, "your calibration, written by `handrig calibrate glove`")
    return Source("glove", installed_config("glove.toml"),
                  f"shipped default; no calibration of yours at {mine}")


def map_file(rig_path: Path, rig_cfg: RigConfig) -> Source:
    if rig_cfg.loop.map:
        return Source("map", _from_loop(rig_path, rig_cfg.loop.map),
                      f"[loop] map of {rig_path.name}")
    return Source("map", DEFAULT_MAP, "shipped default; [loop] map is empty")


def grid_file(rig_path: Path, rig_cfg: RigConfig) -> Source:
    if rig_cfg.loop.sag_grid:
        return Source("sag grid", _from_loop(rig_path, rig_cfg.loop.sag_grid),
                      f"[loop] sag_grid of {rig_path.name}")
    mine = user_data(SAG_GRID.name)
    if mine.is_file():
        return Source("sag grid", mine, "your baked grid, written by `handrig bake`")
    return Source("sag grid", SAG_GRID, f"shipped default; no baked grid of yours at {mine}")


def limits_file() -> Source:
    path = config_file("joint_limits.toml")
    if is_installed(path):
        return Source("joint limits", path, "shipped default")
    return Source("joint limits", path, "your joint_limits.toml")


def run_sources(rig: str | Path | None = None, glove: str | Path | None = None,
                rig_cfg: RigConfig | None = None) -> list[Source]:
    """Every file a run with ``--rig rig`` (and ``--glove-config glove``) reads."""
    first = rig_file(rig)
    cfg = rig_cfg if rig_cfg is not None else robots.load_rig(first.path)
    # sag off (a robot rig without [robot] sag, or sag_gain 0): the grid is not used
    grid = [grid_file(first.path, cfg)] if cfg.effective_sag_gain > 0.0 else []
    out = [first, glove_file(first.path, cfg, glove), map_file(first.path, cfg), *grid,
           limits_file()]
    if isinstance(cfg, robots.RobotRigConfig) and cfg.robot is not None:
        out.append(Source("robot model", Path(cfg.robot.model), f"[robot] of {first.path.name}"))
        out.append(Source("retarget", Path(cfg.robot.retarget),
                          f"[robot] of {first.path.name}"))
    return out


def session_sources(parts: SessionParts, sources: Sequence[Source]) -> list[Source]:
    """``sources`` (:func:`run_sources`) for a session's hands: with a glove per hand,
    the map they read (the two-glove map unless ``[loop] map`` or the show names one)
    and each further hand's glove file."""
    if len(parts.hands) == 1:
        return list(sources)
    out = [Source("map", parts.map_file, "a glove per hand: the two-glove map unless "
                  "[loop] map or the show names one") if s.role == "map" else s
           for s in sources]
    for i, side in enumerate(parts.hands[1:], start=1):
        out.append(Source(f"{parts.name(i)} glove", side.glove_file or Path(),
                          "--glove-left-config, [gloves] left_config, else the right "
                          "glove's"))
    return out


def format_sources(sources: Sequence[Source], title: str = "files in use") -> str:
    """One line per file: ``  rig        /path  (why)``."""
    width = max(len(s.role) for s in sources)
    lines = [f"{title}:"]
    lines += [f"  {s.role:<{width}}  {s.path}  ({s.why})" for s in sources]
    return "\n".join(lines)
