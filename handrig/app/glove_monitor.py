"""What a glove sends, in words: the state behind ``handrig glove monitor``.

:class:`GloveMonitor` is handed each :class:`~handrig.devices.glove.GloveSample` and the
source's :class:`~handrig.devices.glove.GloveStats`; it keeps, per raw channel, the latest
reading and the lowest and highest seen, the calibrated degrees of the glove
config, the forearm's inclination and rotation, the frame rate over the last
second, and the firmware's status flags. :meth:`GloveMonitor.render` turns that
into text lines (a bar per channel), the same on a terminal and in a log.
State is bounded: a ring of arrival times, one row per channel.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from firmware_protocol.glove import FLAG_IMU_ABSENT, FLAG_SENSOR_RAIL
from handrig.app.parts import ForearmAngles
from handrig.devices.glove import GloveSample, GloveStats
from handrig.devices.glove_calibration import GloveCalibration, GloveConfig
from handrig.devices.glove_status import channel_label, pinned_channels, status_names

BAR_WIDTH = 32
RATE_WINDOW_S = 1.0
MAX_RATE_SAMPLES = 4096
"""Arrival times kept for the frame rate (over 2 kHz for a one-second window)."""


@dataclass
class ChannelRange:
    """One raw channel: the latest reading and the extremes seen."""

    latest: float = 0.0
    low: float = np.inf
    high: float = -np.inf

    def see(self, value: float) -> None:
        self.latest = value
        self.low = min(self.low, value)
        self.high = max(self.high, value)


class GloveMonitor:
    """Accumulates samples of one glove (see the module docstring)."""

    def __init__(self, cfg: GloveConfig) -> None:
        self.cfg = cfg
        self.calibration = GloveCalibration.from_config(cfg)
        self.angles = ForearmAngles(cfg)
        self.names: dict[int, str] = {}
        for ch in cfg.channels:
            self.names.setdefault(ch.raw_index(), ch.curve)
        self.channels: list[ChannelRange] = []
        self.degrees = np.zeros(len(self.calibration))
        self.forearm_deg = (cfg.forearm.inclination_deg, cfg.forearm.rotation_deg)
        self.imu_seen = False
        self.status = 0
        self.buttons = 0
        self.samples = 0
        self.short_samples = 0
        self._arrivals: deque[tuple[float, int]] = deque(maxlen=MAX_RATE_SAMPLES)
        self.events: deque[str] = deque(maxlen=8)

    def add(self, sample: GloveSample) -> None:
        """Take one sample."""
        raw = sample.raw
        while len(self.channels) < len(raw):
            self.channels.append(ChannelRange())
        for rng, v in zip(self.channels, raw, strict=False):
            rng.see(float(v))
        if len(raw) > max(self.names, default=-1):
            self.degrees = self.calibration.calibrate(raw)
        else:
            self.short_samples += 1
        self.forearm_deg = self.angles(sample)
        self.imu_seen = self.imu_seen or sample.quat is not None
        self.status = sample.status
        self.buttons = sample.buttons
        self.samples += 1
        self._arrivals.append((sample.host_time_s, sample.count))

    def note(self, event: str) -> None:
        """An event of the source (port gone, flags changed) to show."""
        self.events.append(event)

    def rate_hz(self, now_s: float) -> float:
        """Frames per second over the last :data:`RATE_WINDOW_S`."""
        recent = [a for a in self._arrivals if now_s - a[0] <= RATE_WINDOW_S]
        if len(recent) < 2:
            return 0.0
        # the source's running count: frames the monitor never saw (superseded) count too
        return (recent[-1][1] - recent[0][1]) / max(recent[-1][0] - recent[0][0], 1e-9)

    def render(self, stats: GloveStats, now_s: float) -> list[str]:
        """The monitor's text, one line per item."""
        lines = [f"glove: {stats.frames_ok} frames, {self.rate_hz(now_s):.1f} Hz, "
                 f"{stats.crc_errors} CRC errors, {stats.decode_errors} other errors, "
                 f"{stats.frames_lost} frames lost"]
        full = 4095.0 if all(c.high <= 4095 for c in self.channels) else 65535.0
        for i, c in enumerate(self.channels):
            lines.append(f"  {channel_label(i, [self.names.get(k, '') for k in range(i + 1)]):<28}"
                         f" {_bar(c, full)} {c.latest:6.0f}  min {c.low:6.0f}  max {c.high:6.0f}")
        for ch, deg in zip(self.cfg.channels, self.degrees, strict=False):
            lines.append(f"  {ch.curve:<14} {deg:7.1f} deg  (open {ch.open_deg:g} at "
                         f"{ch.raw_open:g}, closed {ch.closed_deg:g} at {ch.raw_closed:g})")
        incl, rot = self.forearm_deg
        from_imu = self.imu_seen and not self.status & FLAG_IMU_ABSENT
        source = "IMU" if from_imu else "[forearm] of the config"
        lines.append(f"  forearm inclination {incl:6.1f} deg, rotation {rot:6.1f} deg ({source})")
        flags = status_names(self.status) or ["ok"]
        lines.append(f"  firmware flags: {', '.join(flags)}; buttons 0b{self.buttons:08b}")
        pinned = pinned_channels([c.latest for c in self.channels])
        if self.status & FLAG_SENSOR_RAIL and pinned:
            names = [self.names.get(k, "") for k in range(len(self.channels))]
            lines.append("  pinned: " + ", ".join(f"{channel_label(i, names)} at {rail}"
                                                  for i, rail in pinned))
        if self.short_samples:
            lines.append(f"  {self.short_samples} frames had fewer channels than the config reads")
        if stats.failure:
            lines.append(f"  port: {stats.failure}")
        lines.extend(f"  event: {e}" for e in self.events)
        return lines


def _bar(c: ChannelRange, full: float) -> str:
    """``[####....|..]``: the reading as a fill, the lowest and highest seen as ``|``."""
    def cell(v: float) -> int:
        return int(min(max(v / full, 0.0), 1.0) * (BAR_WIDTH - 1))

    cells = ["#" if k <= cell(c.latest) else "." for k in range(BAR_WIDTH)]
    for v in (c.low, c.high):
        if np.isfinite(v):
            cells[cell(v)] = "|"
    return "[" + "".join(cells) + "]"
