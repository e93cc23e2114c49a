"""A show file: one TOML naming everything a live show uses.

``handrig run --show show.toml`` starts the show it describes: the rig (a preset
or a rig file), the gloves (one, or one per hand), the map and the sag grid (when
they differ from the rig file's), the buses, and the outputs (VMC, a recording,
the live view). A flag given on the command line wins over the show file. Paths
are relative to the show file's folder. Every key is checked on load; an error
names the file and the key (``examples/show.toml`` is the commented example)::

    [show]
    name = "Two-hand puppet"   # shown by the panel (default: the file's name)
    rig = "puppet_two_hands"   # a preset or a rig file
    map = ""                   # empty: the rig file's [loop] map
    grid = ""                  # empty: the rig file's [loop] sag_grid

    [gloves]
    right = "/dev/ttyACM0"     # as --glove
    left = "/dev/ttyACM1"      # as --glove-left (empty: one glove)
    right_config = ""          # as --glove-config
    left_config = ""           # as --glove-left-config

    [buses]
    right = ""                 # as --bus (empty: the rig file's [bus] port)
    left = ""                  # as --bus-left

    [outputs]
    vmc = ""                   # HOST:PORT
    openxr = ""                # HOST:PORT: the OpenXR hand joints (docs/openxr.md)
    record = ""                # a new take, .csv or .bvh
    record_rate_hz = 0.0       # a BVH take's rate (0: the glove's)
    view = ""                  # [HOST:]PORT of the live view

    [osc]
    in = "9000"                # [HOST:]PORT cues arrive on, as --osc-in

    [midi]
    port = ""                  # a MIDI input, as --midi-in
    channel = 0                # 0: every channel, else 1..16
    note.60 = "relax"          # a note-on (or cc.N: a controller rising past 64) -> a cue
    cc.20 = "stop"

    [cues]
    takes = "takes"            # the folder of the takes record/start begins

    [takes]                    # performances to layer, by name (name = file)
    left_verse = "takes/left_verse.csv"

    [[layer]]                  # a take layered under the live glove from the start
    take = "left_verse"        # a [takes] name or a performance file
    group = "left"             # a hand, a finger (left.index), the wrist, or curves
    loop = true                # false: once
    fade_s = 0.5               # its fade in and out, seconds

    [timecode]
    source = ""                # as --ltc: LTC from a .wav file or alsa:DEVICE
    fps = "auto"               # as --ltc-fps: "auto", "24", "25", "29.97" or "30"
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path

from handrig.config.cues import ShowCues, ShowMidi, ShowOsc
from handrig.config.layer_groups import DEFAULT_FADE_S, FADE_RANGE_S, group_joints
from handrig.config.loading import build, load_toml
from handrig.errors import ConfigError

GLOVE_PREFIXES = ("replay:", "opengloves:")


@dataclass(frozen=True)
class ShowHead:
    name: str = ""
    rig: str = ""
    map: str = ""
    grid: str = ""


@dataclass(frozen=True)
class ShowGloves:
    right: str = ""
    left: str = ""
    right_config: str = ""
    left_config: str = ""


@dataclass(frozen=True)
class ShowBuses:
    right: str = ""
    left: str = ""


@dataclass(frozen=True)
class ShowOutputs:
    vmc: str = ""
    openxr: str = ""
    record: str = ""
    record_rate_hz: float = 0.0
    view: str = ""

    def check(self) -> None:
        if self.vmc and ":" not in self.vmc:
            raise ConfigError("no port given", key="vmc", value=self.vmc,
                              allowed="HOST:PORT, e.g. 127.0.0.1:39539")
        if self.openxr and ":" not in self.openxr:
            raise ConfigError("no port given", key="openxr", value=self.openxr,
                              allowed="HOST:PORT, e.g. 127.0.0.1:39540")
        if self.record and Path(self.record).suffix.lower() not in (".csv", ".bvh"):
            raise ConfigError("unknown recording suffix", key="record", value=self.record,
                              allowed="a file name ending in .csv or .bvh")
        if self.record_rate_hz and not 1.0 <= self.record_rate_hz <= 2000.0:
            raise ConfigError("out of range", key="record_rate_hz",
                              value=self.record_rate_hz, allowed="0 (the glove's) or 1..2000")


TIMECODE_RATES = ("auto", "24", "25", "29.97", "30")


@dataclass(frozen=True)
class ShowTimecode:
    source: str = ""  # as --ltc: a .wav file or alsa:DEVICE ("": no timecode)
    fps: str = "auto"  # as --ltc-fps

    def check(self) -> None:
        src = self.source
        if src and not (src.startswith("alsa:") or Path(src).suffix.lower() == ".wav"):
            raise ConfigError("not an LTC source", key="timecode.source", value=src,
                              allowed="a .wav file (relative to the show file) or"
                              " alsa:DEVICE, e.g. alsa:default")
        if self.fps not in TIMECODE_RATES:
            raise ConfigError("not a timecode rate", key="timecode.fps", value=self.fps,
                              allowed='"auto" (from the signal), "24", "25", "29.97"'
                              ' (drop-frame) or "30"')


@dataclass(frozen=True)
class ShowLayer:
    """A ``[[layer]]``: a take layered under the live glove from the run's start."""

    take: str = ""
    group: str = ""
    loop: bool = True
    fade_s: float = DEFAULT_FADE_S

    def check(self) -> None:
        if not self.take:
            raise ConfigError("no take named", key="take",
                              allowed="a name from [takes], or a performance .csv/.bvh")
        group_joints(self.group, None, key="group")  # the puppet's hands: checked at start
        low, high = FADE_RANGE_S
        if not low <= self.fade_s <= high:
            raise ConfigError("out of range", key="fade_s", value=self.fade_s,
                              allowed=f"{low:g}..{high:g} seconds")


@dataclass(frozen=True)
class ShowFile:
    """A show file (see the module docstring). ``path``: where it was read from."""

    show: ShowHead = ShowHead()
    gloves: ShowGloves = ShowGloves()
    buses: ShowBuses = ShowBuses()
    outputs: ShowOutputs = ShowOutputs()
    osc: ShowOsc = field(default_factory=ShowOsc)
    midi: ShowMidi = field(default_factory=ShowMidi)
    cues: ShowCues = field(default_factory=ShowCues)
    takes: dict[str, str] = field(default_factory=dict)
    layer: tuple[ShowLayer, ...] = ()
    timecode: ShowTimecode = ShowTimecode()
    path: str = ""

    def check(self) -> None:
        if not self.show.rig:
            raise ConfigError("no rig named", key="show.rig",
                              allowed="a rig preset (puppet_two_hands, leap, ...) or a rig "
                              "file, relative to the show file")
        for name, path in self.takes.items():
            if not name or ":" in name or name in ("*", "all") or not path:
                raise ConfigError("a take needs a name and a file", key=f"takes.{name}",
                                  value=path, allowed='name = "file.csv" (a name without'
                                  ' ":", not "*" or "all"; the file a performance)')
        left = self.gloves.left
        if left and left == self.gloves.right and not left.startswith("replay:"):
            raise ConfigError("the right and the left glove are on the same port",
                              key="gloves.left", value=left,
                              allowed="a port of its own for each hand")

    @property
    def title(self) -> str:
        """The show's name for the panel: ``[show] name``, else the file's name."""
        return self.show.name or Path(self.path).stem


def _file(base: Path, value: str, key: str, show: Path, *, must_exist: bool = True) -> str:
    """``value`` (relative to the show file's folder) as a path; a file that is not there
    is a ConfigError naming the show file and ``key``."""
    if not value:
        return ""
    p = Path(value)
    p = p if p.is_absolute() else Path(os.path.normpath(base / p))
    if must_exist and not p.is_file():
        raise ConfigError(f"no such file: {p}", file=str(show), key=key, value=value,
                          allowed="an existing file (relative to the show file's folder)")
    return str(p)


def _glove(base: Path, value: str, key: str, show: Path) -> str:
    """A glove spec; a recording (``replay:FILE``) relative to the show file's folder."""
    if not value.startswith("replay:"):
        return value
    return "replay:" + _file(base, value.removeprefix("replay:"), key, show)


def _load(p: Path) -> ShowFile:
    """The show file's tables built and checked (``[osc] in``, a Python keyword, is the
    field ``in_``; an error names it ``osc.in``)."""
    data = load_toml(p)
    osc = data.get("osc")
    if isinstance(osc, dict) and "in" in osc:
        osc["in_"] = osc.pop("in")
    try:
        return build(ShowFile, data)
    except ConfigError as exc:
        key = "osc.in" if exc.key == "osc.in_" else exc.key
        allowed = exc.allowed.replace("in_", "in") if exc.allowed else exc.allowed
        raise ConfigError(exc.detail, file=str(p), key=key, value=exc.value,
                          allowed=allowed) from None


def load_show(path: str | Path) -> ShowFile:
    """Load and check a show file; its paths come back resolved (a rig given as a file,
    the map, grid, glove files, recordings to replay and the take to record, relative to
    the show file's folder). ConfigError names the file and the key."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError("no such show file", key="--show", value=str(path),
                          allowed="a show file (see examples/show.toml)")
    show = _load(p)
    base = p.resolve().parent
    rig = show.show.rig
    if "/" in rig or rig.endswith(".toml"):
        rig = _file(base, rig, "show.rig", p)
    try:
        return dataclasses.replace(
            show, path=str(p),
            show=dataclasses.replace(
                show.show, rig=rig, map=_file(base, show.show.map, "show.map", p),
                grid=_file(base, show.show.grid, "show.grid", p)),
            gloves=dataclasses.replace(
                show.gloves, right=_glove(base, show.gloves.right, "gloves.right", p),
                left=_glove(base, show.gloves.left, "gloves.left", p),
                right_config=_file(base, show.gloves.right_config, "gloves.right_config", p),
                left_config=_file(base, show.gloves.left_config, "gloves.left_config", p)),
            outputs=dataclasses.replace(
                show.outputs,
                record=_file(base, show.outputs.record, "outputs.record", p,
                             must_exist=False)),
            cues=dataclasses.replace(show.cues, takes=_file(base, show.cues.takes,
                                                            "cues.takes", p,
                                                            must_exist=False)),
            takes={name: _file(base, path, f"takes.{name}", p)
                   for name, path in show.takes.items()},
            layer=tuple(dataclasses.replace(
                layer, take=layer.take if layer.take in show.takes
                else _file(base, layer.take, f"layer[{i}].take", p))
                for i, layer in enumerate(show.layer)),
            timecode=dataclasses.replace(
                show.timecode, source=show.timecode.source
                if show.timecode.source.startswith("alsa:") else
                _file(base, show.timecode.source, "timecode.source", p)))
    except ConfigError as exc:
        raise exc.located(str(p)) from None
