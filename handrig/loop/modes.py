"""The loop's mode machine: what the puppet should be doing this cycle.

::

    WAITING --first frame--> RUNNING (with ease_in: RESUMING, eased in from where the
                             servos are, then RUNNING)
    WAITING, RUNNING, RESUMING --no frame for glove_timeout_s--> RELAXING
    RELAXING --resume_frames good frames in a row--> RESUMING --eased back--> RUNNING
    any --e-stop, stop request, frames or time done--> STOPPING --eased--> (the run ends)
    any --e-stop key--> STOPPING, ended at once (no easing: torque goes off)

The relax key (:meth:`ModeMachine.toggle_relax`) relaxes the puppet and holds it
relaxed whatever the glove does; pressed again it lets go, and the glove's next
``resume_frames`` good frames ease the puppet back (RESUMING) as after a loss.

"Good frames in a row": each within ``glove_timeout_s`` of the one before, so a
glove that only sends now and then (1 Hz, say) stays relaxed instead of pulling
the puppet back for one frame and letting it go again.

The machine only decides; transitions happen in the loop's thread, between
cycles. :meth:`ModeMachine.request_stop`, :meth:`ModeMachine.toggle_relax` and
:meth:`ModeMachine.request_estop` may be called from a signal handler or another
thread (the keys) at any time: each records the request, the next
:meth:`ModeMachine.poll` acts on it.
Entering RELAXING or STOPPING from a mode that was following (or holding)
calls ``on_relax``; entering RESUMING calls ``on_resume``: the easings restart.

The servo bus can ask for RELAXING too (its ``[silence]`` action ``"relax"``,
:meth:`ModeMachine.servos_silent`): no resume until it says the servos answer
again, then the usual run of good frames.
"""

from __future__ import annotations

import enum
from collections.abc import Callable

from handrig.config.rig import LoopConfig
from handrig.loop.stats import RunStats


class Mode(enum.Enum):
    WAITING = "waiting"  # no glove frame yet: hold where the servos are
    RUNNING = "running"
    RELAXING = "relaxing"  # glove lost or relax key: easing to relaxed, then holding there
    RESUMING = "resuming"  # glove back: easing from where the servos are to the glove's pose
    STOPPING = "stopping"  # e-stop or stop request: easing to relaxed, then the loop ends


_FOLLOWING = (Mode.WAITING, Mode.RUNNING, Mode.RESUMING)


class ModeMachine:
    """Mode transitions and the reasons for them.

    ``event(text)`` is told every transition worth a line in the log;
    ``on_relax()`` / ``on_resume()`` when an easing must start over. The figures
    (stop reason, e-stop, relax events, resumes) are kept in ``stats`` as they happen,
    where a live display reads them.
    """

    def __init__(
        self,
        *,
        glove_timeout_s: float,
        relax_time_s: float,
        resume_frames: int = LoopConfig.resume_frames,
        resume_time_s: float = LoopConfig.resume_time_s,
        event: Callable[[str], None] = lambda text: None,
        on_relax: Callable[[], None] = lambda: None,
        on_resume: Callable[[], None] = lambda: None,
        stats: RunStats | None = None,
        ease_in: bool = False,
    ) -> None:
        self.ease_in = ease_in  # the first frame eases in over resume_time_s (a take played)
        self.glove_timeout_s = float(glove_timeout_s)
        self.relax_time_s = float(relax_time_s)
        self.resume_frames = max(1, int(resume_frames))
        self.resume_time_s = float(resume_time_s)
        self.event = event
        self.on_relax = on_relax
        self.on_resume = on_resume
        self.stats = stats if stats is not None else RunStats()
        self.mode = Mode.WAITING
        self.stop_requests = 0
        self._requested: list[str] = []  # appended by request_stop, consumed by poll
        # appended by toggle_relax (None), request_relax (True), request_resume (False)
        self._toggles: list[tuple[bool | None, str]] = []
        self._estop_requested = ""  # set by request_estop, acted on by poll
        self._halt = False  # an e-stop: end at once, no easing
        self.held = False  # relaxed by the relax key: frames do not resume the puppet
        self._last_frame_s: float | None = None
        self._run = 0  # good frames in a row while relaxed
        self._t0 = 0.0
        self._servos_silent = False  # the bus asked to relax until its servos answer

    @property
    def stop_reason(self) -> str:
        return self.stats.stop_reason

    @stop_reason.setter
    def stop_reason(self, reason: str) -> None:
        self.stats.stop_reason = reason

    @property
    def estop(self) -> bool:
        return self.stats.estop

    @property
    def relax_events(self) -> int:
        return self.stats.relax_events

    @property
    def resumes(self) -> int:
        return self.stats.resumes

    # -- from outside the loop -------------------------------------------------------------
    def request_stop(self, reason: str) -> None:
        """Ease to the relaxed pose, then end the run; a second request ends it at once."""
        self.stop_requests += 1
        if self.stop_requests == 1:
            self.stop_reason = self.stop_reason or reason
        else:
            self.stop_reason = f"{reason} (immediate)"
        self._requested.append(reason)

    def toggle_relax(self, reason: str = "relax key") -> None:
        """Relax and hold (or, when held, let the glove take over again)."""
        self._toggles.append((None, reason))

    def request_relax(self, reason: str) -> None:
        """Relax and hold, as the relax key does when the puppet follows the glove; said
        and nothing more when it is held relaxed already (a cue: ``relax``)."""
        self._toggles.append((True, reason))

    def request_resume(self, reason: str) -> None:
        """Let the glove take over again, as the relax key does when the puppet is held
        relaxed; said and nothing more when it is not held (a cue: ``resume``)."""
        self._toggles.append((False, reason))

    def request_estop(self, reason: str = "e-stop key") -> None:
        """End the run at the next poll without easing (torque goes off at once)."""
        self._estop_requested = reason or "e-stop"

    @property
    def stop_now(self) -> bool:
        """A second stop request or an e-stop came: end without easing."""
        return self.stop_requests > 1 or self._halt

    # -- in the loop ---------------------------------------------------------------------------
    def start(self, t0_s: float) -> None:
        self._t0 = t0_s

    def poll(self) -> None:
        """Act on the requests (e-stop, stop, relax key) that arrived since the last call."""
        if self._estop_requested and not self._halt:
            reason, self._estop_requested = self._estop_requested, ""
            self._halt = True
            self.stats.estop = True
            self.stop_reason = reason
            self.mode = Mode.STOPPING
            self.event(f"{reason}: torque off now, no easing")
        while self._requested:
            reason = self._requested.pop(0)
            self._relax(Mode.STOPPING, reason)
        while self._toggles:
            want, reason = self._toggles.pop(0)
            if want is None or want != self.held:
                self._toggle(reason)
            elif self.mode is not Mode.STOPPING:
                self.event(f"{reason}: " + ("held relaxed already" if self.held
                                            else "not held relaxed, nothing to resume"))

    def finish(self, reason: str) -> None:
        """The run's length is reached (frames or time): stop, unless already stopping."""
        if self.mode is not Mode.STOPPING:
            self.stop_reason = reason
            self._relax(Mode.STOPPING, reason)

    def frame(self, now_s: float, estop: bool) -> Mode:
        """A glove frame arrived in this cycle; returns the mode for the cycle."""
        previous = self._last_frame_s
        self._last_frame_s = now_s
        if estop and self.mode is not Mode.STOPPING:
            self.stats.estop = True
            self.stop_reason = "e-stop"
            self._relax(Mode.STOPPING, "e-stop pressed on the glove")
        mode = self.mode
        if mode is Mode.WAITING and self.ease_in:
            self.mode = Mode.RESUMING
            self.on_resume()
            self.event(f"first frame: easing in from where the servos are over "
                       f"{self.resume_time_s:.2f} s")
        elif mode is Mode.WAITING:
            self.mode = Mode.RUNNING
        elif mode is Mode.RELAXING and not self._servos_silent and not self.held:
            in_a_row = previous is not None and now_s - previous <= self.glove_timeout_s
            self._run = self._run + 1 if in_a_row else 1
            if self._run >= self.resume_frames:
                self._run = 0
                self.mode = Mode.RESUMING
                self.stats.resumes += 1
                self.on_resume()
                self.event(f"glove is back: following it again, easing in over "
                           f"{self.resume_time_s:.2f} s")
        return self.mode

    def silence(self, now_s: float) -> Mode:
        """No glove frame in this cycle; returns the mode for the cycle."""
        if self.mode in _FOLLOWING:
            since = now_s - (self._last_frame_s if self._last_frame_s is not None else self._t0)
            if since > self.glove_timeout_s:
                what = ("no glove frame yet" if self._last_frame_s is None
                        else "glove silent or garbled")
                self._relax(Mode.RELAXING, f"{what} for {since:.2f} s")
        return self.mode

    def servos_silent(self, reason: str | None) -> None:
        """The bus's word on its servos: ``reason`` while it wants the puppet relaxed
        (servos without replies), None when they answer. Relaxes once, and blocks
        resuming until None comes."""
        if reason is not None:
            if not self._servos_silent:
                self._servos_silent = True
                self._relax(Mode.RELAXING, reason)
        elif self._servos_silent:
            self._servos_silent = False
            self._run = 0
            if self.mode is Mode.RELAXING:
                self.event(f"servos answer again: following the glove after "
                           f"{self.resume_frames} good frames in a row")

    def resumed(self) -> None:
        """The easing back to the glove is complete."""
        if self.mode is Mode.RESUMING:
            self.mode = Mode.RUNNING

    # -- internals -----------------------------------------------------------------------------
    def _toggle(self, reason: str) -> None:
        if self.mode is Mode.STOPPING:
            return
        if self.held:
            self.held = False
            self._run = 0
            self.event(f"{reason}: resuming, easing back to the glove over "
                       f"{self.resume_time_s:.2f} s once it sends")
            return
        self.held = True
        self.stats.relax_keys += 1
        if self.mode is Mode.RELAXING:
            self.event(f"{reason}: staying relaxed until it is pressed again")
            return
        self._relax(Mode.RELAXING, f"{reason}: relaxed until it is pressed again")

    def _relax(self, mode: Mode, reason: str) -> None:
        if self.mode is Mode.STOPPING:
            return
        if self.mode in _FOLLOWING:
            if mode is Mode.RELAXING and not self.held:  # the glove was lost
                self.stats.relax_events += 1
            self.on_relax()
        self._run = 0
        self.mode = mode
        self.event(f"{reason}: easing to the relaxed pose over {self.relax_time_s:.2f} s")
