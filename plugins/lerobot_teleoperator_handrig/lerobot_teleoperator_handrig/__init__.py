"""handrig's glove as a LeRobot teleoperator: ``--teleop.type=handrig_glove``.

LeRobot imports this package by its distribution name (its third-party plugin
discovery); importing it registers :class:`HandrigGloveConfig`. The logic lives in
:mod:`handrig.app.lerobot.teleop`; docs/lerobot.md says how to use it.
"""

from .config_handrig_glove import HandrigGloveConfig
from .handrig_glove import HandrigGlove

__all__ = ["HandrigGlove", "HandrigGloveConfig"]
