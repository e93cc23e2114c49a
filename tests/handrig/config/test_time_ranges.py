"""Every time and rate in the rig file and the glove file is bounded (issue 24.6).

The test walks the config dataclasses for keys ending in _s, _ms, _us or _hz, so a
key added later without a range fails here. Each is set, through the loader, to an
absurd value (1e9, below zero, NaN): the error names the key and says the range.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Any

import pytest

from handrig.config.loading import build, load_toml
from handrig.config.paths import CONFIG_DIR
from handrig.config.rig import RigConfig
from handrig.devices.glove_calibration import GloveConfig
from handrig.errors import ConfigError

TIME_SUFFIXES = ("_s", "_ms", "_us", "_hz")


def _time_keys(cls: type, prefix: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], type]]:
    """(path of table names and key, the key's type) for every time key under ``cls``."""
    out: list[tuple[tuple[str, ...], type]] = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            out += _time_keys(typing.cast(type, tp), (*prefix, f.name))
            continue
        args = typing.get_args(tp)
        if args and any(dataclasses.is_dataclass(a) for a in args):
            inner = next(a for a in args if dataclasses.is_dataclass(a))
            nested = _time_keys(inner, (*prefix, f.name))
            if type(None) in args:  # an optional table ([left_bus]): walked like a table
                out += nested
                continue
            # keys inside arrays of tables are not walked below: there must be none
            assert not nested, f"time keys in [[{f.name}]] are not covered: {nested}"
            continue
        if f.name.endswith(TIME_SUFFIXES):
            base = tp if tp in (int, float) else next(a for a in args if a in (int, float))
            out.append(((*prefix, f.name), base))
    return out


RIG_KEYS = _time_keys(RigConfig)
GLOVE_KEYS = _time_keys(GloveConfig)


def test_the_walk_finds_the_keys_the_issue_names() -> None:
    rig = {".".join(p) for p, _ in RIG_KEYS}
    glove = {".".join(p) for p, _ in GLOVE_KEYS}
    assert {"loop.relax_time_s", "loop.glove_timeout_s", "loop.resume_time_s",
            "loop.rate_hz", "bus.watchdog_ms", "left_bus.watchdog_ms", "silence.action_s",
            "servo_settings.return_delay_us"} <= rig
    assert {"glove.rate_hz", "filter.min_cutoff_hz", "filter.d_cutoff_hz"} <= glove


def _with(data: dict[str, Any], path: tuple[str, ...], value: object) -> dict[str, Any]:
    out = dict(data)
    node = out
    for part in path[:-1]:
        node[part] = dict(node.get(part, {}))
        node = node[part]
    node[path[-1]] = value
    return out


def _absurd(tp: type) -> list[object]:
    if tp is int:
        return [10**9, -1]
    return [1e9, -1.0, math.nan]


CASES = ([(RigConfig, "rig.toml", p, v) for p, tp in RIG_KEYS for v in _absurd(tp)]
         + [(GloveConfig, "glove.toml", p, v) for p, tp in GLOVE_KEYS for v in _absurd(tp)])


@pytest.mark.parametrize(("cls", "file", "path", "value"), CASES,
                         ids=[f"{c[1]}:{'.'.join(c[2])}={c[3]!r}" for c in CASES])
def test_an_absurd_time_is_refused_naming_key_and_range(
        cls: type, file: str, path: tuple[str, ...], value: object) -> None:
    shipped = load_toml(CONFIG_DIR / file)
    build(cls, shipped)  # the shipped file itself is accepted
    with pytest.raises(ConfigError) as info:
        build(cls, _with(shipped, path, value))
    err = info.value
    assert err.key is not None and err.key.endswith(path[-1]), str(err)
    assert path[-1] in str(err)
    if isinstance(value, float) and math.isnan(value):
        assert "finite" in str(err), str(err)  # the loader refuses NaN before any range
        return
    assert err.allowed, f"no range given for {'.'.join(path)}: {err}"
    assert any(ch.isdigit() for ch in err.allowed), err.allowed
