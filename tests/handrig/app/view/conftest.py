"""The view tests' shared fixture: the shipped human rig's config (read after the test
session's HOME is pointed at a temporary folder, tests/conftest.py)."""

from __future__ import annotations

import pytest

from handrig.app.parts import build_parts
from handrig.config.rig import RigConfig


@pytest.fixture(scope="module")
def human_rig() -> RigConfig:
    return build_parts(None).rig_config
