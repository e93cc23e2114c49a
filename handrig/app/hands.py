"""A session's hands: one (the whole rig, one glove) or a glove per hand, each its own loop.

:func:`build_session_parts` is what every run builds: :class:`SessionParts`, a tuple of
hands, each a :class:`~handrig.app.parts.RigParts`; one hand is N = 1 (the whole
rig on one glove). Which hands share a bus is data from the rig file
(:attr:`SessionParts.buses`: one bus for all unless ``[left_bus]``).

A rig whose ``[[servos]]`` drive joints of both hands, run with a glove per hand
(``--glove`` and ``--glove-left``, or ``[gloves]`` in the rig file), is two sides
composed: each has its glove, its servos (:func:`handrig.config.rig.hand_rig`),
its pipeline and, in the session, its own :class:`~handrig.loop.rig.Rig`. The two
pipelines share one map, the two-glove map (``config/maps/default_two_gloves.toml``
unless ``[loop] map`` names another with ten controls): every curve of both hands
reads both gloves' controls. :class:`SharedControls` holds the newest controls of
both gloves; each side writes its own glove's into it and reads the whole vector,
so a hand follows its own glove at once and the other glove as of its last frame.
The same goes for the forearms: a side's orientation also tells the other side's
pipeline where this forearm is (its sag in the full pose the outputs get).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handrig.app.parts import (
    ForearmAngles,
    RigParts,
    _resolve,
    build_parts,
    control_channels,
    glove_spec,
)
from handrig.config.loading import load_joint_limits
from handrig.config.rig import HAND_NAMES, RigConfig, hand_of_joint, hand_rig
from handrig.config.rig_files import rig_file_path
from handrig.devices.glove import GloveSample
from handrig.devices.glove_calibration import (
    GloveConfig,
    GloveControls,
    default_glove_path,
    load_glove_config,
)
from handrig.errors import ConfigError
from handrig.hand import mirror_name
from handrig.loop.ports import FloatArray
from handrig.loop.rig import Rig
from handrig.pose import robot_rig as robotrig
from handrig.pose.expand import DEFAULT_TWO_GLOVE_MAP, Expander
from handrig.pose.pipeline import PosePipeline
from handrig.pose.robot_rig import is_two_hand
from handrig.pose.sag import SagGrid, default_grid_path

GLOVE_FLAGS = {"ri": "--glove", "le": "--glove-left"}
RIG_GLOVE_KEYS = {"ri": "gloves.right", "le": "gloves.left"}


class SharedControls:
    """The newest controls of both gloves, in the map's order (the mean controls until a
    glove's first frame). Each side writes only its own glove's slots."""

    def __init__(self, means_deg: FloatArray) -> None:
        self.values = np.array(means_deg, dtype=np.float64)
        self.forearm_deg: dict[str, tuple[float, float]] = {}


class SideControls:
    """A side's ``controls_from_raw``: its glove's controls (calibrated, filtered) into
    its slots of the shared vector, then the whole vector (both gloves) out."""

    def __init__(self, glove: GloveControls, shared: SharedControls,
                 slots: np.ndarray) -> None:
        self.glove = glove
        self.shared = shared
        self.slots = slots
        self._own = np.zeros(len(slots))

    def __call__(self, raw: FloatArray, t_s: float, out: FloatArray) -> FloatArray:
        own = self.glove(raw, t_s, self._own)
        shared = self.shared.values
        shared[self.slots] = own
        out[:] = shared
        return out


class SideOrientation:
    """A side's forearm angles (its glove's IMU), also handed to the other side's
    pipeline as where this forearm is."""

    def __init__(self, angles: ForearmAngles, hand: str, shared: SharedControls) -> None:
        self.angles = angles
        self.hand = hand
        self.shared = shared
        self.other: PosePipeline | None = None  # set once both pipelines exist

    def __call__(self, sample: GloveSample) -> tuple[float, float]:
        a = self.angles(sample)
        other = self.other
        if other is not None and a is not other.other_forearm_deg:
            other.other_forearm_deg = a
        return a


@dataclass
class SessionParts:
    """The device-free parts of a session: its hands (a :class:`RigParts` each, in
    order: the right hand first; one hand: the whole rig, ``hand`` None), the whole
    rig, and the map they read (``shared``: both gloves' controls, with a glove per
    hand)."""

    rig_config: RigConfig
    rig_file: Path
    hands: tuple[RigParts, ...]
    map_file: Path
    shared: SharedControls | None = None

    @classmethod
    def one(cls, parts: RigParts) -> SessionParts:
        """One hand: the whole rig on one glove."""
        return cls(parts.rig_config, parts.rig_file, (parts,), parts.map_file or Path())

    @property
    def buses(self) -> tuple[tuple[int, ...], ...]:
        """Which hands (indices into :attr:`hands`) share which bus, as the rig file
        says: one bus for every hand, unless ``[left_bus]`` gives each hand its own."""
        if len(self.hands) > 1 and self.rig_config.left_bus is not None:
            return tuple((i,) for i in range(len(self.hands)))
        return (tuple(range(len(self.hands))),)

    def key(self, i: int) -> str:
        """Hand ``i``'s key: ``"ri"``, ``"le"``, or ``""`` for the whole rig."""
        return self.hands[i].hand or ""

    def name(self, i: int) -> str:
        """Hand ``i`` for a person: ``"right"``, ``"left"``, ``""`` for the whole rig."""
        return HAND_NAMES.get(self.key(i), "")


class AllHands:
    """The show's controls acting on every hand at once (the keys, the view's buttons,
    a signal): relax/resume, stop (each eases down), e-stop. Safe from any thread, as
    each rig's are."""

    def __init__(self, rigs: Sequence[Rig]) -> None:
        self.rigs = rigs  # filled once the loops are built
        self.estop_reason = ""  # set before any rig is e-stopped
        # the last few cues taken (OSC, MIDI, the r key), naming their source: the view's
        self.cue_source: Callable[[], tuple[str, ...]] = tuple

    def recent_cues(self) -> tuple[str, ...]:
        return self.cue_source()

    def toggle_relax(self) -> None:
        for rig in self.rigs:
            rig.toggle_relax()

    def relax(self, reason: str) -> None:
        for rig in self.rigs:
            rig.relax(reason)

    def resume(self, reason: str) -> None:
        for rig in self.rigs:
            rig.resume(reason)

    def request_stop(self, reason: str = "stop requested") -> None:
        for rig in self.rigs:
            rig.request_stop(reason)

    def estop(self, reason: str = "e-stop key") -> None:
        self.estop_reason = reason
        for rig in self.rigs:
            rig.estop(reason)


def glove_specs(rig: RigConfig, right: str | None, left: str | None
                ) -> tuple[str | None, str | None]:
    """The gloves of a run: ``--glove``/``--glove-left`` over the rig file's ``[gloves]``."""
    return (right or rig.gloves.right or None, left or rig.gloves.left or None)


def check_gloves(parts: SessionParts, specs: tuple[str | None, ...]) -> tuple[str, ...]:
    """Each hand's glove spec checked (:func:`handrig.app.parts.glove_spec`; a second
    glove not the first's port): ConfigError naming the hand's flag. Nothing is
    opened."""
    if len(parts.hands) == 1:
        side = parts.hands[0]
        return (glove_spec(specs[0], side.glove_config, side.glove_file),)
    ri, le = parts.hands
    return check_two_gloves(specs[0] or "", specs[1] or "", ri.glove_config, le.glove_config,
                            ri.glove_file, le.glove_file)


def check_two_gloves(right: str, left: str, cfg_right: GloveConfig, cfg_left: GloveConfig,
                     right_file: Path | None = None, left_file: Path | None = None
                     ) -> tuple[str, str]:
    """Both gloves' specs checked (:func:`handrig.app.parts.glove_spec`, the message
    naming ``--glove-left`` for the left), and not the same port twice: ConfigError
    naming both flags. (One recording may be replayed for both hands.) Nothing is
    opened."""
    r = glove_spec(right, cfg_right, right_file)
    try:
        le = glove_spec(left, cfg_left, left_file)
    except ConfigError as exc:
        if exc.key == "--glove":
            raise ConfigError(exc.detail,
                              key="--glove-left", value=exc.value,
                              allowed=exc.allowed) from None
        raise

    def where(spec: str) -> str:
        for prefix in ("replay:", "opengloves:"):
            spec = spec.removeprefix(prefix)
        p = Path(spec)
        return str(p.resolve()) if p.exists() else spec
    replays = r.startswith("replay:") or le.startswith("replay:")
    if not replays and where(r) == where(le):
        raise ConfigError(
            f"the right and the left glove are on the same port: {where(r)}",
            key="--glove-left", value=left, allowed=f"a port of its own for each hand: --glove "
            f"{right} and --glove-left another (or [gloves] right and left in the rig file)")
    return r, le


def _glove_names(cal_curves: tuple[str, ...], wanted: list[str]) -> list[str]:
    """The glove file's curve for each of ``wanted`` (a hand's controls of the map): the
    same name, or the other hand's (a left glove calibrated with the right glove's
    curve names)."""
    out = []
    for name in wanted:
        out.append(name if name in cal_curves or mirror_name(name) not in cal_curves
                   else mirror_name(name))
    return out


def side_control_channels(side: RigParts) -> tuple[int, ...]:
    """The raw channel of the side's glove driving each control of its loop (both hands'
    controls, in the map's order; -1 for the other hand's), for its telemetry; the whole
    rig on one glove: its channel for each control."""
    controls = side.pipeline.expander.controls
    if side.hand is None:
        return control_channels(side.glove_config, controls)
    cal = tuple(c.curve for c in side.glove_config.channels)
    own = [c for c in controls if hand_of_joint(c) == side.hand]
    names = dict(zip(own, _glove_names(cal, own), strict=True))
    return control_channels(side.glove_config, controls, [names.get(c, "") for c in controls])


def build_session_parts(rig_file: str | Path | None = None,
                        glove_file: str | Path | None = None,
                        left_glove_file: str | Path | None = None, *,
                        glove_per_hand: bool = False,
                        map_file: str | Path | None = None,
                        grid_file: str | Path | None = None) -> SessionParts:
    """The hands of a session on the rig file (or preset): the whole rig on one glove
    (:func:`handrig.app.parts.build_parts`), or with ``glove_per_hand`` the rig cut
    into its two hands, each with its glove file (``glove_file`` for the right;
    ``left_glove_file``, else ``[gloves] left_config``, else the right's for the
    left), the two-glove map and the sag grid (``map_file``, ``grid_file``: a show
    file's, instead of the rig file's)."""
    if not glove_per_hand:
        one = build_parts(rig_file, glove_file, map_file=map_file, grid_file=grid_file)
        return SessionParts.one(one)
    rig_path = rig_file_path(rig_file)
    rig = robotrig.load_rig(rig_path)
    if not is_two_hand(rig):
        raise ConfigError("a glove per hand needs a rig with servos for both hands",
                          file=str(rig_path), key="servos",
                          allowed="[[servos]] with joints ri... and le... (the preset "
                          "puppet_two_hands), or one glove")
    base = rig_path.resolve().parent
    loop = rig.loop
    right_glove = Path(glove_file) if glove_file else _resolve(
        base, loop.glove, default_glove_path(), rig_file=rig_path, key="loop.glove")
    left_glove = (Path(left_glove_file) if left_glove_file else _resolve(
        base, rig.gloves.left_config, right_glove, rig_file=rig_path,
        key="gloves.left_config"))
    limits = load_joint_limits()
    map_file = Path(map_file) if map_file else _resolve(
        base, loop.map, DEFAULT_TWO_GLOVE_MAP, rig_file=rig_path, key="loop.map")
    expander = Expander.from_file(map_file, limits)
    controls = list(expander.controls)
    slots = {h: np.array([i for i, c in enumerate(controls) if c.startswith(h)],
                         dtype=np.intp) for h in HAND_NAMES}
    if not len(slots["le"]) or not len(slots["ri"]):
        raise ConfigError("the map does not read both gloves", file=str(map_file),
                          key="controls", value=controls,
                          allowed="controls of both hands (ri... and le...), e.g. "
                          "config/maps/default_two_gloves.toml")
    sag = SagGrid.load(Path(grid_file) if grid_file else _resolve(
        base, loop.sag_grid, default_grid_path(), rig_file=rig_path, key="loop.sag_grid"))
    shared = SharedControls(expander.control_means_deg)
    sides: dict[str, RigParts] = {}
    orientations: dict[str, SideOrientation] = {}
    for h, gpath in (("ri", right_glove), ("le", left_glove)):
        side = hand_rig(rig, h)
        cfg = load_glove_config(gpath)
        pipeline = PosePipeline(
            expander, sag, [s.joint for s in side.servos],
            servo_limits_deg=np.array([[s.min_deg, s.max_deg] for s in side.servos]),
            limits=limits, slew_deg_s=loop.slew_deg_s, sag_gain=rig.effective_sag_gain,
            left_hand="map", control_means_deg=expander.control_means_deg,
            left_forearm_deg=loop.left_forearm_deg, glove_hand="le" if h == "le" else "ri",
            right_forearm_deg=loop.left_forearm_deg)
        names = _glove_names(tuple(c.curve for c in cfg.channels),
                             [controls[i] for i in slots[h]])
        glove_controls = GloveControls.from_config(cfg, names)
        orientation = SideOrientation(ForearmAngles(cfg, hand="le" if h == "le" else "ri"),
                                      h, shared)
        orientations[h] = orientation
        sides[h] = RigParts(side, rig_path, cfg, expander, sag, pipeline,
                            SideControls(glove_controls, shared, slots[h]), orientation,
                            gpath, hand=h, map_file=map_file)
    orientations["ri"].other = sides["le"].pipeline
    orientations["le"].other = sides["ri"].pipeline
    return SessionParts(rig, rig_path, (sides["ri"], sides["le"]), map_file, shared)
