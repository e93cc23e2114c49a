"""What the loop does about servos that heat up: the ``[heat]`` tiers.

The bus reports facts: each read carries the servos' temperatures as last read
(the driver reads them about once a second, between state reads), NaN until
the first. The decisions are made here, the same for every bus built to
:class:`~handrig.devices.servo.bus.ServoBus`: at ``warn_c`` a servo is named in a
warning; at ``act_c`` its effort is capped (:meth:`ServoBus.limit_effort`, Goal
PWM at ``relief_pwm_pct`` % of its PWM Limit: the joint gives way to the load
toward where it needs less, and the motor current and heat fall with it), the
others go on; at ``action_c`` comes the action: ``"continue"`` (keep the cap and
go on), ``"relax"`` (:attr:`HeatWatch.relax_reason` asks the mode machine to ease
every servo to the relaxed pose until the servo cools below ``action_c``) or
``"stop"`` (ServoFault: the run ends, torque off). Each tier ends
:data:`~handrig.config.rig.HEAT_HYSTERESIS_C` below its threshold, and says so.
A servo the bus rebooted has lost its cap (Goal PWM is RAM): it gets it again. A
servo given its full effort back is listed in :attr:`HeatWatch.uncapped` for the loop
to ease its joint back to its goals from where it gave way, never in one jump.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from handrig.config.rig import HEAT_HYSTERESIS_C, HeatConfig
from handrig.devices.servo.bus import ServoBus, ServoState
from handrig.errors import ServoFault

EVENTS_KEPT = 64
CHECK_EVERY_S = 0.25  # temperatures come about once a second: look four times as often
COOL, WARM, HOT, ACTED = 0, 1, 2, 3  # tiers of a servo's temperature


class HeatWatch:
    """The ``[heat]`` tiers for the servos of ``bus`` (see the module docstring).

    :meth:`update` gets each read's state. Counters: ``warnings`` (servos warned
    about), ``reliefs`` (effort caps put in place), ``actions``; ``max_c`` is the
    hottest reading per servo; :meth:`drain_events` takes what was said.
    """

    def __init__(self, bus: ServoBus, config: HeatConfig) -> None:
        self.bus = bus
        self.config = config
        n = bus.n_servos
        self.n = n
        self.tier = np.zeros(n, np.int8)
        self.capped = np.zeros(n, bool)
        self.max_c = np.full(n, np.nan)
        self.relax_reason: str | None = None
        self.events: deque[str] = deque(maxlen=EVENTS_KEPT)
        self.warnings = 0
        self.reliefs = 0
        self.actions = 0
        self._reboots = np.zeros(n, np.int64)
        self.uncapped: list[int] = []  # servos given full effort back, for the loop to ease
        self._seen = np.full(n, np.nan)  # the temperatures at the last update
        self._next_check_s = -np.inf
        thresholds = (config.warn_c, config.act_c, config.action_c)
        self._up = np.array(thresholds)
        self._down = self._up - HEAT_HYSTERESIS_C

    def update(self, state: ServoState) -> None:
        """After a read: raise and lower tiers and act on them (looking at the
        temperatures every :data:`CHECK_EVERY_S` of read time). ServoFault when a servo
        reaches ``action_c`` and the action is ``"stop"``."""
        self._recap_rebooted(state)
        if state.timestamp_s < self._next_check_s:
            return  # the cycle's path allocates nothing between checks
        self._next_check_s = state.timestamp_s + CHECK_EVERY_S
        temps = np.asarray(state.temperatures_c, dtype=np.float64)
        if np.array_equal(temps, self._seen, equal_nan=True):
            return
        self._seen[:] = temps
        np.fmax(self.max_c, temps, out=self.max_c)
        known = np.isfinite(temps)
        if not known.any():
            return
        t = np.where(known, temps, -np.inf)
        # the tier a servo is in: up when it reaches a threshold, down only past hysteresis
        up = (t[:, None] >= self._up[None, :]).sum(axis=1).astype(np.int8)
        stay = (t[:, None] > self._down[None, :]).sum(axis=1).astype(np.int8)
        new = np.where(up > self.tier, up, np.minimum(self.tier, stay)).astype(np.int8)
        new[~known] = self.tier[~known]
        changed = np.flatnonzero(new != self.tier)
        for i in changed:
            self._move(int(i), int(self.tier[i]), int(new[i]), float(temps[i]))

    def _move(self, i: int, old: int, new: int, temp_c: float) -> None:
        cfg = self.config
        name = self.bus.describe(i)
        self.tier[i] = new
        if new > old:
            if old < WARM <= new:
                self.warnings += 1
                self._say(f"{name} is at {temp_c:.0f} C, warming toward its limit "
                          f"([heat] warn_c {cfg.warn_c:g} C): check its load")
            if old < HOT <= new:
                self._relieve(i, temp_c)
            if old < ACTED <= new:
                self._act(i, temp_c)
            return
        if old >= ACTED > new:
            self._say(f"{name} cooled to {temp_c:.0f} C, below [heat] action_c "
                      f"{cfg.action_c:g} C")
            if not (self.tier >= ACTED).any():
                self.relax_reason = None
        if old >= HOT > new and self.capped[i] and self.bus.limit_effort(i, 1.0):
            self.capped[i] = False
            self.uncapped.append(i)
            self._say(f"{name} cooled to {temp_c:.0f} C: its full effort is back, easing "
                      "its joint back to its goals from where it is")
        if old >= WARM > new:
            self._say(f"{name} cooled to {temp_c:.0f} C, below [heat] warn_c {cfg.warn_c:g} C")

    def _relieve(self, i: int, temp_c: float) -> None:
        cfg = self.config
        name = self.bus.describe(i)
        fraction = cfg.relief_pwm_pct / 100.0
        if self.bus.limit_effort(i, fraction):
            self.capped[i] = True
            self.reliefs += 1
            self._say(f"{name} is at {temp_c:.0f} C ([heat] act_c {cfg.act_c:g} C): its "
                      f"effort is capped at {cfg.relief_pwm_pct:g} % so its joint gives way "
                      "to the load and it cools; the others go on")
        else:
            self._say(f"{name} is at {temp_c:.0f} C ([heat] act_c {cfg.act_c:g} C) and its "
                      "effort could not be capped: lighten its load")

    def _act(self, i: int, temp_c: float) -> None:
        cfg = self.config
        name = self.bus.describe(i)
        self.actions += 1
        what = f"{name} is at {temp_c:.0f} C ([heat] action_c {cfg.action_c:g} C)"
        if cfg.action == "stop":
            raise ServoFault(f"{what} {self.bus.where()}; [heat] action is stop: ending the "
                             "run before the servo's own limit turns it off")
        if cfg.action == "relax":
            self.relax_reason = what
            self._say(f"{what}: relaxing every servo until it cools ([heat] action)")
        else:
            self._say(f"{what}: going on with its effort capped ([heat] action continue)")

    def _recap_rebooted(self, state: ServoState) -> None:
        """A rebooted servo's Goal PWM is back at full: cap it again if it was capped."""
        reboots = state.stats.reboots
        if len(reboots) != self.n or not (reboots > self._reboots).any():
            return
        new = np.flatnonzero(reboots > self._reboots)
        self._reboots[:] = reboots
        fraction = self.config.relief_pwm_pct / 100.0
        for i in new:
            if self.capped[i] and self.bus.limit_effort(int(i), fraction):
                self._say(f"{self.bus.describe(int(i))} was rebooted: its effort is capped "
                          f"at {self.config.relief_pwm_pct:g} % again")

    def hottest(self) -> str:
        """``"servo 19 (riWristFlexion) 41 C"``: the hottest reading of the run, or ``""``."""
        if not np.isfinite(self.max_c).any():
            return ""
        i = int(np.nanargmax(self.max_c))
        return f"{self.bus.describe(i)} {self.max_c[i]:.0f} C"

    def _say(self, text: str) -> None:
        self.events.append(text)

    def drain_events(self) -> list[str]:
        """What happened since the last call, oldest first."""
        out = list(self.events)
        self.events.clear()
        return out
