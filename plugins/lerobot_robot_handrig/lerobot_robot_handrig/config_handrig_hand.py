"""The robot configs (LeRobot's config dataclasses): one per preset, one base."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.robots.config import RobotConfig


@dataclass(kw_only=True)
class HandrigHandConfig(RobotConfig):
    """``port``: ``sim`` (the emulated servos and the robot's MuJoCo model), the servo
    adapter's serial port, or empty for the rig file's ``[bus] port``. ``rig``: a robot
    rig file to use instead of the preset's (your ``handrig calibrate servos`` output);
    its limits, rate, slew limit and ``[silence]``/``[heat]`` policies are the robot's."""

    port: str = "sim"
    rig: str = ""

    @property
    def preset(self) -> str:
        raise NotImplementedError


@RobotConfig.register_subclass("handrig_leap")
@dataclass(kw_only=True)
class HandrigLeapConfig(HandrigHandConfig):
    """The LEAP hand (16 Dynamixel servos), handrig's ``leap`` preset."""

    @property
    def preset(self) -> str:
        return "leap"


@RobotConfig.register_subclass("handrig_orca")
@dataclass(kw_only=True)
class HandrigOrcaConfig(HandrigHandConfig):
    """The ORCA hand (17 Dynamixel servos), handrig's ``orca`` preset."""

    @property
    def preset(self) -> str:
        return "orca"
