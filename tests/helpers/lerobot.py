"""Glove takes with a known time course for the LeRobot tests (tests/handrig/app/lerobot)."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import pytest

from handrig.config.loading import CONFIG_DIR

LEROBOT_DISTRIBUTIONS = ("lerobot", "lerobot_robot_handrig", "lerobot_teleoperator_handrig")


def skip_without_lerobot() -> None:
    """Skip the calling test module, saying why, unless LeRobot and both of handrig's
    plugin distributions are installed (``make lerobot-deps``)."""
    for dist in LEROBOT_DISTRIBUTIONS:
        try:
            importlib.metadata.distribution(dist)
        except importlib.metadata.PackageNotFoundError:
            pytest.skip(f"{dist} is not installed (make lerobot-deps installs LeRobot and "
                        "handrig's plugins for it)", allow_module_level=True)


def write_ramp_take(path: Path, rows: int, row_s: float, start: int, step: int) -> Path:
    """The demo glove's first row held, index MCP ramping ``step`` counts a row from
    ``start``, one row every ``row_s`` seconds."""
    lines = ["# handrig glove recording 1", f"# rate_hz: {1.0 / row_s:g}",
             "t_s,riThumbCMCx,riThumbCMCy,riThumbCMCz,riIndexMCPy,riPinkyMCPy,"
             "qx,qy,qz,qw,buttons"]
    lines += [f"{i * row_s:.6f},2229,2230,1643,{start + step * i},1707,0,0,0,1,0"
              for i in range(rows)]
    path.write_text("\n".join(lines) + "\n")
    return path


def unfiltered_glove_file(path: Path) -> Path:
    """The shipped glove file without its One Euro filter, so a sample's pose does not
    depend on which samples came before it (the tests match actions to rows)."""
    text = (CONFIG_DIR / "glove.toml").read_text()
    at = text.index("[filter]")
    assert text.index("enabled = true", at) == text.index("\n", at) + 1
    path.write_text(text[:at] + text[at:].replace("enabled = true", "enabled = false", 1))
    return path
