"""``handrig config show``: the effective configuration, each value with its source.

Prints the files a run would use (rig, glove, map, sag grid, joint limits) and
why each one, then every setting of the rig file and the glove file: the value a
run uses and where it comes from (the file, or handrig's default when the file
does not set it).
"""

from __future__ import annotations

import argparse
import dataclasses
import enum
import json
from pathlib import Path
from typing import Any

from handrig.app.sources import Source, format_sources, run_sources
from handrig.cli._rig import add_rig_argument
from handrig.config.loading import load_toml
from handrig.devices.glove_calibration import load_glove_config
from handrig.pose.robot_rig import load_rig

DEFAULT = "default"


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "config", help="show the configuration a run uses, and where each value comes from",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(func=lambda _args: _usage(p))
    group = p.add_subparsers(dest="config_what", metavar="WHAT")
    s = group.add_parser("show", help="the effective configuration with each value's source",
                         description=__doc__,
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    add_rig_argument(s)
    s.add_argument("--glove-config", default=None, metavar="FILE",
                   help="glove file (default: as `handrig run` chooses it)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=run)


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def _plain(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    return value


def settings(obj: Any, raw: dict[str, Any], file: str, prefix: str = "") -> list[
        tuple[str, Any, str]]:
    """``(dotted key, value, source)`` for every field of the config dataclass ``obj``;
    ``raw`` is the file's table: a key it sets comes from ``file``, else the default."""
    out: list[tuple[str, Any, str]] = []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        key = f"{prefix}{f.name}"
        given = isinstance(raw, dict) and f.name in raw
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out += settings(value, raw.get(f.name, {}) if given else {}, file, f"{key}.")
        elif (isinstance(value, tuple) and value and dataclasses.is_dataclass(value[0])
              and not isinstance(value[0], type)):
            items = raw.get(f.name, []) if given else []
            for i, item in enumerate(value):
                sub = items[i] if i < len(items) else {}
                out += settings(item, sub, file, f"{key}[{i}].")
        else:
            out.append((key, _plain(value), file if given else DEFAULT))
    return out


def _table(rows: list[tuple[str, Any, str]]) -> list[str]:
    width = min(44, max(len(f"{k} = {json.dumps(v)}") for k, v, _ in rows))
    return [f"  {f'{k} = {json.dumps(v)}':<{width}}  <- {src}" for k, v, src in rows]


def run(args: argparse.Namespace) -> int:
    sources = run_sources(args.rig, args.glove_config)
    by_role: dict[str, Source] = {s.role: s for s in sources}
    rig_path, glove_path = by_role["rig"].path, by_role["glove"].path
    rig = load_rig(rig_path)
    glove = load_glove_config(glove_path)
    rig_rows = settings(rig, load_toml(rig_path), rig_path.name)
    glove_rows = settings(glove, load_toml(glove_path), glove_path.name)
    if args.json:
        print(json.dumps({
            "files": [{"role": s.role, "path": str(s.path), "why": s.why} for s in sources],
            "rig": [{"key": k, "value": v, "source": src} for k, v, src in rig_rows],
            "glove": [{"key": k, "value": v, "source": src} for k, v, src in glove_rows],
        }))
        return 0
    print(format_sources(sources))
    print(f"\nrig ({rig_path}); '{DEFAULT}' is handrig's value for a key the file leaves out:")
    print("\n".join(_table(rig_rows)))
    print(f"\nglove ({glove_path}):")
    print("\n".join(_table(glove_rows)))
    return 0
