"""Config files: TOML loaded into frozen, validated dataclasses.

``load(path, cls)`` reads a TOML file and builds ``cls`` from it, checking every
key against the dataclass's type hints. Any problem becomes one
:class:`~handrig.errors.ConfigError` naming the file, the key (a dotted path such
as ``servos[3].joint``), the bad value and what is allowed. A dataclass can add
its own checks in a ``check()`` method that raises ``ConfigError`` with a
``key`` relative to itself; the loader prefixes the path and the file.

Supported field types: ``bool``, ``int``, ``float`` (an int is accepted),
``str``, ``Literal[...]``, ``Enum`` subclasses (by value), nested dataclasses,
``tuple[T, ...]``, fixed ``tuple[A, B]``, ``dict[str, T]``, and ``T | None``.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from handrig.config.bounded import MAX_CONFIG_BYTES, read_text
from handrig.config.paths import CONFIG_DIR, REPO_ROOT, config_file
from handrig.errors import ConfigError
from handrig.hand import ALL_JOINT_NAMES, anatomical_limits_deg, is_joint_name

T = TypeVar("T")

__all__ = ["CONFIG_DIR", "REPO_ROOT", "JointLimits", "build", "check_joint_name", "load",
           "load_joint_limits", "load_toml"]
"""``CONFIG_DIR`` (where the shipped configs, maps and baked grid live) and ``REPO_ROOT``
are :mod:`handrig.config.paths`' and are named here too, beside the loaders that read them."""


def load_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing or malformed file is a ConfigError naming it."""
    p = Path(path)
    text = read_text(p, MAX_CONFIG_BYTES, "a handrig TOML file", ConfigError)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=str(p)) from None
    except RecursionError:
        raise ConfigError("not valid TOML: nested too deeply", file=str(p)) from None


def load(path: str | Path, cls: type[T], *, section: str | None = None) -> T:
    """Load ``cls`` from the TOML file ``path`` (optionally from one table ``section``)."""
    data: Any = load_toml(path)
    prefix = ""
    if section is not None:
        if section not in data:
            raise ConfigError(f"missing table [{section}]", file=str(path))
        data, prefix = data[section], section
    try:
        return build(cls, data, key=prefix)
    except ConfigError as exc:
        raise exc.located(str(path)) from None


def _join(key: str, part: str) -> str:
    return f"{key}.{part}" if key else part


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def build(cls: type[T], data: Any, *, key: str = "") -> T:
    """Build dataclass ``cls`` from plain data (a TOML table); errors carry ``key`` paths."""
    return typing.cast(T, _convert(cls, data, key))


def _convert(tp: Any, value: Any, key: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _convert(inner[0], value, key)
        errors = []
        for a in inner:
            try:
                return _convert(a, value, key)
            except ConfigError as exc:
                errors.append(exc.detail)
        raise ConfigError("; ".join(errors), key=key, value=value)
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(
                "not an allowed value", key=key, value=value,
                allowed=", ".join(repr(a) for a in args),
            )
        return value
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _build_dataclass(tp, value, key)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            raise ConfigError(
                "not an allowed value", key=key, value=value,
                allowed=", ".join(repr(m.value) for m in tp),
            ) from None
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError("expected an array", key=key, value=value)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{key}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(
                f"expected an array of {len(args)} values", key=key, value=value
            )
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(_convert(a, v, f"{key}[{i}]") for i, (a, v) in pairs)
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(value, dict):
            raise ConfigError("expected a table", key=key, value=value)
        vt = args[1] if len(args) == 2 else Any
        return {str(k): _convert(vt, v, _join(key, str(k))) for k, v in value.items()}
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError("expected true or false", key=key, value=value)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError("expected an integer", key=key, value=value)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError("expected a number", key=key, value=value)
        if not math.isfinite(value):
            raise ConfigError("expected a finite number", key=key, value=value)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError("expected a string", key=key, value=value)
        return value
    if tp is Path:
        if not isinstance(value, str):
            raise ConfigError("expected a path string", key=key, value=value)
        return Path(value)
    raise TypeError(f"config type {_type_name(tp)} at {key!r} is not supported")


def _build_dataclass(cls: type, value: Any, key: str) -> Any:
    if not isinstance(value, dict):
        raise ConfigError("expected a table", key=key or None, value=value)
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(value) - set(fields))
    if unknown:
        raise ConfigError(
            "unknown key", key=_join(key, unknown[0]), allowed=", ".join(sorted(fields))
        )
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        sub = _join(key, name)
        if name in value:
            kwargs[name] = _convert(hints[name], value[name], sub)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError("missing required key", key=sub)
    try:
        obj = cls(**kwargs)
        check = getattr(obj, "check", None)
        if callable(check):
            check()
    except ConfigError as exc:
        inner = exc.key
        raise ConfigError(
            exc.detail,
            key=_join(key, inner) if inner else (key or None),
            value=exc.value,
            allowed=exc.allowed,
        ) from None
    except (TypeError, ValueError, ArithmeticError, LookupError) as exc:
        # a value the types allow but the class's own code cannot use
        raise ConfigError(f"not a usable {cls.__name__}: {exc}", key=key or None) from None
    return obj


def check_joint_name(name: str, key: str) -> None:
    """Raise a ConfigError at ``key`` unless ``name`` is a curve or DOF name."""
    if not is_joint_name(name):
        import difflib

        close = difflib.get_close_matches(name, ALL_JOINT_NAMES, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ConfigError(
            "unknown joint", key=key, value=name,
            allowed=f"{hint}one of the 50 curve names (e.g. riIndexMCPy) or the wrist DOFs"
            " (riWristFlexion, riWristDeviation, le...)",
        )


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits in degrees, overriding the anatomical defaults of :mod:`handrig.hand`.

    File ``config/joint_limits.toml``::

        [limits]
        riIndexMCPy = [-10.0, 85.0]   # [low, high], degrees, flexion positive
    """

    limits: dict[str, tuple[float, float]] = field(default_factory=dict)

    def check(self) -> None:
        for name, (low, high) in self.limits.items():
            check_joint_name(name, f"limits.{name}")
            if low >= high:
                raise ConfigError(
                    "inverted limit: low must be below high", key=f"limits.{name}",
                    value=[low, high], allowed="[low, high] with low < high",
                )

    def of(self, name: str) -> tuple[float, float]:
        """Limits for ``name``: the override if any, else the anatomical default."""
        return self.limits.get(name) or anatomical_limits_deg(name)


def load_joint_limits(path: str | Path | None = None) -> JointLimits:
    """Load joint-limit overrides (default: the user's ``joint_limits.toml`` when there is
    one, :func:`handrig.config.paths.config_file`, else ``config/joint_limits.toml``)."""
    if path is None:
        path = config_file("joint_limits.toml")
    return load(path, JointLimits)
