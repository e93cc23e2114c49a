"""The ``handrig_glove`` teleoperator's config (LeRobot's config dataclass)."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.teleoperators.config import TeleoperatorConfig


@TeleoperatorConfig.register_subclass("handrig_glove")
@dataclass(kw_only=True)
class HandrigGloveConfig(TeleoperatorConfig):
    """``port``: ``sim`` (the emulated glove streaming ``recording``, the shipped demo by
    default), ``replay:FILE`` (a glove take), a serial port or ``opengloves:PORT``.
    ``robot``: a robot preset (``leap``, ``orca``) or robot rig file: the action is then
    that robot's joint targets through its retarget table (pair it with
    ``--robot.type=handrig_<preset>``); empty: the 50 human curves. ``glove_config``: the
    glove file (empty: yours from ``handrig calibrate glove``, else the shipped one).
    ``fps``: the recording's ``--dataset.fps`` (or ``--fps`` of lerobot-teleoperate):
    each frame's action is then the pose at that frame's time; 0: the newest pose when
    asked. ``max_lag_s``: how far the caller's loop may fall behind its frame grid
    before it is re-anchored (and a warning says so)."""

    port: str = "sim"
    robot: str = ""
    glove_config: str = ""
    recording: str = ""
    fps: float = 0.0
    max_lag_s: float = 0.1
