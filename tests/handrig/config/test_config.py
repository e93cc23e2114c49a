from dataclasses import dataclass
from typing import Literal

import pytest

from handrig.config.loading import JointLimits, build, load, load_joint_limits
from handrig.errors import ConfigError


def write(tmp_path, text, name="limits.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_limits_load():
    limits = load_joint_limits()
    assert limits.of("riIndexPIPy") == (0.0, 110.0)


def test_override_applies(tmp_path):
    p = write(tmp_path, "[limits]\nriIndexMCPy = [-5, 80.5]\n")
    limits = load(p, JointLimits)
    assert limits.of("riIndexMCPy") == (-5.0, 80.5)
    assert limits.of("riIndexPIPy") == (0.0, 110.0)


def test_malformed_file_names_file_and_position(tmp_path):
    p = write(tmp_path, "[limits\nriIndexMCPy = [0, 1]\n")
    with pytest.raises(ConfigError) as exc:
        load(p, JointLimits)
    msg = str(exc.value)
    assert str(p) in msg and "not valid TOML" in msg and "line 1" in msg


def test_unknown_joint_is_named_with_a_suggestion(tmp_path):
    p = write(tmp_path, "[limits]\nriIndxMCPy = [0, 90]\n")
    with pytest.raises(ConfigError) as exc:
        load(p, JointLimits)
    msg = str(exc.value)
    assert str(p) in msg
    assert "limits.riIndxMCPy" in msg and "unknown joint" in msg
    assert "did you mean 'riIndexMCPy'" in msg


def test_inverted_limit_is_its_own_message(tmp_path):
    p = write(tmp_path, "[limits]\nriIndexPIPy = [90, 10]\n")
    with pytest.raises(ConfigError) as exc:
        load(p, JointLimits)
    msg = str(exc.value)
    assert "inverted limit" in msg and "[90.0, 10.0]" in msg and "limits.riIndexPIPy" in msg


def test_wrong_types_and_missing_file(tmp_path):
    p = write(tmp_path, "[limits]\nriIndexPIPy = [0, 'a lot']\n")
    with pytest.raises(ConfigError, match=r"limits.riIndexPIPy\[1\].*expected a number"):
        load(p, JointLimits)
    with pytest.raises(ConfigError, match="file not found"):
        load(tmp_path / "nope.toml", JointLimits)


@dataclass(frozen=True)
class _Servo:
    id: int
    mode: Literal["position", "extended"] = "position"


@dataclass(frozen=True)
class _Rig:
    port: str
    servos: tuple[_Servo, ...] = ()
    rate_hz: float = 100.0


def test_nested_paths_unknown_keys_and_literals():
    rig = build(_Rig, {"port": "/dev/x", "servos": [{"id": 1}, {"id": 2, "mode": "extended"}]})
    assert rig.servos[1].mode == "extended" and rig.rate_hz == 100.0
    with pytest.raises(ConfigError, match=r"servos\[1\].mode.*allowed: 'position', 'extended'"):
        build(_Rig, {"port": "p", "servos": [{"id": 1}, {"id": 2, "mode": "fast"}]})
    with pytest.raises(ConfigError, match=r"servos\[0\].speed.*unknown key"):
        build(_Rig, {"port": "p", "servos": [{"id": 1, "speed": 3}]})
    with pytest.raises(ConfigError, match=r"port.*missing required key"):
        build(_Rig, {})
    with pytest.raises(ConfigError, match="expected an integer"):
        build(_Rig, {"port": "p", "servos": [{"id": True}]})


@dataclass(frozen=True)
class _Ratio:
    top: float = 1.0
    bottom: float = 1.0

    def check(self) -> None:
        _ = self.top / self.bottom  # code of its own that a value can break


@dataclass(frozen=True)
class _Holder:
    ratio: _Ratio = _Ratio()


def test_a_class_failing_on_an_allowed_value_is_a_config_error(tmp_path):
    p = write(tmp_path, "[ratio]\nbottom = 0\n", name="ratio.toml")
    with pytest.raises(ConfigError) as exc:
        load(p, _Holder)
    msg = str(exc.value)
    assert "ratio.toml" in msg and "'ratio'" in msg and "division by zero" in msg


def test_deeply_nested_toml_is_a_config_error(tmp_path):
    p = write(tmp_path, "x = " + "[" * 100_000 + "]" * 100_000 + "\n", name="deep.toml")
    with pytest.raises(ConfigError, match=r"deep\.toml: not valid TOML"):
        load(p, JointLimits)
