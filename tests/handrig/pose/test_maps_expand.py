"""Linear maps (fit, file, validation), the runtime Expander and the map commands."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.cli import main
from handrig.config.loading import JointLimits
from handrig.errors import ConfigError, DataError
from handrig.offline import mocap
from handrig.offline.bvh import Bvh, format_bvh, read_bvh
from handrig.offline.evaluation import cross_validate
from handrig.offline.fitting import fit_map
from handrig.pose.expand import DEFAULT_MAP, DEFAULT_TWO_GLOVE_MAP, Expander
from handrig.pose.maps import DEFAULT_RIGHT_CONTROLS, LinearMap

CTRL = ("riIndexMCPy", "riPinkyMCPy")
I0, I1 = hand.curve_index(CTRL[0]), hand.curve_index(CTRL[1])
T = hand.curve_index("riRingMCPy")


def _data(n: int = 500, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = np.tile(np.linspace(5, 10, 50), (n, 1))
    y[:, I0] = 20 + 15 * rng.standard_normal(n)
    y[:, I1] = 30 + 10 * rng.standard_normal(n)
    y[:, T] = 5 + 2.0 * (y[:, I0] - 20) - 1.0 * (y[:, I1] - 30)
    return y


def test_ridge_recovers_exact_linear_gains() -> None:
    m = fit_map(_data(), CTRL, "ridge", alpha=0.0)
    np.testing.assert_allclose(m.gains[T], [2.0, -1.0], atol=1e-9)
    assert m.predict(np.array([[20.0, 30.0]]))[0, T] == pytest.approx(5.0, abs=1e-9)
    np.testing.assert_array_equal(m.gains[[I0, I1]], np.eye(2))  # controls pass through
    y = _data()
    assert m.curve_range_deg is not None  # the output is clipped inside the joints:
    lo, hi = m.curve_range_deg[T]  # exact wherever the synthetic curve is inside them
    inside = (y[:, T] >= lo) & (y[:, T] <= hi)
    assert 0.5 < inside.mean() < 1.0
    np.testing.assert_allclose(m.predict(y[:, [I0, I1]])[inside, T], y[inside, T], atol=1e-9)


def test_paper_map_preserves_mean_and_std_and_picks_best_control() -> None:
    y = _data()
    y[:, T] = 40 - 0.5 * (y[:, I1] - 30)  # follows pinky with a negative slope
    m = fit_map(y, CTRL, "paper")
    assert m.gains[T, 0] == 0.0
    assert m.gains[T, 1] == pytest.approx(-y[:, T].std() / y[:, I1].std())
    pred = m.predict(y[:, [I0, I1]])[:, T]
    assert pred.mean() == pytest.approx(y[:, T].mean()) and pred.std() == pytest.approx(
        y[:, T].std())
    assert not m.gains[0].any()  # range 0 < 1: its mean


def test_huber_resists_outliers_that_pull_least_squares() -> None:
    y = _data(seed=3)
    y[:, T] += np.random.default_rng(4).normal(0, 0.5, len(y))
    y[::20, T] += 100.0  # 5 % of frames with 100 degree errors
    ridge = fit_map(y, CTRL, "ridge", alpha=0.0)
    huber = fit_map(y, CTRL, "huber", alpha=0.0)
    truth = np.array([2.0, -1.0])
    assert np.abs(huber.gains[T] - truth).max() < 0.05
    at_truth = np.array([[20.0, 30.0]])
    assert abs(huber.predict(at_truth)[0, T] - 5.0) < 0.5
    assert abs(ridge.predict(at_truth)[0, T] - 5.0) > 4.0


@pytest.mark.filterwarnings("ignore::handrig.pose.maps.MapWarning")  # synthetic gains swing widely
def test_map_file_round_trip_is_readable(tmp_path: Path) -> None:
    m = fit_map(_data(), CTRL, "ridge", alpha=0.0, trained_on=("a.bvh",))
    p = m.save(tmp_path / "m.toml")
    text = p.read_text()
    assert "[curves.riRingMCPy]" in text and "riIndexMCPy = 2.0" in text
    back = LinearMap.load(p)
    assert back.controls == CTRL and back.trained_on == ("a.bvh",)
    x = _data(seed=9)[:, [I0, I1]]
    np.testing.assert_allclose(back.predict(x), m.predict(x), atol=2e-3)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: t.replace("[curves.leRingDIPy]", "[curves.leRingDIPx]"),
         r"key 'curves.leRingDIPx'"),
        (lambda t: t.replace('"riPinkyMCPy"]', '"riPinkyMCPq"]'), r"controls\[1\].*riPinkyMCPq"),
        (lambda t: t.replace("riIndexMCPy = 2.0", "riThumbIPz = 2.0"),
         r"curves.riRingMCPy.gains.riThumbIPz.*gain on a name that is not a control"),
        (lambda t: t.replace('format = "handrig-linear-map"', 'format = "x"'), r"key 'format'"),
        (lambda t: t.replace("control_means_deg = [", "control_means_deg = [1.0, "),
         r"control_means_deg"),
    ],
)
def test_bad_map_files_name_file_and_key(tmp_path: Path, edit: object, match: str) -> None:
    p = fit_map(_data(), CTRL, "ridge", alpha=0.0).save(tmp_path / "m.toml")
    p.write_text(edit(p.read_text()))  # type: ignore[operator]
    with pytest.raises(ConfigError, match=r"m\.toml: .*" + match):
        LinearMap.load(p)


def test_expander_matches_the_map_clamps_and_reuses_buffers() -> None:
    m = fit_map(_data(), CTRL, "ridge", alpha=0.0)
    ex = Expander(m, JointLimits())
    assert ex.controls == CTRL and ex.curve_names == hand.CURVE_NAMES
    lim = hand.curve_limits_deg()
    x = np.array([[20.0, 30.0], [80.0, -15.0], [-60.0, 200.0]])
    want = np.clip(m.predict(x), lim[:, 0], lim[:, 1])
    many = ex.expand_many(x)
    np.testing.assert_allclose(many, want, atol=1e-9)
    out = np.empty(50)
    for row, w in zip(x, want, strict=True):
        got = ex.expand(row, out=out)
        assert got is out
        np.testing.assert_allclose(got, w, atol=1e-9)
    assert ex.expand(x[0]) is ex.expand(x[1])  # the expander's own buffer, reused
    assert np.all(many >= lim[:, 0]) and np.all(many <= lim[:, 1])
    assert np.all(many[2] == np.clip(many[2], lim[:, 0], lim[:, 1]))
    with pytest.raises(DataError, match=r"expected 2 control values"):
        ex.expand(np.zeros(3))


def test_shipped_default_maps() -> None:
    ex = Expander.from_file()
    assert ex.controls == DEFAULT_RIGHT_CONTROLS
    assert ex.control_means_deg.shape == (5,)
    ref = mocap.load_reference()
    np.testing.assert_allclose(ex.control_means_deg,
                               ref.curves[:, [hand.curve_index(c) for c in ex.controls]].mean(0),
                               atol=1e-3)
    pose = ex.expand(ex.control_means_deg.copy())
    assert pose.shape == (50,)
    two = Expander.from_file(DEFAULT_TWO_GLOVE_MAP)
    assert len(two.controls) == 10 and two.controls[5:] == tuple(
        hand.mirror_name(c) for c in DEFAULT_RIGHT_CONTROLS)
    assert LinearMap.load(DEFAULT_MAP).method == "piecewise"


def test_ridge_beats_the_paper_on_unseen_gestures() -> None:
    ref = mocap.load_reference()
    folds = [(a, b + 1) for _, a, b in mocap.REFERENCE_CLIPS]
    res = cross_validate(ref.curves, DEFAULT_RIGHT_CONTROLS, folds, ("ridge", "paper", "mean"))
    assert res["ridge"].ri < res["paper"].ri < res["mean"].ri
    assert res["ridge"].ri < 0.5 * res["mean"].ri


def test_fit_expand_evaluate_commands(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ref = str(mocap.REFERENCE_BVH)
    out_map = tmp_path / "m.toml"
    assert main(["fit-map", ref, "--controls", "riThumbCMCz,riIndexMCPy", "--out",
                 str(out_map), "--method", "huber"]) == 0
    assert LinearMap.load(out_map).method == "huber"
    csv_path = tmp_path / "pred.csv"
    assert main(["expand", "--map", str(out_map), ref, "--out", str(csv_path)]) == 0
    with csv_path.open() as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == hand.CURVE_NAMES and len(rows) == 1064
    vals = np.array(rows[1:], dtype=float)
    lim = hand.curve_limits_deg()
    assert np.all(vals >= lim[:, 0]) and np.all(vals <= lim[:, 1])
    capsys.readouterr()
    assert main(["evaluate", "--map", str(out_map), ref, "--json", "--no-compare"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["in_sample"] is True and obj["map_errors"]["ri_rms_deg"] > 0
    assert set(obj["map_errors"]["per_curve_rms_deg"]) == set(hand.CURVE_NAMES)


def test_fitting_refuses_glitches_until_despiked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    b = read_bvh(mocap.REFERENCE_BVH)
    motion = b.motion[:200].copy()
    motion[50, b.column("RightHandThumb3", "Yrotation")] = 150.0  # impossible IP spike
    spiky = Bvh(b.joints, b.frame_time_s, motion)
    p = tmp_path / "spiky.bvh"
    p.write_text(format_bvh(spiky))
    out = tmp_path / "m.toml"
    assert main(["fit-map", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "riThumbIPz frame 50" in err and "--despike" in err
    assert main(["fit-map", str(p), "--out", str(out), "--despike"]) == 0
    assert main(["expand", "--map", str(out), str(p), "--out", "-"]) == 0


def test_evaluate_compares_methods_on_held_out_blocks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    b = read_bvh(mocap.REFERENCE_BVH)
    p = tmp_path / "part.bvh"
    p.write_text(format_bvh(Bvh(b.joints, b.frame_time_s, b.motion[300:700])))
    fig = tmp_path / "err.png"
    assert main(["evaluate", str(p), "--json", "--folds", "4", "--figure", str(fig)]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["figure"] == str(fig) and fig.stat().st_size > 10000
    assert obj["in_sample"] is False
    assert "4 contiguous blocks" in obj["held_out"]["scheme"]
    meth = obj["held_out"]["methods"]
    assert set(meth) == {"robust", "ridge", "paper", "mean", "piecewise"}
    assert set(obj["out_of_regime"]) == {"clips", "calm", "calm-unseen", "offset"}
    assert meth["ridge"]["ri_rms_deg"] < meth["mean"]["ri_rms_deg"]
    assert main(["evaluate", str(p), "--folds", "1"]) == 2
    assert "folds" in capsys.readouterr().err
    assert main(["evaluate", str(p), "--folds", "3", "--methods", "mean,paper"]) == 0
    text = capsys.readouterr().out
    assert "offset: leave one block out, every control off by 2 deg" in text
    assert "  offset       paper" in text and "right hand" in text and "left hand" in text
    assert main(["evaluate", str(p), "--methods", "mean,lasso"]) == 2
    assert "lasso" in capsys.readouterr().err
