"""A robot-hand preset as a LeRobot robot (``handrig_leap``, ``handrig_orca``): handrig's
side of it, one class over the presets.

:class:`HandRobot` is :class:`~handrig.app.robot_api.RobotHand` in LeRobot's words:
:meth:`~HandRobot.connect` commissions the servos through handrig's driver (torque on
behind the safe-torque checks, the limits, slew limit, watchdog, ``[silence]`` and
``[heat]`` policies of the rig file) and starts the show's realtime loop in a thread;
:meth:`~HandRobot.send` sets the target that loop follows at the rig's rate
(``[loop] rate_hz``), no bus write of its own; :meth:`~HandRobot.observation` is the
loop's newest read of the servos (with the time it ended);
:meth:`~HandRobot.disconnect` eases to the relaxed pose and turns torque off. Joint
values are degrees in the robot model's convention, named ``<joint>.pos`` (currents
``<joint>.current``, mA, where the loop reads them).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from handrig.app.robot_api import Reading, RobotHand
from handrig.errors import ConfigError, HandrigError

POS = ".pos"
CURRENT = ".current"


class HandRobot:
    """``rig``: a preset (``"leap"``, ``"orca"``) or a robot rig file; ``port``: ``"sim"``
    (the emulated bus and the robot's MuJoCo model), a serial port, or None for the
    rig file's ``[bus] port``."""

    def __init__(self, rig: str, port: str | None) -> None:
        self.hand = RobotHand(rig, port=port)
        self.joint_names = self.hand.joint_names
        self.reads_current = self.hand.reads_current
        self.observed: Reading | None = None
        """The read the last :meth:`observation` gave (None before one)."""
        self._open = False

    @property
    def action_names(self) -> tuple[str, ...]:
        return tuple(j + POS for j in self.joint_names)

    @property
    def observation_names(self) -> tuple[str, ...]:
        currents = tuple(j + CURRENT for j in self.joint_names) if self.reads_current else ()
        return (*self.action_names, *currents)

    @property
    def is_connected(self) -> bool:
        return self._open

    def connect(self) -> None:
        if self._open:
            raise HandrigError("the robot hand is already connected")
        self.hand.__enter__()
        self._open = True

    def send(self, action: Mapping[str, float]) -> dict[str, float]:
        """Have the loop follow these ``<joint>.pos`` targets (joints not named keep
        theirs; the first action names them all); returns the targets the loop will
        follow, clipped to the limits, by the same names."""
        joints: dict[str, float] = {}
        for key, value in action.items():
            if not key.endswith(POS):
                raise ConfigError("not a joint target of this robot: nothing was sent",
                                  key=key, allowed=", ".join(self.action_names))
            joints[key.removesuffix(POS)] = value
        targets = self.hand.command_joints(joints)
        return {name: float(t) for name, t in zip(self.action_names, targets, strict=True)}

    def observation(self) -> dict[str, float]:
        """The loop's newest read of the servos (:meth:`RobotHand.reading`, not a
        snapshot, not an average): positions (NaN: no fresh reading) and currents;
        :attr:`observed_at_s` is when that read ended."""
        reading = self.hand.reading()
        self.observed = reading
        nan = dict.fromkeys(self.joint_names, math.nan)
        out = {j + POS: v for j, v in (reading.positions_deg if reading else nan).items()}
        if self.reads_current:
            out.update({j + CURRENT: v
                        for j, v in (reading.currents_ma if reading else nan).items()})
        return out

    @property
    def observed_at_s(self) -> float:
        """When the read the last :meth:`observation` gave ended, on the loop's clock
        (``time.perf_counter``); NaN before one."""
        return self.observed.t_s if self.observed is not None else math.nan

    def goals(self) -> dict[str, float]:
        """The goals the loop last sent to the servos, by ``<joint>.pos``."""
        return {j + POS: v for j, v in self.hand.goals_deg().items()}

    def disconnect(self) -> None:
        """Ease to the relaxed pose, torque off, bus closed. Idempotent."""
        if self._open:
            self._open = False
            self.hand.close()

    @property
    def torque_off_confirmed(self) -> bool | None:
        return self.hand.torque_off_confirmed

