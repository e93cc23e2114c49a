"""Admission: a servo left out at connect that answers later is brought into the run.

Under ``[silence] action = "continue"`` a servo that does not answer at connect is
left out (:mod:`~handrig.devices.servo.commissioning`): no goal, no torque. The
reader still asks it, last in the chain; when it answers, the loop asks the bus to
admit it (:meth:`handrig.devices.servo.bus.ServoBus.admit`). It is pinged and its
model checked, commissioned as at connect (Status Return Level, the rig's settings
read back, Bus Watchdog cleared, a pending hardware error handled), and, with torque
on, given its present position (clamped into its limits) as goal before torque,
then the Bus Watchdogs are re-armed. Only then do the goal Sync Writes carry it,
starting from where it is: the loop eases it to its goals at the slew limit. A servo
resting outside its limits by more than torque-on tolerates is not admitted (it
would jump into them); neither is one of another model. About 15 transactions: a
few cycles late once, like a reboot.
"""

from __future__ import annotations

import contextlib

import numpy as np

from handrig.devices.servo.bus import BusStats
from handrig.devices.servo.codec import INST_PING, build_instruction
from handrig.devices.servo.commissioning import Commissioner
from handrig.devices.servo.faults import FaultHandler
from handrig.devices.servo.goals import GoalWriter
from handrig.devices.servo.link import Link
from handrig.devices.servo.models import MODEL_NAMES, servo_model
from handrig.devices.servo.registers import Reg
from handrig.devices.servo.roster import Roster
from handrig.devices.servo.torque import TORQUE_ON_SLACK_DEG
from handrig.errors import DeviceError

PING_ATTEMPTS = 2


class Admission:
    """Admits the servos of ``roster`` left out at connect (see the module docstring)."""

    def __init__(self, roster: Roster, link: Link, writer: GoalWriter,
                 commissioner: Commissioner, faults: FaultHandler, stats: BusStats) -> None:
        self.roster = roster
        self.link = link
        self.writer = writer
        self.commissioner = commissioner
        self.faults = faults
        self.stats = stats

    def admit(self, index: int) -> tuple[float | None, str]:
        """Admit servo ``index``: (its goal, joint degrees, or None if it stays out; what
        was done or why not)."""
        r = self.roster
        who = r.describe(index)
        if not r.absent[index]:
            return None, f"{who} is not left out"
        sid = r.ids[index]
        status = self.link.transact(build_instruction(sid, INST_PING), sid,
                                    attempts=PING_ATTEMPTS, n_params=3)
        if status is None or len(status.params) < 3:
            return None, f"{who} answered a read but not a ping {r.where()}: still left out"
        model = status.params[0] | status.params[1] << 8
        if model != r.expected_models[index]:
            return None, (f"{who} answers as model {model} ({MODEL_NAMES.get(model, 'unknown')}), "
                          f"the rig says {servo_model(r.rig.servos[index])}: left out for the run "
                          "(fix config/rig.toml or the servo)")
        self.commissioner.models[sid] = model
        self.commissioner.firmware[sid] = status.params[2]
        self.commissioner.configure(index)  # torque off, settings read back, watchdog 0
        ticks = self.link.read_register(index, Reg.PRESENT_POSITION)
        pos = float((ticks - r.zero_ticks[index]) / r.ticks_per_deg[index])
        low, high = float(r.min_deg[index]), float(r.max_deg[index])
        excess = max(low - pos, pos - high)
        if excess > TORQUE_ON_SLACK_DEG:
            return None, (f"{who} answers, resting at {pos:.1f} deg, outside its limits "
                          f"[{low:g}, {high:g}]: left out until it is moved into them "
                          "(torque there would jump it in)")
        goal = float(np.clip(pos, low, high))
        torque = self.faults.torque_on
        if torque:
            self.link.write_register(index, Reg.GOAL_POSITION, r.ticks(index, goal))
            try:
                self.link.write_register(index, Reg.TORQUE_ENABLE, 1)
            except DeviceError:
                self._torque_off(index)
                raise
        r.absent[index] = False
        self.writer.admit(index, goal)
        self.stats.admissions += 1
        if torque:
            self.faults.arm_watchdog(strict=False)
        how = (f"torque on where it is ({goal:.1f} deg), easing to its goals at the slew "
               "limit" if torque else "torque off, as every servo")
        return goal, f"{who} answered {r.where()}: commissioned, {how}"

    def restore(self, index: int) -> str:
        """Servo ``index`` restarted on its own with torque on in the run (a power loss):
        commissioned again (its RAM settings are gone), then torque on where it is,
        clamped into its limits, and remembered as its last goal (the loop eases it back
        from there). Returns what was done; DeviceError if it could not be."""
        r = self.roster
        self.commissioner.configure(index)
        ticks = self.link.read_register(index, Reg.PRESENT_POSITION)
        pos = float((ticks - r.zero_ticks[index]) / r.ticks_per_deg[index])
        goal = float(np.clip(pos, r.min_deg[index], r.max_deg[index]))
        self.link.write_register(index, Reg.GOAL_POSITION, r.ticks(index, goal))
        self.link.write_register(index, Reg.TORQUE_ENABLE, 1)
        remembered = self.writer.last_goal_deg.copy()
        remembered[index] = goal
        self.writer.remember(remembered)
        return (f"commissioned again, torque on where it is ({goal:.1f} deg), easing back to "
                "its goals")

    def _torque_off(self, index: int) -> None:
        """Best effort after a failed admission: the servo stays out, torque off."""
        with contextlib.suppress(DeviceError):  # the broadcast at exit reaches it too
            self.link.write_register(index, Reg.TORQUE_ENABLE, 0)
