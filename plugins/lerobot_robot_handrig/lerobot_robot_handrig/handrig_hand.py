"""The robot: LeRobot's Robot over :class:`handrig.app.lerobot.hand.HandRobot`, one
class for every preset."""

from __future__ import annotations

import logging
from typing import Any

from lerobot.robots.robot import Robot

from handrig.app.lerobot.hand import HandRobot

from .config_handrig_hand import HandrigHandConfig

log = logging.getLogger(__name__)


class HandrigHand(Robot):
    """A robot-hand preset driven by handrig's realtime loop in a thread of its own:
    :meth:`send_action` sets the target the loop follows at the rig's rate (no bus write
    per call), :meth:`get_observation` is the loop's newest read. Joint values are
    degrees (the robot model's convention), ``<joint>.pos``; ``<joint>.current`` (mA)
    where the loop reads currents."""

    config_class = HandrigHandConfig
    name = "handrig_hand"

    def __init__(self, config: HandrigHandConfig) -> None:
        self.name = config.type  # handrig_leap, handrig_orca: the dataset's robot_type
        super().__init__(config)
        self.config = config
        self.cameras: dict[str, Any] = {}  # LeRobot's record reads it; a hand has none
        self.hand = HandRobot(config.rig or config.preset, config.port or None)

    @property
    def observation_features(self) -> dict[str, type]:
        return dict.fromkeys(self.hand.observation_names, float)

    @property
    def action_features(self) -> dict[str, type]:
        return dict.fromkeys(self.hand.action_names, float)

    @property
    def is_connected(self) -> bool:
        return self.hand.is_connected

    @property
    def is_calibrated(self) -> bool:
        """The servos' calibration is the rig file's (``handrig calibrate servos``):
        LeRobot keeps no second one."""
        return True

    def connect(self, calibrate: bool = True) -> None:
        """Commission the servos through handrig's driver (torque on behind its checks)
        and start the realtime loop; the hand eases from where it is."""
        self.hand.connect()

    def calibrate(self) -> None:
        log.info("the servos' calibration is the rig file's: `handrig calibrate servos "
                 "--rig %s` writes it", self.config.rig or self.config.preset)

    def configure(self) -> None:
        """Nothing beyond the rig file: connect() commissions the servos from it."""

    def get_observation(self) -> dict[str, Any]:
        """The loop's newest read of the servos (not a snapshot, not an average); its
        time is :attr:`observation_time_s`."""
        return dict(self.hand.observation())

    @property
    def observation_time_s(self) -> float:
        """When the read the last :meth:`get_observation` gave ended (``time.perf_counter``,
        LeRobot's loop clock too); NaN before one."""
        return self.hand.observed_at_s

    def send_action(self, action: dict[str, Any]) -> dict[str, Any]:
        return dict(self.hand.send(action))

    def disconnect(self) -> None:
        self.hand.disconnect()
