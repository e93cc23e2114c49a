"""handrig's robot-hand presets as LeRobot robots: ``--robot.type=handrig_leap`` and
``--robot.type=handrig_orca``.

LeRobot imports this package by its distribution name (its third-party plugin
discovery); importing it registers the configs. One robot class serves every preset
(:class:`HandrigHand`): LeRobot looks a config's device class up by its name less
``Config``, so ``HandrigLeap`` and ``HandrigOrca`` are that one class under the names it
looks for. The logic lives in :mod:`handrig.app.lerobot.hand`; docs/lerobot.md says
how to use it.
"""

from .config_handrig_hand import HandrigHandConfig, HandrigLeapConfig, HandrigOrcaConfig
from .handrig_hand import HandrigHand

HandrigLeap = HandrigHand
HandrigOrca = HandrigHand

__all__ = ["HandrigHand", "HandrigHandConfig", "HandrigLeap", "HandrigLeapConfig",
           "HandrigOrca", "HandrigOrcaConfig"]
