"""The easing on its own: smoothstep from what was sent, restartable, a moving target."""

from __future__ import annotations

import numpy as np
import pytest

from handrig.loop.easing import Easing


def test_eases_from_what_was_sent_to_the_target_with_zero_speed_at_both_ends() -> None:
    e = Easing(2, 3, duration_s=1.0)
    sent, to = np.array([0.0, 10.0]), np.array([10.0, -10.0])
    path = []
    for k in range(0, 201):
        goals, done = e.goals(5.0 + k * 0.005, sent, None, to)
        path.append(goals.copy())
        sent = goals.copy()
        assert done == (k >= 200)
    path_a = np.array(path)
    np.testing.assert_allclose(path_a[0], [0.0, 10.0])
    np.testing.assert_allclose(path_a[-1], to)
    steps = np.abs(np.diff(path_a[:, 0]))
    assert steps[0] < 0.01 and steps[-1] < 0.01 and steps.max() == pytest.approx(
        1.5 * 10.0 / 1.0 * 0.005, rel=0.02)


def test_restart_starts_over_from_the_goals_given_then_and_the_pose_follows() -> None:
    e = Easing(1, 2, duration_s=0.5)
    e.goals(0.0, np.array([0.0]), np.array([1.0, 1.0]), np.array([4.0]))
    goals, _ = e.goals(0.25, np.array([9.0]), None, np.array([4.0]))
    assert goals[0] == pytest.approx(2.0)  # halfway from 0 (the start), not from 9
    np.testing.assert_allclose(e.pose(np.array([3.0, 5.0])), [2.0, 3.0])
    e.restart()
    assert not e.started
    goals, _ = e.goals(1.0, np.array([9.0]), None, np.array([4.0]))
    assert goals[0] == 9.0
    np.testing.assert_allclose(e.pose(np.array([3.0, 5.0])), [3.0, 5.0])  # no pose: target
