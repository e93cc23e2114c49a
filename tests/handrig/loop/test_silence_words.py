"""One silent servo costs that servo only, in words too (issue 41): reads of a part that
go unanswered as a whole, again and again, beside one servo that really went quiet, are
said once as the read's trouble (held, never named as silent servos, their returns not
announced), the host's lateness is said once in a line of its own, and the counts say
what happened to whom. On the real driver over the in-process emulator, a FakeClock."""

from __future__ import annotations

import math

import numpy as np

from handrig.config.rig import SilenceConfig
from handrig.devices.servo import DynamixelBus
from handrig.loop.silence import SilenceWatch
from tests.handrig.devices.servo.test_servo_parts import make_bus, small_rig
from tests.handrig.loop.test_silence import POLICY

STEP_S = 0.02  # a read every 20 ms, the parts in turn


def _watch(emulated: bool = True) -> tuple[DynamixelBus, SilenceWatch, object]:
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY, emulated=emulated)
    config = SilenceConfig(warn_s=0.1, hold_s=0.2, action_s=0.6, action="continue")
    return bus, SilenceWatch(bus, config, bus.rig.loop.slew_deg_s), peer


def _run(bus: DynamixelBus, watch: SilenceWatch, reads: int, start: int = 0,
         stall_at: int | None = None) -> list[str]:
    said = []
    for k in range(start, start + reads):
        if k == stall_at:
            bus.clock.advance(0.08)  # type: ignore[attr-defined]  # the host stalls
        bus.write_goals_deg(np.zeros(6))
        watch.note_read(bus.clock.now())
        watch.update(bus.read_state(part=(k % 2, 2)), bus.clock.now())
        said += watch.drain_events()
        bus.clock.advance(STEP_S)  # type: ignore[attr-defined]
    return said


def _named_silent(said: list[str]) -> set[str]:
    return {e.split("no valid reply from ")[1].split(" for ")[0]
            for e in said if e.startswith("no valid reply from")}


def test_part_outages_beside_one_silent_servo_are_said_once_and_counted() -> None:
    bus, watch, peer = _watch()
    said = _run(bus, watch, 20)
    peer.servos[2].silent_until = math.inf  # servo 3: its own silence (part 0)
    k = 20
    for _ in range(5):  # part 1 (servos 2, 4, 6) unanswered as a whole for 0.16 s, 5 times
        until = bus.clock.now() + 0.16
        for i in (1, 3, 5):
            peer.servos[i].silent_until = until
        said += _run(bus, watch, 20, start=k)
        k += 20
    text = " | ".join(said)
    assert _named_silent(said) == {"servo 3 (riThumbCMCz)"}, text
    assert sum("went unanswered as a whole" in e for e in said) == 1, text
    assert "the emulator was not keeping up" in text
    assert not any(e.startswith("holding") and "servo 2 " in e for e in said), text
    assert not any("answer again" in e for e in said), text  # nobody's return to announce
    assert any(e.startswith("holding servo 3 (riThumbCMCz)") for e in said), text
    counts = watch.counts()
    assert counts["servos"] == {"servo 3 (riThumbCMCz)": {"silent": 1, "held": 1, "acted": 1}}
    assert counts["reads_unanswered_whole"] == 5
    assert watch.silences == 1 and watch.held == 1
    # held while unanswered (a held goal is safe), released after
    assert not watch.holding[[1, 3, 5]].any() and watch.holding[2]


def test_a_servo_of_an_unanswered_read_that_stays_quiet_is_named_on_its_own() -> None:
    bus, watch, peer = _watch(emulated=False)
    _run(bus, watch, 20)
    until = bus.clock.now() + 0.16
    for i in (1, 3):
        peer.servos[i].silent_until = until
    peer.servos[5].silent_until = math.inf  # servo 6 does not come back with its read
    said = _run(bus, watch, 30, start=20)
    text = " | ".join(said)
    assert "went unanswered as a whole" in text and "the host or the USB adapter" in text
    assert _named_silent(said) == {"servo 6 (riIndexMCPx)"}, text
    assert "the other servos answer: check its cable, power and ID" in text
    assert watch.counts()["servos"] == {
        "servo 6 (riIndexMCPx)": {"silent": 1, "held": 1, "acted": 1}}


def test_the_hosts_lateness_is_said_once_in_a_line_of_its_own() -> None:
    bus, watch, peer = _watch()
    said = _run(bus, watch, 20)
    peer.servos[2].silent_until = math.inf
    said += _run(bus, watch, 20, start=20, stall_at=21)
    peer.servos[2].silent_until = 0.0  # back
    said += _run(bus, watch, 10, start=40)
    peer.servos[4].silent_until = math.inf  # another servo, the host late again
    said += _run(bus, watch, 20, start=50, stall_at=51)
    host = [e for e in said if "host was late" in e]
    assert len(host) == 1 and "the host, not the bus" in host[0], said
    assert not any("host was late" in e for e in said if e.startswith("no valid reply")), said
    assert _named_silent(said) == {"servo 3 (riThumbCMCz)", "servo 5 (riThumbIPz)"}, said
    assert watch.counts()["host_late"] == 2


def test_every_read_unanswered_for_a_moment_on_an_emulator_is_said_once() -> None:
    bus, watch, peer = _watch()
    said = _run(bus, watch, 20)
    k = 20
    for _ in range(3):  # the emulator starved: nobody answers for 0.16 s, three times
        until = bus.clock.now() + 0.16
        for servo in peer.servos:
            servo.silent_until = until
        said += _run(bus, watch, 20, start=k)
        k += 20
    quiet = [e for e in said if "no valid reply" in e or "answer" in e]
    # the first part to go past warn_s, then every servo: each said once, as the
    # emulator's; the two later times are counted, not said
    assert len(quiet) == 2 and all("said once" in e for e in quiet), said
    assert "the emulator is not keeping up" in quiet[1], said
    counts = watch.counts()
    assert counts["servos"] == {} and counts["reads_unanswered_whole"] >= 3, counts
    assert watch.silences == 0 and not watch.holding.any()
