"""The robust default map, checks at load, the training range, out-of-regime evaluation."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.cli import main
from handrig.config.loading import JointLimits
from handrig.errors import ConfigError, HandrigError
from handrig.offline import mocap
from handrig.offline.evaluation import (
    block_splits,
    calm_frames,
    out_of_regime,
    reference_splits,
    write_error_figure,
)
from handrig.offline.fitting import fit_map
from handrig.pose.expand import DEFAULT_MAP, DEFAULT_TWO_GLOVE_MAP, Expander
from handrig.pose.maps import DEFAULT_TWO_GLOVE_CONTROLS, LinearMap, MapWarning

CTRL = ("riIndexMCPy", "riPinkyMCPy", "leIndexMCPy")
I0, I1, I2 = (hand.curve_index(c) for c in CTRL)
T = hand.curve_index("riRingMCPy")
U = hand.curve_index("riMiddleMCPx")


def _data(n: int = 600, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = np.tile(np.linspace(5, 10, 50), (n, 1))
    y[:, I0] = 20 + 15 * rng.standard_normal(n)
    y[:, I1] = 30 + 10 * rng.standard_normal(n)
    noise = 2.0 * rng.standard_normal(n)
    y[:, T] = 5 + 2.0 * (y[:, I0] - 20) - 1.0 * (y[:, I1] - 30) + noise
    y[:, I2] = 4 + noise / 10  # a control that barely moves, by chance tied to the noise
    y[:, U] = 3 + rng.standard_normal(n)  # follows nothing
    return y


def test_robust_keeps_real_gains_and_refuses_a_barely_moving_control() -> None:
    y = _data()
    ridge = fit_map(y, CTRL, "ridge", alpha=0.0)
    robust = fit_map(y, CTRL, "robust")
    assert abs(ridge.gains[T, 2]) > 5.0  # least squares explains the noise by the tiny control
    assert abs(robust.gains[T, 2]) < 1.0
    np.testing.assert_allclose(robust.gains[T, :2], [2.0, -1.0], atol=0.05)
    assert not robust.gains[U].any() and robust.curve_means_deg[U] == pytest.approx(
        y[:, U].mean())  # held out, following lost to the mean: held at the mean
    assert "robust" in robust.fitting and "contiguous blocks" in robust.fitting
    rng = robust.control_range_deg
    assert rng is not None
    np.testing.assert_allclose(rng[:, 0], y[:, [I0, I1, I2]].min(axis=0))


def test_robust_uses_the_given_groups() -> None:
    y = _data()
    groups = np.repeat(np.arange(6), 100)
    m = fit_map(y, CTRL, "robust", groups=groups)
    assert "6 groups (clips)" in m.fitting
    with pytest.raises(Exception, match="one label per frame"):
        fit_map(y, CTRL, "robust", groups=groups[:10])


def _saved(tmp_path: Path) -> Path:
    return fit_map(_data(), CTRL, "ridge", alpha=0.0).save(tmp_path / "m.toml")


def test_a_huge_gain_is_refused_naming_file_and_key(tmp_path: Path) -> None:
    p = _saved(tmp_path)
    text = p.read_text()
    start = text.index("[curves.riRingMCPy]")
    line_start = text.index("gains = ", start)
    line_end = text.index("\n", line_start)
    p.write_text(text[:line_start] + "gains = { riIndexMCPy = 1e9 }" + text[line_end:])
    with pytest.raises(ConfigError, match=r"m\.toml: key 'curves\.riRingMCPy\.gains\.riIndexMCPy'"
                       r" = 1000000000\.0: gain is implausible"):
        LinearMap.load(p)


def test_gains_beyond_the_training_data_warn_then_refuse(tmp_path: Path) -> None:
    m = fit_map(_data(), CTRL, "ridge", alpha=0.0)
    span = np.diff(hand.curve_limits_deg()[T])[0]
    assert m.control_range_deg is not None
    width = np.diff(m.control_range_deg[1])[0]
    for factor, expect_error in ((4.0, False), (20.0, True)):
        g = m.gains.copy()
        g[T] = [0.0, factor * span / width, 0.0]
        p = LinearMap(**{**m.__dict__, "gains": g}).save(tmp_path / f"m{factor:g}.toml")
        if expect_error:
            with pytest.raises(ConfigError, match=r"curves\.riRingMCPy\.gains.*training range"):
                LinearMap.load(p)
        else:
            with pytest.warns(MapWarning, match=r"m4\.toml: key 'curves\.riRingMCPy\.gains'"):
                LinearMap.load(p)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: "\x00\xff not toml [[[", r"not valid TOML"),
        (lambda t: t.replace("gains = { riIndexMCPy = 2.0",
                             'gains = { riIndexMCPy = "2.0"'), r"expected a number"),
        (lambda t: t.replace("control_range_deg = [[", "control_range_deg = [[0.0, 1.0], ["),
         r"control_range_deg.*one \[low, high\] per control"),
        (lambda t: re.sub(r"control_range_deg = \[\[[^,]+,", "control_range_deg = [[1e6,", t),
         r"control_range_deg\[0\].*inverted range"),
        (lambda t: t.replace("control_means_deg = [", "control_means_deg = [-900.0, 0.0, 0.0]"
                             " #"), r"control_range_deg\[0\].*outside its training range"),
        (lambda t: t.replace("mean_deg = ", "mean_deg = nan #", 1), r"finite number"),
        (lambda t: t.replace("[curves.riRingMCPy]\nmean_deg = ", "[curves.riRingMCPy]\nmean_deg"
                             " = 4000.0 #"), r"curves\.riRingMCPy\.mean_deg.*not a pose"),
        (lambda t: t[: len(t) // 2], r"(not valid TOML|missing)"),
    ],
)
def test_corrupt_map_files_give_one_message_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], edit: object, match: str
) -> None:
    p = _saved(tmp_path)
    p.write_text(edit(p.read_text()))  # type: ignore[operator]
    with pytest.raises(ConfigError, match=r"m\.toml.*" + match):
        LinearMap.load(p)
    ref = str(mocap.REFERENCE_BVH)
    assert main(["expand", "--map", str(p), ref, "--out", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert "m.toml" in err and "Traceback" not in err


def test_expander_counts_frames_outside_the_training_range() -> None:
    m = fit_map(_data(), CTRL, "ridge", alpha=0.0)
    ex = Expander(m, JointLimits(), range_margin_deg=1.0)
    assert m.control_range_deg is not None
    inside = m.control_means_deg.copy()
    high = m.control_range_deg[:, 1]
    out = np.empty(50)
    for _ in range(3):
        ex.expand(inside, out=out)
    ex.expand(np.array([high[0] + 0.5, inside[1], inside[2]]), out=out)  # within the margin
    ex.expand(np.array([high[0] + 2.0, inside[1], high[2] + 5.0]), out=out)
    rep = ex.training_range()
    assert rep.known and rep.frames == 5 and rep.outside_frames == 1
    assert rep.outside_by_control == {"riIndexMCPy": 1, "riPinkyMCPy": 0, "leIndexMCPy": 1}
    assert rep.outside_fraction == pytest.approx(0.2)
    assert "1 of 5 frames" in rep.summary() and "calibration" in rep.summary()
    ex.expand_many(np.tile(np.array([high[0] + 2.0, inside[1], inside[2]]), (4, 1)))
    assert ex.training_range().outside_frames == 5 and ex.training_range().frames == 9
    assert ex.note_controls(inside) is False
    assert ex.note_controls(np.array([inside[0], high[1] + 3.0, inside[2]])) is True
    assert ex.training_range().outside_by_control["riPinkyMCPy"] == 1
    ex.reset_training_range()
    assert ex.training_range().frames == 0 and ex.training_range().outside_frames == 0
    old = LinearMap(**{**m.__dict__, "control_range_deg": None})
    ex_old = Expander(old, JointLimits())
    ex_old.expand(high + 100.0)
    assert not ex_old.training_range().known and ex_old.training_range().outside_frames == 0
    assert "unknown" in ex_old.training_range().summary()


def test_calm_frames_are_still_stretches_within_each_group() -> None:
    n = 200
    y = np.zeros((n, 50))
    t = np.arange(n) / 24.0
    y[:100, :25] = 30 * np.sin(2 * np.pi * t[:100])[:, None]  # moving
    y[100:, :25] = 10.0 + 0.01 * np.arange(100)[:, None]  # still
    calm = calm_frames(y, 24.0, np.zeros(n, dtype=np.intp))
    assert not calm[10:90].any() and calm[110:].all()


def test_out_of_regime_splits_methods_and_figure(tmp_path: Path) -> None:
    ref = mocap.load_reference()
    y = ref.curves[:400]
    splits, groups = block_splits(y, ref.fps, 4)
    assert [s.name for s in splits] == ["clips", "calm", "calm-unseen", "offset"]
    res = out_of_regime(y, ("riIndexMCPy", "riPinkyMCPy"), splits, groups, ("mean", "paper"))
    assert set(res) == {s.name for s in splits} and set(res["clips"]) == {"mean", "paper"}
    assert res["clips"]["paper"].ri < res["clips"]["mean"].ri
    # an offset moves the controls (passed through) and what follows them, not the mean map's
    assert res["offset"]["mean"].per_curve[hand.curve_index("riRingMCPy")] == pytest.approx(
        res["clips"]["mean"].per_curve[hand.curve_index("riRingMCPy")])
    png = write_error_figure(res, tmp_path / "fig.png", title="t")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    full, labels = reference_splits(ref.curves, ref.fps)
    assert [s.name for s in full] == ["clips", "kinds", "calm", "calm-unseen", "offset"]
    assert len(full[0].folds) == 15 and len(full[1].folds) == 3 and labels.max() == 14


def test_shipped_maps_are_piecewise_and_say_how_they_were_fit() -> None:
    for path, k in ((DEFAULT_MAP, 5), (DEFAULT_TWO_GLOVE_MAP, 10)):
        with warnings.catch_warnings():
            warnings.simplefilter("error", MapWarning)
            m = LinearMap.load(path)
        assert m.method == "piecewise" and len(m.controls) == k and m.piecewise
        assert m.control_range_deg is not None and m.frames == 1063
        assert "hinge at its training median" in m.fitting
        assert [e.split(" ")[0] for e in m.evaluation] == [
            "clips", "kinds", "calm", "calm-unseen", "offset", "blocked", "blocked-calm",
            "blocked-offset", "other-hand"]


def test_robust_never_hurts_when_the_controls_are_off() -> None:
    """Two gloves on the reference: the offset split is where ridge is worse than the mean."""
    ref = mocap.load_reference()
    splits, groups = reference_splits(ref.curves, ref.fps)
    chosen = [s for s in splits if s.name in ("clips", "offset")]
    res = out_of_regime(ref.curves, DEFAULT_TWO_GLOVE_CONTROLS, chosen, groups,
                        ("mean", "paper", "ridge", "robust"))
    clips, off = res["clips"], res["offset"]
    assert off["ridge"].ri > 0.8 * off["mean"].ri  # the failure this method exists for
    assert off["robust"].ri <= 1.05 * off["paper"].ri and off["robust"].ri < 0.6 * off[
        "mean"].ri
    assert clips["robust"].ri < 0.8 * clips["paper"].ri
    assert clips["robust"].ri < clips["ridge"].ri + 0.3


def test_expand_command_reports_the_training_range(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ref = str(mocap.REFERENCE_BVH)
    assert main(["expand", "--map", str(DEFAULT_MAP), ref, "--out", str(tmp_path / "o.csv")]) == 0
    assert "inside the map's training range in all 1063 frames" in capsys.readouterr().out


def test_randomly_damaged_map_files_never_raise_anything_but_a_handrig_error(
    tmp_path: Path,
) -> None:
    text = _saved(tmp_path).read_text()
    rng = np.random.default_rng(7)
    alphabet = list("[]{}=\"#,.0123456789-e\n abcxyz")
    p = tmp_path / "damaged.toml"
    for _ in range(150):
        chars = list(text)
        for pos in rng.integers(0, len(chars), size=int(rng.integers(1, 6))):
            chars[pos] = str(rng.choice(alphabet))
        p.write_text("".join(chars))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MapWarning)
            try:
                LinearMap.load(p)
            except HandrigError as exc:
                assert "damaged.toml" in str(exc)


def test_fit_map_on_two_files_groups_each_files_blocks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from handrig.offline.bvh import Bvh, format_bvh, read_bvh

    b = read_bvh(mocap.REFERENCE_BVH)
    files = []
    for i, (a, z) in enumerate(((0, 300), (300, 700))):
        p = tmp_path / f"part{i}.bvh"
        p.write_text(format_bvh(Bvh(b.joints, b.frame_time_s, b.motion[a:z])))
        files.append(str(p))
    out = tmp_path / "m.toml"
    assert main(["fit-map", *files, "--out", str(out), "--evaluate", "--method", "robust"]) == 0
    m = LinearMap.load(out)
    assert m.method == "robust" and m.frames == 700
    assert "10 groups (5 contiguous blocks per file)" in m.fitting
    assert m.evaluation[0].startswith("clips (leave one block out): robust")
    assert "contiguous blocks of the concatenated files" in capsys.readouterr().out
