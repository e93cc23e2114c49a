"""`pip install -e '.[lerobot]'` alone makes LeRobot find handrig's devices: the installed
metadata of handrig's `lerobot` extra names both plugin distributions (LeRobot 0.4.4
imports every installed distribution whose name starts with `lerobot_robot_` or
`lerobot_teleoperator_`, and only those), each by a direct reference to its folder in
this checkout. Reads the installed metadata only: it holds with or without LeRobot."""

from __future__ import annotations

import importlib.metadata
import sysconfig
import tomllib
from pathlib import Path
from urllib.parse import unquote, urlparse

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[4]
PLUGINS = {"lerobot_teleoperator_handrig": "lerobot_teleoperator_",
           "lerobot_robot_handrig": "lerobot_robot_"}


def installed_handrig() -> importlib.metadata.Distribution:
    """handrig's metadata as installed in this environment's site-packages, where
    LeRobot's console scripts see it (not a build's handrig.egg-info in the checkout,
    which the current folder on sys.path would find first)."""
    paths = sorted({sysconfig.get_paths()[k] for k in ("purelib", "platlib")})
    found = list(importlib.metadata.distributions(name="handrig", path=paths))
    assert len(found) == 1, f"handrig is installed {len(found)} times in {paths}"
    return found[0]


def extra_requirements(extra: str) -> list[Requirement]:
    out = []
    for line in installed_handrig().requires or []:
        req = Requirement(line)
        if req.marker is not None and req.marker.evaluate({"extra": extra}) and \
                not req.marker.evaluate({"extra": ""}):
            out.append(req)
    return out


def test_the_lerobot_extra_names_both_plugin_distributions_by_their_folder() -> None:
    reqs = {r.name: r for r in extra_requirements("lerobot")}
    assert "lerobot" in reqs, sorted(reqs)
    for name, prefix in PLUGINS.items():
        assert name in reqs, (
            f"handrig's installed [lerobot] extra does not name {name} (it names "
            f"{sorted(reqs)}): reinstall handrig (make .venv/.installed)")
        url = urlparse(reqs[name].url or "")
        assert url.scheme == "file", reqs[name]
        folder = Path(unquote(url.path))
        assert folder == ROOT / "plugins" / name, folder
        # the distribution's own name is what LeRobot's discovery matches and imports
        project = tomllib.loads((folder / "pyproject.toml").read_text())["project"]
        assert project["name"] == name and name.startswith(prefix)
        assert (folder / name / "__init__.py").is_file()


def test_the_other_extras_are_as_before() -> None:
    dev = {r.name for r in extra_requirements("dev")}
    show = {r.name for r in extra_requirements("show")}
    assert {"pytest", "mypy", "ruff", "handrig"} <= dev  # handrig[show]
    assert show == {"mido", "python-rtmidi"}
    assert not any(r.url for r in extra_requirements("dev") + extra_requirements("show"))
