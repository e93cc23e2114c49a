"""BVH parser, joint-mapping profiles, glitches and resampling, on the shipped capture."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.errors import ConfigError, DataError
from handrig.offline import mocap
from handrig.offline.bvh import format_bvh, make_bvh, parse_bvh, read_bvh

REF = mocap.REFERENCE_BVH


def _common_joints() -> list[str]:
    names = ["Hips"]
    for side in ("Right", "Left"):
        for digit in hand.DIGITS:
            names += [f"{side}Hand{digit}{k}" for k in (1, 2, 3)]
    return names


def _synthetic(n: int = 40, seed: int = 0) -> tuple[list[str], np.ndarray]:
    joints = _common_joints()
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n)[:, None]
    motion = 20 * np.sin(t + rng.uniform(0, 6, size=(1, 3 * len(joints))))
    return joints, motion


def _write(tmp_path: Path, text: str, name: str = "x.bvh") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reference_file_parses_with_its_declared_shape() -> None:
    b = read_bvh(REF)
    assert b.motion.shape == (1063, 180)
    assert len(b.joints) == 59
    assert b.fps == pytest.approx(24.0, rel=1e-4)
    assert b.joints[0].name == "Hips" and b.joints[0].channels[:3] == (
        "Xposition", "Yposition", "Zposition")
    assert b.motion[0, 0] == pytest.approx(-0.61160)


def test_format_and_parse_round_trip() -> None:
    joints, motion = _synthetic()
    b = make_bvh(joints, motion)
    again = parse_bvh(format_bvh(b, decimals=6))
    assert again.joint_names == tuple(joints)
    np.testing.assert_allclose(again.motion, motion, atol=1e-6)


def test_reference_curves_follow_the_readme_table() -> None:
    raw = mocap.load_reference("raw")
    b = read_bvh(REF)
    c = raw.curves
    idx = hand.curve_index
    np.testing.assert_array_equal(c[:, idx("riIndexMCPy")],
                                  b.motion[:, b.column("RightHandIndex1", "Zrotation")])
    np.testing.assert_array_equal(c[:, idx("riThumbIPz")],
                                  b.motion[:, b.column("RightHandThumb3", "Yrotation")])
    np.testing.assert_array_equal(c[:, idx("leThumbIPz")],
                                  b.motion[:, b.column("LeftHandThumb3", "Zrotation")])
    # README facts: DIP equals PIP exactly; 6 curves range < 1, 9 under 5.
    np.testing.assert_array_equal(c[:, idx("riRingDIPy")], c[:, idx("riRingPIPy")])
    rng = np.ptp(c, axis=0)
    assert (rng < 1).sum() == 6
    assert (rng < 5).sum() == 9
    assert raw.glitches == ()


def test_vocabulary_convention_makes_flexion_positive_on_both_hands() -> None:
    voc = mocap.load_reference("vocabulary", condition=False).curves
    raw = mocap.load_reference("raw").curves
    for name in ("MiddleMCPy", "RingPIPy", "PinkyMCPy"):
        ri, le = hand.curve_index("ri" + name), hand.curve_index("le" + name)
        assert voc[:, ri].mean() > 0 and voc[:, le].mean() > 0
        np.testing.assert_allclose(voc[:, le], -raw[:, le])
    means = voc.mean(axis=0)
    lim = hand.curve_limits_deg()
    # riIndexPIPy's mean is -0.6: PN copies MCP flexion (which may hyperextend) to the PIP
    assert np.all((means > lim[:, 0] - 1.0) & (means < lim[:, 1]))


def test_common_profile_reads_a_skeleton_without_metacarpals(tmp_path: Path) -> None:
    joints, motion = _synthetic()
    p = _write(tmp_path, format_bvh(make_bvh(joints, motion)))
    m = mocap.load_curves(p, "common", "raw")
    col = 3 * joints.index("RightHandIndex1")  # ZXY: Zrotation first
    np.testing.assert_allclose(m.curves[:, hand.curve_index("riIndexMCPy")], motion[:, col],
                               atol=1e-5)


def test_missing_joint_names_the_joint_and_the_profile(tmp_path: Path) -> None:
    joints, motion = _synthetic()
    joints2 = [j for j in joints if j != "LeftHandPinky2"]
    keep = [i for i, j in enumerate(joints) if j != "LeftHandPinky2"]
    cols = [3 * i + k for i in keep for k in range(3)]
    p2 = _write(tmp_path, format_bvh(make_bvh(joints2, motion[:, cols])), "y.bvh")
    for prof in ("common", "perception_neuron"):
        with pytest.raises(DataError, match=rf"'LeftHandPinky2' \(curve lePinkyPIPy\).*'{prof}'"):
            mocap.load_curves(p2, prof)


def test_truncated_motion_says_at_which_frame(tmp_path: Path) -> None:
    joints, motion = _synthetic(n=10)
    lines = format_bvh(make_bvh(joints, motion)).splitlines()
    cut = len(lines) - 10 + 7  # frame 7 is cut in the middle, 8 and 9 are gone
    lines[cut] = " ".join(lines[cut].split()[:20])
    text = "\n".join(lines[: cut + 1]) + "\n"
    with pytest.raises(DataError, match=r"truncated at frame 7 .*10 frames"):
        parse_bvh(text, "cut.bvh")
    with pytest.raises(DataError, match=r"no MOTION block"):
        parse_bvh(text.split("MOTION")[0], "cut.bvh")


def test_bad_number_and_bad_hierarchy_are_located() -> None:
    joints, motion = _synthetic(n=5)
    text = format_bvh(make_bvh(joints, motion))
    lines = text.splitlines()
    lines[-2] = lines[-2].replace(lines[-2].split()[4], "abc", 1)
    with pytest.raises(DataError, match=r"frame 3: 'abc' is not a number"):
        parse_bvh("\n".join(lines))
    with pytest.raises(DataError, match=r"line 5: unknown channel 'Wrotation'"):
        parse_bvh(text.replace("Zrotation", "Wrotation", 1))


def test_spikes_and_nan_are_reported_refused_and_repaired(tmp_path: Path) -> None:
    joints, motion = _synthetic(n=50)
    col = 3 * joints.index("RightHandThumb3") + 2  # Yrotation = riThumbIPz in common
    truth = motion[20, col]
    motion[20, col] += 120.0  # a 120 degree single-frame spike
    nan_col = 3 * joints.index("LeftHandIndex1")  # Zrotation = leIndexMCPy
    motion[33, nan_col] = np.nan
    p = _write(tmp_path, format_bvh(make_bvh(joints, motion)).replace("nan", "NaN"))
    m = mocap.load_curves(p, "common", "raw")
    found = {(g.curve, g.frame, g.kind) for g in m.glitches}
    assert found == {("riThumbIPz", 20, "spike"), ("leIndexMCPy", 33, "nan")}
    with pytest.raises(DataError, match=r"riThumbIPz frame 20: .*--despike"):
        m.require_clean()
    fixed = mocap.load_curves(p, "common", "raw", despike=True)
    fixed.require_clean()
    assert len(fixed.glitches) == 2
    assert abs(fixed.curves[20, hand.curve_index("riThumbIPz")] - truth) < 3.0
    assert np.isfinite(fixed.curves).all()


def test_reference_has_no_false_glitches_even_with_a_low_threshold() -> None:
    raw = mocap.load_reference("raw").curves
    assert mocap.find_glitches(raw, spike_deg=25.0) == []


def test_resample_keeps_duration_and_is_linear() -> None:
    x = np.arange(25, dtype=np.float64)[:, None] * np.array([[1.0, -2.0]])  # 1 s at 24 fps
    y = mocap.resample(x, 24.0, 30.0)
    assert y.shape == (31, 2)
    np.testing.assert_allclose(y[:, 0], np.arange(31) * 24 / 30)
    m = mocap.load_curves(REF, fps=30.0)
    assert m.fps == 30.0 and m.n_frames == 1328


def test_profile_errors_name_file_and_key(tmp_path: Path) -> None:
    src = (mocap.PROFILE_DIR / "common.toml").read_text()
    bad = _write(tmp_path, src.replace("sign = { ri = 1, le = -1 } }", "sign = 2 }", 1),
                 "bad.toml")
    with pytest.raises(ConfigError, match=r"bad.toml: key 'template.ThumbCMCx.sign' = 2"):
        mocap.load_profile(bad)
    with pytest.raises(ConfigError, match=r"no profile 'nope'.*perception_neuron"):
        mocap.load_profile("nope")


def test_short_runs_of_spikes_are_found_but_real_steps_are_not() -> None:
    raw = np.tile(np.linspace(0, 10, 60)[:, None], (1, 50))
    raw[10:13, 4] += 110.0  # a 3-frame glitch on riThumbIPz
    raw[30:, 7] += 60.0  # a step that stays: a clip boundary, not a glitch
    raw[45:47, 20] -= 150.0  # 2 frames
    found = {(g.curve, g.frame) for g in mocap.find_glitches(raw)}
    assert found == {("riThumbIPz", 10), ("riThumbIPz", 11), ("riThumbIPz", 12),
                     ("riPinkyMCPx", 45), ("riPinkyMCPx", 46)}
    fixed = mocap.repair(raw, mocap.find_glitches(raw))
    np.testing.assert_allclose(fixed[:, 4], np.linspace(0, 10, 60))


def test_a_user_profile_with_a_prefix(tmp_path: Path) -> None:
    joints, motion = _synthetic()
    named = [j if j == "Hips" else f"mixamorig:{j}" for j in joints]
    p = _write(tmp_path, format_bvh(make_bvh(named, motion)))
    src = (mocap.PROFILE_DIR / "common.toml").read_text()
    prof = _write(tmp_path, src.replace('prefix = ""', 'prefix = "mixamorig:"')
                  .replace('name = "common"', 'name = "mixamo"'), "mixamo.toml")
    m = mocap.load_curves(p, prof, "vocabulary")
    assert m.profile == "mixamo"
    col = 3 * joints.index("LeftHandRing2")  # Zrotation; left flexion sign -1
    np.testing.assert_allclose(m.curves[:, hand.curve_index("leRingPIPy")], -motion[:, col],
                               atol=1e-5)
    with pytest.raises(DataError, match=r"'mixamorig:RightHandThumb1'.*'mixamo'"):
        mocap.load_curves(_write(tmp_path, format_bvh(make_bvh(joints, motion)), "plain.bvh"),
                          prof)
