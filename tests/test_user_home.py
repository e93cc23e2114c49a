"""Tests never read the user's home, whatever a fixture's scope.

``handrig bake --plot`` (which README suggests) writes a grid into the user's data
directory, which ``handrig run`` then reads by default. The grid tests compare
the *shipped* grid with the paper's table; a fixture that loads the default grid
once per module must still get the shipped one when the developer has baked
their own. This test makes such a home and runs those tests in it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def test_grid_tests_pass_in_a_home_with_a_baked_grid(tmp_path: Path) -> None:
    home = tmp_path / "home"
    env = {k: v for k, v in os.environ.items() if not k.startswith("XDG_")}
    env["HOME"] = str(home)  # a user with no XDG variables: ~/.local/share/handrig
    bake = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "bake", "--plot", "--quiet", "--step-deg", "15"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert bake.returncode == 0, bake.stderr
    baked = home / ".local" / "share" / "handrig" / "sag_grid.npz"
    assert baked.is_file() and baked.with_suffix(".png").is_file()
    assert "read it from now on" in bake.stdout

    # the baked grid is what a run in this home reads ...
    show = subprocess.run([sys.executable, "-m", "handrig.cli", "config", "show"], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=120)
    assert show.returncode == 0, show.stderr
    assert f"{baked}  (your baked grid" in show.stdout

    # ... and the shipped grid's tests, run by this user, still test the shipped grid
    tests = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
         "tests/handrig/pose/test_sag.py", "-k", "shipped"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert tests.returncode == 0, tests.stdout[-3000:]
    assert "3 passed" in tests.stdout and "failed" not in tests.stdout
    assert baked.is_file()  # the tests did not touch the user's files
