"""The mode machine on its own: glove loss, hysteresis on the way back, stops."""

from __future__ import annotations

from handrig.loop.modes import Mode, ModeMachine


def machine(**kw):
    calls: list[str] = []
    m = ModeMachine(glove_timeout_s=0.25, relax_time_s=1.0, event=calls.append,
                    on_relax=lambda: calls.append("<relax>"),
                    on_resume=lambda: calls.append("<resume>"), **kw)
    m.start(0.0)
    return m, calls


def feed(m: ModeMachine, t0: float, t1: float, frame_every_s: float | None,
         dt: float = 0.005) -> list[Mode]:
    """Cycles every dt from t0 to t1, a frame every ``frame_every_s`` (None: silence)."""
    modes = []
    next_frame = t0
    t = t0
    while t < t1 - 1e-12:
        if frame_every_s is not None and t >= next_frame - 1e-12:
            modes.append(m.frame(t, False))
            next_frame += frame_every_s
        else:
            modes.append(m.silence(t))
        t += dt
    return modes


def test_first_frame_runs_and_silence_relaxes() -> None:
    m, calls = machine()
    assert m.mode is Mode.WAITING
    feed(m, 0.0, 0.2, None)
    assert m.mode is Mode.WAITING  # within glove_timeout_s of the start
    feed(m, 0.2, 0.3, None)
    assert m.mode is Mode.RELAXING and "no glove frame yet" in calls[-1]
    assert calls[-2] == "<relax>" and m.relax_events == 1


def test_back_after_a_short_run_of_good_frames_then_eased_in() -> None:
    m, calls = machine(resume_frames=3)
    feed(m, 0.0, 0.5, 0.005)
    assert m.mode is Mode.RUNNING
    feed(m, 0.5, 1.0, None)
    assert m.mode is Mode.RELAXING
    assert m.frame(1.0, False) is Mode.RELAXING
    assert m.frame(1.005, False) is Mode.RELAXING
    assert m.frame(1.010, False) is Mode.RESUMING  # the third in a row
    assert calls[-2:] == ["<resume>", calls[-1]] and "glove is back" in calls[-1]
    m.resumed()
    assert m.mode is Mode.RUNNING and m.resumes == 1


def test_a_glove_that_sends_now_and_then_stays_relaxed() -> None:
    m, _ = machine(resume_frames=3)
    feed(m, 0.0, 0.5, 0.005)
    modes = feed(m, 0.5, 10.0, 1.0)  # a 1 Hz glove: every gap is longer than the timeout
    assert Mode.RESUMING not in modes and m.mode is Mode.RELAXING
    assert m.relax_events == 1 and m.resumes == 0


def test_a_gap_breaks_the_run() -> None:
    m, _ = machine(resume_frames=3)
    feed(m, 0.0, 0.5, 0.005)
    feed(m, 0.5, 1.0, None)
    m.frame(1.0, False)
    m.frame(1.005, False)
    m.silence(1.1)
    assert m.frame(1.3, False) is Mode.RELAXING  # 0.295 s after the last: starts over
    assert m.frame(1.305, False) is Mode.RELAXING
    assert m.frame(1.31, False) is Mode.RESUMING


def test_stop_requests_act_between_cycles_and_the_second_is_immediate() -> None:
    m, calls = machine()
    feed(m, 0.0, 0.1, 0.005)
    m.request_stop("SIGHUP received")
    assert m.mode is Mode.RUNNING  # nothing happens inside a signal handler
    m.poll()
    assert m.mode is Mode.STOPPING and m.stop_reason == "SIGHUP received"
    assert "<relax>" in calls and not m.stop_now
    m.request_stop("SIGHUP received")
    m.poll()
    assert m.stop_now and m.stop_reason == "SIGHUP received (immediate)"


def test_estop_stops_and_the_end_of_the_run_does_not_override_it() -> None:
    m, _ = machine()
    feed(m, 0.0, 0.1, 0.005)
    assert m.frame(0.1, True) is Mode.STOPPING and m.estop
    m.finish("100 frames done")
    assert m.stop_reason == "e-stop"


def test_servos_silent_relaxes_blocks_the_resume_then_lets_good_frames_bring_it_back() -> None:
    m, calls = machine(resume_frames=3)
    feed(m, 0.0, 0.5, 0.005)
    m.servos_silent("no valid reply from servo 7 for 1.00 s")
    assert m.mode is Mode.RELAXING and m.relax_events == 1
    assert calls[-2] == "<relax>" and calls[-1].startswith("no valid reply from servo 7")
    m.servos_silent("no valid reply from servo 7 for 1.20 s")  # still: said once
    assert calls[-1].endswith("over 1.00 s") and len([c for c in calls if "servo 7" in c]) == 1
    feed(m, 0.5, 1.0, 0.005)  # good frames, but the servos are silent
    assert m.mode is Mode.RELAXING
    m.servos_silent(None)
    assert "servos answer again" in calls[-1]
    assert [m.frame(1.0 + 0.005 * k, False) for k in range(3)][-1] is Mode.RESUMING


def test_servos_silent_while_stopping_changes_nothing() -> None:
    m, _ = machine()
    feed(m, 0.0, 0.1, 0.005)
    m.request_stop("test")
    m.poll()
    m.servos_silent("no valid reply from any servo")
    assert m.mode is Mode.STOPPING


def test_relax_key_holds_the_puppet_relaxed_while_the_glove_sends() -> None:
    m, calls = machine(resume_frames=3)
    feed(m, 0.0, 0.5, 0.005)
    m.toggle_relax()
    assert m.mode is Mode.RUNNING  # a key only records the request
    m.poll()
    assert m.mode is Mode.RELAXING and m.held and "<relax>" in calls
    assert "relax key: relaxed until it is pressed again" in calls[-1]
    modes = feed(m, 0.5, 2.0, 0.005)  # good frames all along: still held
    assert set(modes) == {Mode.RELAXING}
    assert m.relax_events == 0  # a relax key is no glove loss
    m.toggle_relax()
    m.poll()
    assert not m.held and "relax key: resuming" in calls[-1]
    modes = feed(m, 2.0, 2.02, 0.005)
    assert Mode.RESUMING in modes and m.resumes == 1
    m.resumed()
    assert m.mode is Mode.RUNNING


def test_relax_key_while_the_glove_is_lost_keeps_it_relaxed_when_it_comes_back() -> None:
    m, calls = machine(resume_frames=3)
    feed(m, 0.0, 0.5, 0.005)
    feed(m, 0.5, 1.0, None)
    assert m.mode is Mode.RELAXING and m.relax_events == 1
    m.toggle_relax()
    m.poll()
    assert "staying relaxed" in calls[-1]
    assert set(feed(m, 1.0, 1.5, 0.005)) == {Mode.RELAXING}


def test_relax_key_does_nothing_while_stopping() -> None:
    m, _ = machine()
    feed(m, 0.0, 0.1, 0.005)
    m.request_stop("q pressed")
    m.toggle_relax()
    m.poll()
    assert m.mode is Mode.STOPPING and not m.held and not m.stop_now


def test_estop_key_ends_at_once_without_easing() -> None:
    m, calls = machine()
    feed(m, 0.0, 0.1, 0.005)
    m.request_estop("e-stop key")
    assert not m.stop_now
    m.poll()
    assert m.stop_now and m.estop and m.mode is Mode.STOPPING
    assert m.stop_reason == "e-stop key" and "<relax>" not in calls
    assert calls[-1] == "e-stop key: torque off now, no easing"
    m.finish("100 frames done")
    assert m.stop_reason == "e-stop key"


def test_ease_in_eases_the_first_frame_from_where_the_servos_are() -> None:
    m, calls = machine(ease_in=True)
    assert m.frame(0.0, False) is Mode.RESUMING
    assert calls[0] == "<resume>" and "easing in" in calls[1]
    assert m.resumes == 0  # an ease in is no glove coming back
    m.resumed()
    assert m.frame(0.01, False) is Mode.RUNNING
