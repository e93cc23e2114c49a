"""The blocked validation's splits (issue 42): gaps kept out of training, the other hand
mirrored, each fold's figure kept, and what `handrig evaluate` prints of them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.cli import main
from handrig.errors import DataError
from handrig.offline import mocap
from handrig.offline.bvh import Bvh, format_bvh, read_bvh
from handrig.offline.evaluation import out_of_regime
from handrig.offline.validation import (
    best_methods,
    blocked_folds,
    blocked_splits,
    spread,
    validation_table,
)


@pytest.mark.parametrize(("n", "fps", "count", "gap_s"),
                         [(1063, 24.0, 5, 2.0), (400, 30.0, 4, 0.5), (97, 10.0, 3, 0.0)])
def test_a_blocked_split_never_trains_within_the_gap_of_its_test_block(
        n: int, fps: float, count: int, gap_s: float) -> None:
    folds = blocked_folds(n, fps, count, gap_s)
    gap = round(gap_s * fps)
    assert len(folds) == count
    tested = np.zeros(n, dtype=int)
    for train, test in folds:
        assert not (train & test).any()
        t = np.flatnonzero(test)
        assert len(t) and np.array_equal(t, np.arange(t[0], t[-1] + 1))  # one stretch
        tr = np.flatnonzero(train)
        dist = np.min(np.abs(tr[:, None] - t[None, :]))
        assert dist > gap  # no training frame within the gap of a test frame
        # and the gap is as narrow as it says: the frames just beyond it train
        beyond = [f for f in (t[0] - gap - 1, t[-1] + gap + 1) if 0 <= f < n]
        assert all(train[f] for f in beyond)
        tested += test
    assert np.all(tested == 1)  # every frame tested exactly once


def test_blocked_folds_refuse_what_cannot_be_split() -> None:
    with pytest.raises(DataError, match="blocks"):
        blocked_folds(100, 24.0, 1)
    with pytest.raises(DataError, match="no training frames"):
        blocked_folds(100, 24.0, 2, gap_s=10.0)
    with pytest.raises(DataError, match="frame rate"):
        blocked_folds(100, 0.0, 4)


def _two_hands(n: int = 400, left_ring: tuple[float, float] = (1.5, -0.5)) -> np.ndarray:
    """Each hand with controls of its own (the same swing, another phase); the thumb IP
    follows the same law of its hand's controls on both hands, the ring PIP the right's
    law (1.5, -0.5) on the right and ``left_ring`` on the left."""
    y = np.tile(np.linspace(-5.0, 5.0, 50), (n, 1))
    t = np.arange(n, dtype=np.float64)
    for side, phase, ring in (("ri", 0.0, (1.5, -0.5)), ("le", 2.0, left_ring)):
        a = 15 + 10 * np.sin(t / 9 + phase)
        b = 15 + 8 * np.cos(t / 11 + 2 * phase)
        y[:, hand.curve_index(side + "IndexMCPy")] = a
        y[:, hand.curve_index(side + "PinkyMCPy")] = b
        y[:, hand.curve_index(side + "RingPIPy")] = 30 + ring[0] * (a - 15) + ring[1] * (b - 15)
        y[:, hand.curve_index(side + "ThumbIPz")] = 10 - 0.7 * (b - 15)
    return y


def test_the_other_hand_split_drives_each_hand_from_the_other_hands_curves() -> None:
    y = _two_hands(left_ring=(-0.5, 1.0))
    ctrl = ("riIndexMCPy", "riPinkyMCPy")
    calm = np.zeros(len(y), dtype=bool)
    splits = [s for s in blocked_splits(len(y), 24.0, calm, 4, 0.5) if s.name == "other-hand"]
    assert [s.mirrored for s in splits] == [True]
    err = out_of_regime(y, ctrl, splits, np.zeros(len(y), dtype=np.intp),
                        ("ridge",))["other-hand"]["ridge"]
    # the right-glove map, fed the left hand's controls: the thumb, whose law the hands
    # share, comes out as the left thumb; the ring, whose law differs, does not
    assert err.per_curve[hand.curve_index("riThumbIPz")] < 0.2
    assert err.per_curve[hand.curve_index("riRingPIPy")] > 5.0
    assert len(err.ri_folds) == 4
    # with the same law on both hands the left ring is reproduced too
    same = out_of_regime(_two_hands(), ctrl, splits, np.zeros(len(y), dtype=np.intp),
                         ("ridge",))["other-hand"]["ridge"]
    assert same.per_curve[hand.curve_index("riRingPIPy")] < 0.2


def test_mirror_pose_swaps_the_hands_curve_by_curve() -> None:
    pose = np.arange(50, dtype=np.float64)
    m = hand.mirror_pose(pose)
    for name in hand.CURVE_NAMES:
        assert m[hand.curve_index(name)] == pose[hand.curve_index(hand.mirror_name(name))]
    assert np.array_equal(hand.mirror_pose(m), pose)


def test_spread_and_best_methods_and_the_table() -> None:
    assert spread(()) == (0.0, 0.0)
    sd, worst = spread((1.0, 3.0))
    assert sd == pytest.approx(1.0) and worst == 3.0
    y = _two_hands(300)
    calm = np.zeros(len(y), dtype=bool)
    calm[::3] = True
    splits = blocked_splits(len(y), 24.0, calm, 3, 0.25)
    assert [s.name for s in splits] == ["blocked", "blocked-calm", "blocked-offset",
                                        "other-hand"]
    res = out_of_regime(y, ("riIndexMCPy", "riPinkyMCPy"), splits,
                        np.zeros(len(y), np.intp), ("mean", "ridge"))
    assert best_methods(res) == {s.name: "ridge" for s in splits}
    lines = validation_table(res, splits)
    assert len(lines) == 1 + 2 * len(splits)
    row = next(x for x in lines if x.split()[:2] == ["blocked", "ridge"])
    err = res["blocked"]["ridge"]
    assert float(row.split()[2]) == pytest.approx(err.ri, abs=0.006)
    assert float(row.split()[4]) == pytest.approx(max(err.ri_folds), abs=0.006)


def test_evaluate_prints_the_blocked_validation_with_spreads(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b = read_bvh(mocap.REFERENCE_BVH)
    p = tmp_path / "part.bvh"
    p.write_text(format_bvh(Bvh(b.joints, b.frame_time_s, b.motion[300:700])))
    args = ["evaluate", str(p), "--folds", "4", "--gap-s", "1", "--methods", "mean,paper"]
    assert main([*args, "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    val = obj["validation"]
    assert set(val) == {"blocked", "blocked-calm", "blocked-offset", "other-hand"}
    paper = val["blocked"]["methods"]["paper"]
    assert len(paper["ri_folds_rms_deg"]) == 4
    assert paper["ri_worst_fold_deg"] == max(paper["ri_folds_rms_deg"])
    assert paper["ri_rms_deg"] < val["blocked"]["methods"]["mean"]["ri_rms_deg"]
    assert obj["validation_best"]["blocked"] == "paper"
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "4 blocks of time held out, 1 s on each side" in text
    assert "  other-hand      paper" in text and "worst" in text
