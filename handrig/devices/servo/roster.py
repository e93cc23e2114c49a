"""The servos of one rig as the driver sees them: IDs, names, limits and unit conversions.

Arrays are in rig order (``RigConfig.servos``). Joint degrees become ticks as
``zero_ticks + deg * ticks_per_deg``, where ``ticks_per_deg`` carries the
direction and gear ratio (4096 ticks per servo turn).
"""

from __future__ import annotations

import numpy as np

from handrig.config.rig import RigConfig
from handrig.devices.servo.models import (
    MODEL_NUMBERS,
    RETURN_DELAY_MAX_US,
    check_rig,
    servo_model,
    servo_settings_for,
)
from handrig.devices.servo.positions import POSITION_TICKS_MAX, TICKS_PER_DEG
from handrig.devices.servo.registers import CURRENT_MA_PER_UNIT, VELOCITY_DPS_PER_UNIT
from handrig.errors import DeviceError


class Roster:
    """IDs, joint names and calibration of the servos of ``rig`` on ``port``."""

    def __init__(self, rig: RigConfig, port: str, baud: int) -> None:
        if not rig.servos:
            raise DeviceError("the rig config lists no servos: add [[servos]] to config/rig.toml")
        check_rig(rig)  # the servos it names are ones this driver knows, at bauds they take
        servos = rig.servos
        self.rig = rig
        self.port = port
        self.baud = baud
        self.n = len(servos)
        self.ids: tuple[int, ...] = tuple(s.id for s in servos)
        self.ids_bytes = bytes(self.ids)
        self.names: tuple[str, ...] = tuple(s.joint for s in servos)
        self.index_of_id = {s.id: i for i, s in enumerate(servos)}
        self.min_deg = np.array([s.min_deg for s in servos], np.float64)
        self.max_deg = np.array([s.max_deg for s in servos], np.float64)
        self.hold_deg = np.clip(0.0, self.min_deg, self.max_deg)
        self.expected_models = tuple(MODEL_NUMBERS[servo_model(s)] for s in servos)
        ticks_per_deg = np.array(
            [s.direction * s.gear_ratio * TICKS_PER_DEG for s in servos], np.float64)
        # the codec kernels' scale rows: zero ticks, ticks per joint degree, joint deg/s
        # per Present Velocity unit, mA per Present Current unit
        self.scale = np.stack([
            np.array([s.zero_ticks for s in servos], np.float64),
            ticks_per_deg,
            VELOCITY_DPS_PER_UNIT * TICKS_PER_DEG / ticks_per_deg,
            np.array([CURRENT_MA_PER_UNIT.get(m, 1.0) for m in self.expected_models]),
        ])
        self.zero_ticks, self.ticks_per_deg = self.scale[0], self.scale[1]
        self.absent = np.zeros(self.n, bool)
        """Servos that did not answer at start-up, left out for the run (commissioning
        sets it when ``[silence] action`` is ``"continue"``): not commissioned, never
        sent a goal or torque."""
        # the Return Delay Time commissioning gives each servo
        self.return_delay_us = np.array(
            [servo_settings_for(rig, s.id).return_delay_us for s in servos], np.int64)

    def latest_reply_delay_s(self, indices: np.ndarray) -> float:
        """The longest a servo of ``indices`` may wait before its reply (its Return Delay
        Time): the one commissioning set, or the protocol's longest for a servo left out
        at start-up (not commissioned yet: it may still have the factory's 500 us)."""
        delay_us = np.where(self.absent[indices], RETURN_DELAY_MAX_US,
                            self.return_delay_us[indices])
        return float(delay_us.max(initial=0)) * 1e-6

    def describe(self, index: int) -> str:
        """``"servo 7 (riRingPIPy)"`` for the servo at rig index ``index``."""
        return f"servo {self.ids[index]} ({self.names[index]})"

    def where(self) -> str:
        return f"on {self.port} at {self.baud} baud"

    def ticks(self, index: int, deg: float) -> int:
        """Goal Position ticks of servo ``index`` for joint angle ``deg`` (0..4095)."""
        t = round(self.zero_ticks[index] + deg * self.ticks_per_deg[index])
        return int(min(max(t, 0), POSITION_TICKS_MAX))
