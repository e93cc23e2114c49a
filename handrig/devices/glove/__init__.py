"""Glove sources: where the realtime loop gets raw glove samples.

* :mod:`~handrig.devices.glove.source`: the abstract device :class:`GloveSource`,
  :class:`GloveSample` and :class:`GloveStats`;
* :mod:`~handrig.devices.glove.serial_glove`: :class:`SerialGlove`, a serial port
  (or pty) in the handrig frame format or the OpenGloves alpha line format;
* :mod:`~handrig.devices.glove.replay`: :class:`ReplayGlove`, a
  :class:`~handrig.devices.glove_recording.GloveRecording` played against the
  injected clock (no thread, deterministic with a FakeClock).
"""

from handrig.devices.glove.replay import DUE_TOLERANCE_S, ReplayGlove
from handrig.devices.glove.serial_glove import LOCK_FRAMES, GloveFormat, SerialGlove
from handrig.devices.glove.source import (
    BEHIND_KEPT,
    MAX_EVENTS,
    FloatArray,
    GloveSample,
    GloveSource,
    GloveStats,
)

__all__ = [
    "BEHIND_KEPT", "DUE_TOLERANCE_S", "LOCK_FRAMES", "MAX_EVENTS", "FloatArray", "GloveFormat",
    "GloveSample", "GloveSource", "GloveStats", "ReplayGlove", "SerialGlove",
]
