"""The ``handrig_glove`` teleoperator: LeRobot's Teleoperator over
:class:`handrig.app.lerobot.teleop.GloveTeleop`."""

from __future__ import annotations

from typing import Any

from lerobot.teleoperators.teleoperator import Teleoperator

from handrig.app.lerobot.teleop import GloveTeleop

from .config_handrig_glove import HandrigGloveConfig


class HandrigGlove(Teleoperator):
    """The glove through handrig's pipeline (calibration, map, sag, limits, a robot's
    retarget); :meth:`get_action` returns the pose at the caller's frame time without
    touching the port (the glove runs in a thread of its own)."""

    config_class = HandrigGloveConfig
    name = "handrig_glove"

    def __init__(self, config: HandrigGloveConfig) -> None:
        super().__init__(config)
        self.config = config
        self.glove = GloveTeleop(port=config.port, robot=config.robot or None,
                                 glove_config=config.glove_config or None,
                                 recording=config.recording or None,
                                 fps=config.fps or None, max_lag_s=config.max_lag_s)

    @property
    def action_features(self) -> dict[str, type]:
        return dict.fromkeys(self.glove.names, float)

    @property
    def feedback_features(self) -> dict[str, type]:
        return {}

    @property
    def is_connected(self) -> bool:
        return self.glove.is_connected

    @property
    def is_calibrated(self) -> bool:
        """Whether handrig's glove file is a calibration (``handrig calibrate glove``);
        LeRobot keeps no second calibration of the glove."""
        return self.glove.is_calibrated

    def connect(self, calibrate: bool = True) -> None:
        if calibrate and not self.is_calibrated:
            self.calibrate()
        self.glove.connect()

    def calibrate(self) -> None:
        """Runs ``handrig calibrate glove`` on this port (its prompts write handrig's
        glove file)."""
        self.glove.calibrate()

    def configure(self) -> None:
        """Nothing to set on the glove: its settings are the glove file's."""

    def get_action(self) -> dict[str, Any]:
        return dict(self.glove.action())

    def send_feedback(self, feedback: dict[str, Any]) -> None:
        """The glove has no actuators: feedback is not supported."""
        raise NotImplementedError("the handrig glove takes no feedback")

    def disconnect(self) -> None:
        self.glove.disconnect()
