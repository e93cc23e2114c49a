"""The layering engine in the loop (issue 40): a take blended into the live servo targets
and full pose, fading in and out without a jump, looped or once, in step with the run's
time, slew limited from the goals sent. On the real pipeline of the two-hand puppet;
the loop's clock is the test's (times given to ``advance``)."""

from __future__ import annotations

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.loop.layers import LayerMixer, LayerOff, LayerOn, LayerPlan, smoothstep
from handrig.pose import layer_kernels as lk
from handrig.pose.pipeline import POSE_SIZE, PosePipeline, pose_index

DT_S = 0.005  # a 200 Hz glove's cycle


@pytest.fixture(scope="module")
def pipeline() -> PosePipeline:
    return build_parts("puppet_two_hands").pipeline


def _take(values_deg: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """A take's poses: every curve at ``values_deg`` per frame."""
    return np.repeat(np.asarray(values_deg, dtype=np.float64)[:, None], POSE_SIZE, axis=1)


def _plan(mixer: LayerMixer, joints: list[str], times: np.ndarray, values: np.ndarray, *,
          loop: bool = True, fade_s: float = 0.5, at_start: bool = False,
          group: str = "g", take: str = "t") -> LayerPlan:
    index = np.array([pose_index(j) for j in joints], dtype=np.intp)
    return LayerPlan.build(mixer.servo_index, take, group, times, _take(values, times), index,
                           loop=loop, fade_s=fade_s, at_start=at_start)


def _servo(pipeline: PosePipeline, joint: str) -> int:
    return pipeline.servo_joints.index(joint)


def _run(mixer: LayerMixer, live: np.ndarray, t_from: float, t_to: float) -> np.ndarray:
    """The layered targets each cycle from ``t_from`` to ``t_to`` (the live ones fixed)."""
    out = []
    for now in np.arange(t_from, t_to, DT_S):
        mixer.advance(float(now))
        raw = live.copy()
        mixer.mix_targets(raw)
        out.append(raw)
    return np.array(out)


def test_the_kernels_match_numpy() -> None:
    rng = np.random.default_rng(4)
    times = np.cumsum(rng.uniform(0.001, 0.02, 50))
    times -= times[0]
    poses = rng.normal(0, 30, (50, 7))
    row = np.zeros(7)
    cursor = 0
    for t in np.sort(rng.uniform(-0.1, times[-1] + 0.1, 200)):
        cursor = lk.layer_frame(times, poses, float(t), cursor, row)
        want = [np.interp(t, times, poses[:, j]) for j in range(7)]
        np.testing.assert_allclose(row, want, atol=1e-9)
    # a time before the cursor's frame (a loop wrapped) starts the search again
    cursor = lk.layer_frame(times, poses, 0.0, cursor, row)
    np.testing.assert_allclose(row, poses[0])
    values = rng.normal(0, 30, 9)
    at = np.array([1, 4, 8], dtype=np.intp)
    cols = np.array([0, 2, 6], dtype=np.intp)
    low, high = np.full(9, -20.0), np.full(9, 20.0)
    want = values.copy()
    want[at] = np.clip(values[at] + 0.3 * (row[cols] - values[at]), -20.0, 20.0)
    lk.layer_mix(values, at, cols, row, 0.3, low, high)
    np.testing.assert_allclose(values, want)
    row[0] = np.nan  # a non-finite take value leaves the live one
    before = values.copy()
    lk.layer_mix(values, at, cols, row, 1.0, low, high)
    assert values[1] == before[1]


def test_a_fade_in_and_out_never_jumps_and_touches_only_its_group(
        pipeline: PosePipeline) -> None:
    mixer = LayerMixer(pipeline)
    mixer.start(0.0)
    times = np.array([0.0, 10.0])
    mixer.post(LayerOn(_plan(mixer, ["leIndexPIPy"], times, np.array([80.0, 80.0]),
                             fade_s=0.5, at_start=True)))
    live = np.clip(np.zeros(len(pipeline.servo_joints)), pipeline.servo_low,
                   pipeline.servo_high)
    k = _servo(pipeline, "leIndexPIPy")
    fade_in = _run(mixer, live, 0.0, 1.0)
    mixer.post(LayerOff("t", fade_s=0.5))
    fade_out = _run(mixer, live, 1.0, 2.0)
    both = np.concatenate([fade_in, fade_out])
    track = both[:, k]
    delta = 80.0 - live[k]
    # from the live value to the take's and back; smoothstep's steepest slope is 1.5
    assert track[0] == pytest.approx(live[k]) and fade_in[-1, k] == pytest.approx(80.0)
    assert track[-1] == pytest.approx(live[k])
    steps = np.abs(np.diff(track))
    assert steps.max() <= 1.5 * delta * DT_S / 0.5 + 1e-6, steps.max()
    assert steps.max() >= 1.2 * delta * DT_S / 0.5  # it did move at the fade's pace
    assert np.all(np.diff(fade_in[:, k]) >= -1e-9) and np.all(np.diff(fade_out[:, k]) <= 1e-9)
    others = np.delete(both, k, axis=1)
    assert np.all(others == live[np.arange(len(live)) != k])  # the glove's, untouched
    assert mixer.active == 0 and mixer.status == ()
    events = mixer.drain_events()
    assert any("fading in" in e for e in events) and any("ended" in e for e in events)


def test_a_looped_layer_wraps_and_a_once_layer_fades_out_with_its_take(
        pipeline: PosePipeline) -> None:
    k = _servo(pipeline, "riIndexMCPy")
    live = np.clip(np.full(len(pipeline.servo_joints), 10.0), pipeline.servo_low,
                   pipeline.servo_high)
    times = np.linspace(0.0, 1.0, 101)
    ramp = 20.0 + 40.0 * times  # 20 -> 60 deg over the take's second
    for loop in (True, False):
        mixer = LayerMixer(pipeline)
        mixer.start(5.0)  # the run started at 5 s on the loop's clock
        mixer.post(LayerOn(_plan(mixer, ["riIndexMCPy"], times, ramp, loop=loop,
                                 fade_s=0.2, at_start=True)))
        got = _run(mixer, live, 5.0, 7.0)[:, k]
        t = np.arange(5.0, 7.0, DT_S) - 5.0
        at = {round(x, 3): v for x, v in zip(t, got, strict=True)}
        assert at[0.5] == pytest.approx(40.0, abs=1e-6)  # in step with the run's time
        if loop:
            assert at[1.25] == pytest.approx(30.0, abs=1e-6)  # the take from its start again
            assert at[1.75] == pytest.approx(50.0, abs=1e-6)
            assert mixer.active == 1 and mixer.status[0].state == "on"
        else:
            assert at[1.25] == pytest.approx(live[k]) and mixer.active == 0
            # the fade out ends with the take, its last 0.2 s
            assert at[0.79] == pytest.approx(20.0 + 40.0 * 0.79, abs=1e-6)
            assert live[k] < at[0.9] < 20.0 + 40.0 * 0.9
            assert np.abs(np.diff(got)).max() <= 1.5 * 60.0 * DT_S / 0.2 + 0.5


def test_a_cue_starts_the_take_at_its_own_time_and_cross_fades_its_group(
        pipeline: PosePipeline) -> None:
    k = _servo(pipeline, "riIndexMCPy")
    live = np.clip(np.zeros(len(pipeline.servo_joints)), pipeline.servo_low,
                   pipeline.servo_high)
    mixer = LayerMixer(pipeline)
    mixer.start(0.0)
    times = np.linspace(0.0, 2.0, 201)
    _run(mixer, live, 0.0, 1.0)  # a second of the glove alone
    mixer.post(LayerOn(_plan(mixer, ["riIndexMCPy"], times, 30.0 + 10.0 * times,
                             fade_s=0.1, take="a")))  # a cue: its time 0 is now
    got = _run(mixer, live, 1.0, 1.5)
    assert got[-1, k] == pytest.approx(30.0 + 10.0 * (0.5 - DT_S), abs=1e-6)
    mixer.post(LayerOn(_plan(mixer, ["riIndexMCPy"], times, np.full(201, 70.0), fade_s=0.1,
                             take="b")))  # the same group: "a" fades out as "b" fades in
    got = _run(mixer, live, 1.5, 2.0)[:, k]
    assert got[-1] == pytest.approx(70.0) and np.abs(np.diff(got)).max() < 10.0
    assert [s.take for s in mixer.status] == ["b"] and mixer.active == 1


def test_goals_are_slew_limited_from_the_goals_sent_and_the_pose_clamped(
        pipeline: PosePipeline) -> None:
    k = _servo(pipeline, "riIndexPIPy")
    n = len(pipeline.servo_joints)
    mixer = LayerMixer(pipeline)
    mixer.start(0.0)
    times = np.array([0.0, 5.0])
    mixer.post(LayerOn(_plan(mixer, ["riIndexPIPy"], times, np.array([500.0, 500.0]),
                             fade_s=0.0, at_start=True)))  # no fade: the slew limit holds
    mixer.advance(0.0)
    sent = np.clip(np.zeros(n), pipeline.servo_low, pipeline.servo_high)
    raw, targets = sent.copy(), sent.copy()
    mixer.mix_goals(raw, sent, targets, 3.6)  # 720 deg/s for 5 ms
    assert raw[k] == pipeline.servo_high[k]  # the take past the limit: clamped
    assert targets[k] == pytest.approx(sent[k] + 3.6)
    pose = np.zeros(POSE_SIZE)
    mixer.mix_pose(pose)
    p = pose_index("riIndexPIPy")
    assert pose[p] == pipeline.pose_high[p] and np.count_nonzero(pose) == 1


def test_smoothstep() -> None:
    assert smoothstep(-1.0) == 0.0 and smoothstep(0.5) == 0.5 and smoothstep(2.0) == 1.0
