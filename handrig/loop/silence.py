"""What the loop does about servos that stop answering: the ``[silence]`` tiers.

The bus reports facts: each read says which servos gave a valid reading and how
old each servo's last one is (:class:`~handrig.devices.servo.bus.ServoState`),
and whether the read was sent at all. The decisions are made here, the same for
every bus built to :class:`~handrig.devices.servo.bus.ServoBus`: after ``warn_s``
without a valid reading a servo is named in a warning; after ``hold_s`` its goal
is held where it was (goals still go out, so the Bus Watchdogs stay fed); after
``action_s`` comes the action: ``"continue"`` (the others keep following),
``"relax"`` (:attr:`SilenceWatch.relax_reason` asks the mode machine to ease to
the relaxed pose until it answers) or ``"stop"`` (DeviceTimeoutError: the run
ends, torque off). A servo that answers again is brought back to its goals at
the slew limit. A servo left out at connect (``ServoBus.left_out``) gets no tiers;
when it answers, the bus is asked to admit it (:meth:`ServoBus.admit`: commissioned,
torque on where it is) and it is eased from there to its goals at the slew limit,
as a servo that answers again; refused, it is asked again after ``ADMIT_RETRY_S``.

What is said names what was seen: which servos, for how long, whether the host
itself was late (the gaps between reads) and whether every servo went quiet at
once; hardware advice is given only when the host kept time and the others answer.
One silent servo costs that servo only, in words too: a read that asked several
servos and got no answer at all, while other reads answer, is the read's trouble
(the host, the emulator, the adapter), not each servo's: its servos are held as any
silent servo is (a goal held is safe), but they are not counted or named as silent
servos, and it is said once in the run, as is a host that made reads late; later
ones are counted (:meth:`SilenceWatch.counts`, the run's summary). Only when such a
read stays unanswered until ``action_s`` is it named and acted on.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from handrig.config.rig import SilenceConfig
from handrig.devices.servo.bus import ServoBus, ServoState
from handrig.errors import DeviceTimeoutError

FloatArray = NDArray[np.float64]

HOST_LATE_S = 0.02  # a read this much later than the usual gap: the host was late
GAP_WARM_UP = 16  # gaps between reads learnt before any is judged late
EVENTS_KEPT = 64
ADMIT_RETRY_S = 1.0  # a servo left out that answers but was not admitted: asked again
ANSWERING, WARNED, HELD, ACTED = 0, 1, 2, 3  # tiers of a silent servo
MISSED_MIN = 3  # reads in a row that asked a servo and got nothing, before it is silent


class SilenceWatch:
    """The ``[silence]`` tiers for the servos of ``bus`` (see the module docstring).

    :meth:`note_read` is told when each read starts (``late``: after its deadline);
    :meth:`update` gets each read's state; :meth:`steer` turns the goals the loop
    wants into the goals to send (held servos stay, released ones come back at
    ``slew_deg_s``). Counters: ``silences`` (servos warned about), ``held``,
    ``recoveries``, ``recovery_reads_max``; :meth:`drain_events` takes what was said.
    """

    def __init__(self, bus: ServoBus, config: SilenceConfig, slew_deg_s: float, *,
                 loop_goals: Callable[[FloatArray], FloatArray] | None = None) -> None:
        self.bus = bus
        # the bus's last goals as the loop's (a robot's gravity offsets taken off)
        self._loop_goals = loop_goals if loop_goals is not None else (lambda held: held)
        self.config = config
        self.slew_deg_s = float(slew_deg_s)
        n = bus.n_servos
        self.n = n
        self.tier = np.zeros(n, np.int8)
        self.holding = np.zeros(n, bool)
        self.releasing = np.zeros(n, bool)
        self.steering = False  # holding or releasing any servo
        self.active = False  # any servo past warn_s
        self.relax_reason: str | None = None
        self.events: deque[str] = deque(maxlen=EVENTS_KEPT)
        self.silences = 0
        self.held = 0
        self.recoveries = 0
        self.recovery_reads_max = 0
        self._reads = np.zeros(n, np.int64)  # reads while silent
        self._reboots = np.zeros(n, np.int64)  # the bus's reboots seen so far
        self._from = np.full(n, np.nan)  # where a rebooted servo eases back from
        self._goals = np.zeros(n, np.float64)
        self._step = np.zeros(n, np.float64)
        self._t_ref = np.nan  # the first read: nobody is silent since before it
        self._last_read_s = np.nan
        self._usual_gap_s = np.nan
        self._gaps_seen = 0
        self.late_s = 0.0  # the host's worst lateness within the last action_s
        self._late_at = -np.inf
        self._late_reads = 0  # reads that came after their deadline, same window
        self._left_out: np.ndarray | None = None  # the bus's, learnt at the first read
        self.waiting = True  # servos left out (or not yet known): every read is looked at
        self.admitted = 0  # servos left out at connect, admitted when they answered
        self._admit_after = np.full(n, -np.inf)
        self._admit_said = [""] * n
        # servos whose last read asked 2+ servos and had no answer at all (a read part
        # that went quiet as a whole, not each servo's cable)
        self._quiet_together = np.zeros(n, bool)
        # servos where the bus saw a reply stop (ServoState.stopped): their own silence;
        # the others of a read cut short went unanswered with them. None: the bus cannot
        # tell, and a read unanswered as a whole is what tells the read's trouble apart
        self._stopped: np.ndarray | None = None
        # servos a read left unanswered while others in it answered and the bus saw the
        # reply stop before them (cut off with a silent servo): not their own silence
        self._cut = np.zeros(n, bool)
        self._outage = np.zeros(n, bool)  # silent because their reads went unanswered whole
        self._missed = np.zeros(n, np.int64)  # reads since each servo was last heard
        self.read_outages = 0  # times a read's servos went past warn_s together
        self.host_late_episodes = 0  # warnings given while the host was late
        self._said_outage = False
        self._said_all_quiet = False
        self._said_host = False
        self.silent_by = np.zeros(n, np.int64)  # per servo: silences warned about
        self.held_by = np.zeros(n, np.int64)
        self.acted_by = np.zeros(n, np.int64)

    # ------------------------------------------------------------------ host timing
    def note_read(self, now: float, late: bool = False) -> None:
        """A read starts at ``now`` (``late``: the caller came after its deadline)."""
        if not np.isfinite(self._t_ref):
            self._t_ref = now
        gap = now - self._last_read_s
        self._last_read_s = now
        usual = self._usual_gap_s
        if not np.isfinite(gap):
            return
        if gap > self.config.action_s:
            # nobody was reading: silence counts from this read on
            self._t_ref = now
            self._gaps_seen = 0
            return
        self._gaps_seen += 1
        if self._gaps_seen <= GAP_WARM_UP or not np.isfinite(usual):
            self._usual_gap_s = gap if not np.isfinite(usual) else usual + 0.25 * (gap - usual)
            return
        lateness = gap - usual
        if now - self._late_at > self.config.action_s:
            self.late_s, self._late_reads = 0.0, 0
        if late:
            self._late_reads += 1
            self._late_at = now
        if lateness >= HOST_LATE_S and lateness >= self.late_s:
            self.late_s, self._late_at = lateness, now
        self._usual_gap_s = usual + 0.02 * (min(gap, 2.0 * usual) - usual)

    # ------------------------------------------------------------------ tiers
    def update(self, state: ServoState, now: float) -> None:
        """After a read: raise tiers, act on them, release servos that answer.
        DeviceTimeoutError when the action is ``"stop"``."""
        cfg = self.config
        self._note_reboots(state)
        missed = self._missed
        if state.sent:
            asked = (np.ones(self.n, bool) if state.asked is None
                     else np.asarray(state.asked, dtype=bool))
            answered = np.asarray(state.answered, dtype=bool)
            together = asked.sum() >= 2 and not bool(answered.any())
            self._quiet_together[asked] = together
            missed[asked & answered] = 0
            missed[asked & ~answered] += 1
            if state.stopped is not None:
                stopped = np.asarray(state.stopped, dtype=bool) & ~answered
                self._stopped = stopped
                self._cut[asked] = (bool(answered.any()) & ~answered & ~stopped)[asked]
            else:  # the bus cannot tell (a Sync Read, a whole read's short way)
                self._stopped = None
                self._cut[asked] = False
        else:  # the read could not be sent: nobody was heard
            missed += 1
        since_ref = now - self._t_ref if np.isfinite(self._t_ref) else 0.0
        silent_s = np.minimum(np.asarray(state.age_s, dtype=np.float64)
                              + (now - state.timestamp_s), since_ref)
        # a servo is silent when it has not been heard for warn_s and the last MISSED_MIN
        # reads that asked it got nothing from it: one the host did not ask for a while
        # (it stalled, or read the other parts) is not, nor one a silent servo before it
        # in a Fast Sync Read's chain cut off (the bus moves that one to the chain's end
        # after SILENT_AFTER reads)
        silent = (silent_s > cfg.warn_s) & (missed >= MISSED_MIN)
        if self._left_out is None:  # after connect: the servos left out are known
            self._left_out = np.zeros(self.n, bool)
            self._left_out[list(self.bus.left_out)] = True
        if self._left_out.any():  # named once at start-up, never sent a goal: no tiers
            self._admit(self._left_out, state, now)
            silent &= ~self._left_out
        self.waiting = bool(self._left_out.any())
        self._reads[silent] += 1
        if self._outage.any():  # (the usual read has none: no arrays built for it)
            alone = self._outage & silent & self._own()
            if alone.any():  # its read answers now, it does not: its own silence, named
                self._outage[alone] = False
                self.tier[alone] = ANSWERING
        back = np.flatnonzero((self.tier > ANSWERING) & ~silent)
        if back.size:
            self._recover(back)
        if not silent.any():
            self.active = False
            return
        self.active = True
        new = np.where(silent_s > cfg.action_s, ACTED,
                       np.where(silent_s > cfg.hold_s, HELD, WARNED)).astype(np.int8)
        new[~silent] = ANSWERING
        rising = np.flatnonzero(new > self.tier)
        if not rising.size:
            return
        old = self.tier[rising].copy()
        self.tier[rising] = new[rising]
        warned = rising[old < WARNED]
        if warned.size:
            self._warn(warned, float(silent_s[warned].max()))
        newly_held = rising[(old < HELD) & (new[rising] >= HELD)]
        if newly_held.size:
            self.holding[newly_held] = True
            self.releasing[newly_held] = False
            self.steering = True
            own = newly_held[~self._outage[newly_held]]
            self.held_by[own] += 1
            self.held += int(own.size)
            if own.size:
                self._say(f"holding {self._names(own)} at the last goal sent "
                          "(goals still go out; no reply is needed for them)")
        acting = rising[(old < ACTED) & (new[rising] >= ACTED)]
        if acting.size:
            self._outage[acting] = False  # unanswered this long: named, whatever the cause
            self.acted_by[acting] += 1
            self._act(acting, float(silent_s[acting].max()))

    def _own(self) -> np.ndarray:
        """(n,) bool: the servos whose silence is their own: those whose last read had
        other servos answering (or asked them alone), less those the bus saw a reply cut
        off before; and those the bus saw a reply stop at, whatever their last read."""
        own = ~(self._quiet_together | self._cut)
        if self._stopped is not None:
            own |= self._stopped
        return own

    def _warn(self, warned: np.ndarray, seconds: float) -> None:
        """Servos just past ``warn_s``: those whose silence is not their own (their reads
        went unanswered as a whole, or were cut short at a silent servo before them; not
        every servo) are the read's trouble, said once; the others are named."""
        everyone = len(warned) == self.n or bool((self.tier > ANSWERING).all())
        whole = ~self._own()[warned]
        if everyone and whole.all():
            # every servo, reads unanswered whole: the host's, the emulator's or the
            # bus's (its power, the adapter), said once with the cause; later times are
            # counted. Still quiet at action_s, it is named and acted on.
            self._outage[warned] = True
            self.read_outages += 1
            if not self._said_all_quiet:
                self._said_all_quiet = True
                what, why = self.describe(warned, seconds)
                self._say(f"{what}; {why}; every servo is held until it answers (said once;"
                          " the summary counts such reads)")
            return
        if (whole.sum() >= 2 or self._cut[warned].any()) and not everyone:
            self._outage[warned[whole]] = True
            self.read_outages += 1
            own = warned[~whole]
            if own.size:
                self._name_silent(own, seconds, everyone)
            if not self._said_outage:
                self._said_outage = True
                cause = ("the emulator was not keeping up (a loaded machine)"
                         if self.bus.emulated else
                         "the host or the USB adapter was late, or the bus's power dipped")
                group = warned[whole]
                stopped_at = (np.flatnonzero(self._stopped) if self._stopped is not None
                              else np.zeros(0, np.intp))
                if self._quiet_together[group].all() or not stopped_at.size:
                    self._say(f"a read of {len(group)} servos ({self._names(group)}) went "
                              f"unanswered as a whole for {seconds:.2f} s while other reads "
                              f"answer: {cause}, not these servos; they are held until it "
                              "answers (said once; the summary counts such reads)")
                else:
                    self._say(f"{self._names(group)} went unanswered for {seconds:.2f} s "
                              f"in reads whose reply stopped at {self._names(stopped_at)} "
                              f"before them, or when {cause}: not these servos; they are "
                              "held until they answer (said once; the summary counts such "
                              "reads)")
            self._say_host_late()
            return
        self._name_silent(warned, seconds, everyone)

    def _name_silent(self, warned: np.ndarray, seconds: float, everyone: bool) -> None:
        self._outage[warned] = False
        what, why = self.describe(warned, seconds)
        self.silences += int(warned.size)
        self.silent_by[warned] += 1
        self._say(f"{what}; {why}")
        if not everyone:
            self._say_host_late()

    def _host_late(self) -> bool:
        late = self.late_s >= HOST_LATE_S or self._late_reads > 0
        return late and self._last_read_s - self._late_at <= self.config.action_s

    def _late_text(self) -> str:
        return (f"the host was late by {self.late_s * 1e3:.0f} ms"
                + (f" ({self._late_reads} reads came after their deadline)"
                   if self._late_reads else ""))

    def _say_host_late(self) -> None:
        """The host made reads late while servos went quiet: said once in the run, in a
        line of its own (not in each servo's); later times are counted."""
        if not self._host_late():
            return
        self.host_late_episodes += 1
        if not self._said_host:
            self._said_host = True
            self._say(f"{self._late_text()} while servos went quiet: the host, not the bus, "
                      "made those reads late (give the loop a CPU of its own, see [loop] "
                      "realtime_priority and pin_cpu; said once, the summary counts it)")

    def counts(self) -> dict[str, object]:
        """What happened to whom, for the run's summary: each servo's silences, holds
        and actions (the servos it happened to), and the reads unanswered as a whole and
        the host's late episodes (nobody's cable)."""
        who = {}
        for i in np.flatnonzero(self.silent_by + self.held_by + self.acted_by).tolist():
            who[self.bus.describe(i)] = {"silent": int(self.silent_by[i]),
                                         "held": int(self.held_by[i]),
                                         "acted": int(self.acted_by[i])}
        return {"servos": who, "reads_unanswered_whole": self.read_outages,
                "host_late": self.host_late_episodes}

    def _act(self, indices: np.ndarray, seconds: float) -> None:
        what, why = self.describe(indices, seconds)
        action = self.config.action
        if action == "stop":
            raise DeviceTimeoutError(
                f"{what} {self.bus.where()} ({self.bus.stats.summary()}); {why}; "
                "[silence] action is stop")
        if action == "relax":
            self.relax_reason = f"{what}; {why}"
            self._say(f"{what}: relaxing every servo until it answers ([silence] action)")
        else:
            rest = ("stays held, the others continue" if len(indices) < self.n
                    else "stay held")
            whole = len(indices) >= 2 and bool(self._quiet_together[indices].all())
            self._say(f"{what}: {self._names(indices)} {rest} ([silence] action)"
                      + (f"; {why}" if whole else ""))

    def rebooted(self, state: ServoState) -> bool:
        """Whether the bus rebooted (or found restarted) a servo since the last look: then
        :meth:`update` must see this read, all fresh or not, to ease it back."""
        reboots = state.stats.reboots
        return len(reboots) == self.n and bool((reboots > self._reboots).any())

    def _note_reboots(self, state: ServoState) -> None:
        """A servo the bus rebooted came back with torque on where it was (its goal is
        the bus's last goal for it): it eases back to the loop's goals from there at
        the slew limit, as a servo that answers again does."""
        reboots = state.stats.reboots
        if len(reboots) != self.n or not (reboots > self._reboots).any():
            return
        new = np.flatnonzero(reboots > self._reboots)
        self._reboots[:] = reboots
        self._from[new] = self._loop_goals(
            np.asarray(self.bus.last_goals_deg, dtype=np.float64))[new]
        self.releasing[new] = True
        self.steering = True

    def ease_from(self, index: int, deg: float) -> None:
        """Servo ``index`` eases to the loop's goals from ``deg`` at the slew limit, as a
        rebooted servo does (the [heat] tiers: a joint that gave way under an effort cap
        gets its full effort back where it is)."""
        self._from[index] = deg
        self.releasing[index] = True
        self.steering = True

    def _admit(self, left_out: np.ndarray, state: ServoState, now: float) -> None:
        """Servos left out that answer in this read: the bus admits them (or says why
        not, once per reason, and is asked again after ``ADMIT_RETRY_S``); each admitted
        one eases from where the bus gave it torque to its goals at the slew limit."""
        answering = left_out & state.answered & (now >= self._admit_after)
        for i in np.flatnonzero(answering).tolist():
            goal, text = self.bus.admit(i)
            if goal is None:
                self._admit_after[i] = now + ADMIT_RETRY_S
                if text != self._admit_said[i]:
                    self._admit_said[i] = text
                    self._say(text)
                continue
            left_out[i] = False
            self._from[i] = goal
            self.releasing[i] = True
            self.steering = True
            self.admitted += 1
            self._say(text)

    def _recover(self, back: np.ndarray) -> None:
        own = back[~self._outage[back]]
        self.recoveries += int(own.size)
        if own.size:  # a read unanswered as a whole that answers again: not said
            self.recovery_reads_max = max(self.recovery_reads_max,
                                          int(self._reads[own].max()))
            held = bool(self.holding[own].any())
            who = f"{self._names(own)} answer{'s' if own.size in (1, self.n) else ''}"
            self._say(f"{who} again after {int(self._reads[own].max())} silent reads"
                      + (": releasing to the goals at the slew limit" if held else ""))
        self._outage[back] = False
        self.releasing[back] |= self.holding[back]
        self.holding[back] = False
        self.tier[back] = ANSWERING
        self._reads[back] = 0
        if not (self.tier >= ACTED).any():
            self.relax_reason = None

    def describe(self, indices: np.ndarray, seconds: float) -> tuple[str, str]:
        """(what was seen, what it points to) for silent servos ``indices``."""
        everyone = len(indices) == self.n or bool((self.tier > ANSWERING).all())
        who = "any servo" if everyone else self._names(indices)
        what = f"no valid reply from {who} for {seconds:.2f} s"
        late = self._host_late()
        late_text = self._late_text()
        emulated = self.bus.emulated
        if everyone and late:
            why = (f"{late_text} and every servo went quiet at once: the host "
                   + ("and the emulator are" if emulated else "is")
                   + " not keeping up, not a hardware fault (give the loop a CPU of its "
                   "own, see [loop] realtime_priority and pin_cpu, or lower rate_hz)")
        elif everyone and emulated:
            why = ("every servo went quiet at once on an emulated bus while the host kept "
                   "time: the emulator is not keeping up (a loaded machine), not a "
                   "hardware fault")
        elif everyone:
            why = ("every servo went quiet at once: check the bus's power supply, the USB "
                   "adapter and the baud rate")
        elif len(indices) >= 2 and bool(self._quiet_together[indices].all()):
            k = len(indices)
            why = (f"all {k} went quiet at once, every servo one read asks, while the other "
                   f"servos answer: a read unanswered as a whole, not {k} cables; "
                   + ("the emulator is not keeping up (a loaded machine)" if emulated
                      else "check the bus's power supply and the USB adapter"))
        else:
            why = "the other servos answer: check its cable, power and ID"
        return what, why

    def _names(self, indices: np.ndarray) -> str:
        if len(indices) == self.n:
            return "every servo"
        return ", ".join(self.bus.describe(int(i)) for i in indices)

    def _say(self, text: str) -> None:
        self.events.append(text)

    def drain_events(self) -> list[str]:
        """What happened since the last call, oldest first."""
        out = list(self.events)
        self.events.clear()
        return out

    # ------------------------------------------------------------------ goals
    def steer(self, goals_deg: np.ndarray, last_goal_deg: np.ndarray,
              dt_s: float) -> np.ndarray:
        """``goals_deg`` with held servos at ``last_goal_deg`` and released ones moving
        back at the slew limit over ``dt_s`` (a new array; the caller's is untouched)."""
        out = self._goals
        np.copyto(out, goals_deg)
        if not self.steering:
            return out
        rebooted = np.isfinite(self._from)
        if rebooted.any():  # eases from where the rebooted servo is, not the last goal
            last_goal_deg = np.where(rebooted, self._from, last_goal_deg)
            self._from[:] = np.nan
        known = np.isfinite(last_goal_deg)
        hold = self.holding & known
        out[hold] = last_goal_deg[hold]
        rel = self.releasing & known & np.isfinite(out)
        if rel.any():
            limit = self.slew_deg_s * dt_s
            step = self._step
            np.subtract(out, last_goal_deg, out=step)
            done = rel & (np.abs(step) <= limit)
            np.clip(step, -limit, limit, out=step)
            out[rel] = last_goal_deg[rel] + step[rel]
            self.releasing[done] = False
        self.releasing &= known
        self.steering = bool(self.holding.any() or self.releasing.any())
        return out
