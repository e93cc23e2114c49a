"""Fixtures shared by the loop's tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from handrig.clock import MonotonicClock
from tests.helpers.pipe_glove import PipeGlove


@pytest.fixture
def pipe_glove() -> Iterator[PipeGlove]:
    g = PipeGlove(MonotonicClock(spin_s=0.0))
    yield g
    g.close()
