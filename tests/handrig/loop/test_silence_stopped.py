"""Where a reply stopped decides whose silence it is (``ServoState.stopped``).

A Fast Sync Read's reply is a chain: a silent servo ends it, and the servos after it go
unanswered with it until the bus asks the silent one last. On a starved host the read's
retry does not fit and those servos miss reads in a row, while the servos before the
silent one answer: their last read was not "unanswered as a whole", and the silence
tiers used to name them all as silent servos ("check its cable"). The bus says which
servo the reply stopped at; the others are the read's trouble, said once, not named.

The facts are fed to :class:`~handrig.loop.silence.SilenceWatch` read by read, as the
driver reports them (what a starved host makes of a read is what is scripted), with
the real driver on the in-process emulator for the servos' names. The driver's side (that
a Fast Sync Read cut short marks where it stopped) is checked on the emulator below.
"""

from __future__ import annotations

import math

import numpy as np

from handrig.config.rig import SilenceConfig
from handrig.devices.servo import DynamixelBus, ServoState
from handrig.loop.silence import SilenceWatch
from tests.handrig.loop.test_silence import POLICY
from tests.helpers.servos import make_bus, small_rig

STEP_S = 0.02  # a read every 20 ms, the parts (0, 2, 4) and (1, 3, 5) in turn
PART = (np.array([0, 2, 4]), np.array([1, 3, 5]))


def _watch() -> tuple[DynamixelBus, SilenceWatch]:
    bus, _, _ = make_bus(small_rig(), fault_policy=POLICY)
    config = SilenceConfig(warn_s=0.1, hold_s=0.2, action_s=0.6, action="continue")
    return bus, SilenceWatch(bus, config, bus.rig.loop.slew_deg_s)


def _feed(watch: SilenceWatch, bus: DynamixelBus, reads: int, t0: float,
          unanswered: set[int], stopped: set[int], heard: np.ndarray,
          tell_stopped: bool = True, parts: tuple[np.ndarray, ...] = PART) -> list[str]:
    """``reads`` reads from ``t0``: the servos in ``unanswered`` give nothing, those in
    ``stopped`` are where the bus saw the reply stop; ``heard`` (last reading times) is
    kept up to date."""
    said = []
    n = bus.n_servos
    for k in range(reads):
        now = t0 + k * STEP_S
        asked = np.zeros(n, bool)
        asked[parts[k % len(parts)]] = True
        answered = asked.copy()
        answered[list(unanswered)] = False
        heard[answered] = now
        watch.note_read(now)
        state = ServoState(
            positions_deg=np.zeros(n), velocities_dps=np.zeros(n), currents_ma=np.zeros(n),
            temperatures_c=np.full(n, 30.0), status_errors=np.zeros(n, np.uint8),
            hardware_errors=np.zeros(n, np.uint8), stale=~answered & asked,
            age_s=now - heard, timestamp_s=now, stats=bus.stats.copy(), asked=asked,
            stopped=(np.isin(np.arange(n), list(stopped)) if tell_stopped else None))
        watch.update(state, now)
        said += watch.drain_events()
    return said


def _named_silent(said: list[str]) -> set[str]:
    return {e.split("no valid reply from ")[1].split(";")[0].rsplit(" for ", 1)[0]
            for e in said if e.startswith("no valid reply from")}


def test_servos_a_cut_reply_left_unanswered_are_not_named_as_silent() -> None:
    bus, watch = _watch()
    heard = np.full(bus.n_servos, 100.0)
    said = _feed(watch, bus, 10, 100.0, set(), set(), heard)
    # servo 3 (index 2) stops; the chain [0, 2, 4] ends there, servo 5 (index 4) goes
    # unanswered with it for 8 reads of its part while servo 1 (index 0) answers
    said += _feed(watch, bus, 16, 100.2, {2, 4}, {2}, heard)
    text = " | ".join(said)
    assert _named_silent(said) == {"servo 3 (riThumbCMCz)"}, text
    assert "the other servos answer: check its cable" in text
    cut = [e for e in said if "servo 5 (riThumbIPz)" in e]
    assert len(cut) == 1 and "reply stopped at servo 3 (riThumbCMCz)" in cut[0], text
    assert "not these servos" in cut[0] and "said once" in cut[0]
    assert watch.counts()["servos"] == {
        "servo 3 (riThumbCMCz)": {"silent": 1, "held": 1, "acted": 0}}
    assert watch.holding[2] and watch.holding[4]  # both held (a held goal is safe)
    # the chain moves servo 3 last: servo 5 answers again, unannounced; servo 3 stays
    said = _feed(watch, bus, 10, 100.52, {2}, {2}, heard)
    assert not watch.holding[4] and watch.holding[2]
    assert not any("answer" in e and "servo 5" in e for e in said), said


def test_a_bus_that_cannot_tell_where_replies_stopped_keeps_the_old_judgement() -> None:
    """Without ``stopped`` (a vendor whose bus has no chain), a servo whose read had others
    answering is its own silence: the two are named (what the words say is then all the
    watch can know)."""
    bus, watch = _watch()
    heard = np.full(bus.n_servos, 100.0)
    _feed(watch, bus, 10, 100.0, set(), set(), heard, tell_stopped=False)
    said = _feed(watch, bus, 16, 100.2, {2, 4}, {2}, heard, tell_stopped=False)
    assert _named_silent(said) == {"servo 3 (riThumbCMCz), servo 5 (riThumbIPz)"}, said


def test_the_driver_marks_where_a_fast_sync_read_reply_stopped() -> None:
    """The driver's side, on the in-process emulator: servo 3 silent, a read of its part
    with no retry (a starved host's) marks servo 3 as where the reply stopped, not the
    servo the chain lost after it; a read that answers clears the mark."""
    from handrig.devices.servo.bus import FaultPolicy

    bus, _, peer = make_bus(small_rig(), fault_policy=FaultPolicy(read_budget_s=0.01,
                                                                  read_retries=0))
    first = bus.read_state(part=(0, 2))
    assert first.stopped is not None and not first.stopped.any()
    peer.servos[2].silent_until = math.inf
    state = bus.read_state(part=(0, 2))
    assert state.answered.tolist() == [True, False, False, False, False, False]
    assert state.stopped.tolist() == [False, False, True, False, False, False]
    peer.servos[2].silent_until = 0.0
    for _ in range(3):
        state = bus.read_state(part=(0, 2))
    assert state.answered[[0, 2, 4]].all() and not state.stopped.any()


def test_after_a_fall_back_to_sync_read_a_silent_servo_is_named() -> None:
    """Fast Sync Read said where replies stopped, then the bus fell back to Sync Read
    (no chain: it cannot say): a servo that goes silent then is named, as before."""
    bus, watch = _watch()
    heard = np.full(bus.n_servos, 100.0)
    _feed(watch, bus, 10, 100.0, set(), set(), heard)
    _feed(watch, bus, 4, 100.2, {2, 4}, {2}, heard)  # a cut chain, told
    _feed(watch, bus, 6, 100.28, set(), set(), heard)  # all back
    said = _feed(watch, bus, 16, 100.4, {3}, set(), heard, tell_stopped=False)
    assert _named_silent(said) == {"servo 4 (riThumbMCPz)"}, said
    assert "the other servos answer: check its cable" in " | ".join(said)


def test_a_servo_read_alone_that_gives_nothing_is_its_own_silence() -> None:
    """Parts of one servo (a small rig): a read that asks one servo and gets nothing has
    nobody to cut off and nobody else to blame: the servo is named."""
    bus, watch = _watch()
    heard = np.full(bus.n_servos, 100.0)
    ones = tuple(np.array([i]) for i in range(bus.n_servos))
    _feed(watch, bus, 12, 100.0, set(), set(), heard, parts=ones)
    said = _feed(watch, bus, 60, 100.24, {2}, set(), heard, parts=ones)
    assert _named_silent(said) == {"servo 3 (riThumbCMCz)"}, said
