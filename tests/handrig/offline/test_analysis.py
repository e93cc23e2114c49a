"""Sections 4-5 of Jörg & O'Sullivan against hand-derived counts and the reference capture."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.cli import main
from handrig.offline import analysis, mocap

N = 400
T = 2 * np.pi * np.arange(N) / N
S, C = np.sin(T), np.cos(T)  # exactly orthogonal over whole periods


def _toy() -> np.ndarray:
    """A, B = A scaled, C = -A scaled, D orthogonal to A, E = D small, F tiny, G at r=0.92."""
    x = np.full((N, 50), 7.0)
    x[:, 0] = 10 * S  # A, range 20
    x[:, 1] = 5 * S + 2  # B: rmsd1(A, B) = 0
    x[:, 2] = -3 * S  # C: rmsd2(A, C) = 0, range 6
    x[:, 3] = 10 * C  # D: rmsd1(A, D) = rmsd2 = sqrt(2); same std as A (tie, A wins)
    x[:, 4] = 2 * C  # E: range 4, rmsd1(D, E) = 0
    x[:, 5] = 0.3 * S  # F: range 0.6 < 1
    x[:, 6] = 8 * (0.92 * S + np.sqrt(1 - 0.92**2) * C)  # G: r(A, G) = 0.92, rmsd1 = 0.4
    return x


def test_toy_counts_derived_by_hand() -> None:
    an = analysis.analyze(_toy())
    assert [s.dofs_left for s in an.stages] == [50, 6, 3, 5, 2]
    assert [s.condition for s in an.stages] == [
        "original", "range<1", "range<1 + rmsd<0.3", "range<5", "range<5 + rmsd<0.5"]
    # among A B C D E G: rmsd1<0.3 {AB, DE}; rmsd2<0.3 {AC, BC};
    # rmsd1<0.5 adds AG, BG; rmsd2<0.5 adds CG.
    assert an.pairs_below == {"0.3": {"rmsd1": 2, "rmsd2": 2}, "0.5": {"rmsd1": 4, "rmsd2": 3}}
    n = hand.CURVE_NAMES
    links2 = {(lk.dependent, lk.controller, lk.slope) for lk in an.stages[2].links}
    assert links2 == {(n[1], n[0], 1), (n[2], n[0], -1), (n[4], n[3], 1)}
    links4 = {(lk.dependent, lk.controller) for lk in an.stages[4].links}
    assert links4 == {(n[1], n[0]), (n[2], n[0]), (n[6], n[0])}
    assert an.rmsd1[0, 6] == pytest.approx(0.4, abs=1e-9)
    assert an.rmsd1[0, 3] == pytest.approx(np.sqrt(2))


def test_rmsd_identities_match_the_direct_definition() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(size=(300, 6)) @ rng.normal(size=(6, 6))
    x[:, 5] = 3.0  # constant: standardises to zeros, no NaN
    r1, r2 = analysis.rmsd_matrices(x)
    z = analysis.standardise(x)
    for a in range(6):
        for b in range(6):
            assert r1[a, b] == pytest.approx(np.sqrt(np.mean((z[:, a] - z[:, b]) ** 2)), abs=1e-7)
            assert r2[a, b] == pytest.approx(np.sqrt(np.mean((z[:, a] + z[:, b]) ** 2)), abs=1e-7)
    assert np.isfinite(r1).all() and np.isfinite(r2).all()
    assert r1[0, 5] == pytest.approx(1.0)
    assert z.std(axis=0)[:5] == pytest.approx(np.ones(5))  # population std


def test_chain_rule_passes_the_controller_on() -> None:
    x = np.full((N, 50), 1.0)
    th = np.arccos(0.97)
    x[:, 0] = 10 * S  # c
    x[:, 1] = 8 * (np.cos(th) * S + np.sin(th) * C)  # b: rmsd1(b, c) = 0.245
    x[:, 2] = 6 * (np.cos(2 * th) * S + np.sin(2 * th) * C)  # a: rmsd1(a, b) 0.245, (a, c) 0.486
    an = analysis.analyze(x)
    (la,) = [lk for lk in an.stages[2].links if lk.dependent == hand.CURVE_NAMES[2]]
    assert la.partner == hand.CURVE_NAMES[1] and la.controller == hand.CURVE_NAMES[0]
    assert la.rmsd == pytest.approx(np.sqrt(2 - 2 * np.cos(2 * th)))
    assert an.stages[2].dofs_left == 1
    rebuilt = analysis.rebuild(x, an.stages[2])
    assert rebuilt[:, 2].mean() == pytest.approx(x[:, 2].mean())
    assert rebuilt[:, 2].std() == pytest.approx(x[:, 2].std())


def test_reference_capture_stages_match_its_readme() -> None:
    an = analysis.analyze(mocap.load_reference("raw").curves)
    d = [s.dofs_left for s in an.stages]
    assert d[:2] == [50, 44] and d[3] == 41  # README: 6 curves under 1 deg, 9 under 5
    links = {lk.dependent: lk.controller for lk in an.stages[2].links}
    assert links["riRingDIPy"] == "riRingPIPy"  # DIP equals PIP exactly
    assert d[2] < d[1] and d[4] < d[3]


def test_analyze_cli_json_and_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ref = str(mocap.REFERENCE_BVH)
    assert main(["analyze", ref, "--json", "--out", str(tmp_path)]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["frames"] == 1063 and obj["curves"] == list(hand.CURVE_NAMES)
    assert [s["dofs_left"] for s in obj["stages"]][:2] == [50, 44]
    assert set(obj["pairs_below"]) == {"0.3", "0.5"}
    assert set(obj["pairs_below"]["0.3"]) == {"rmsd1", "rmsd2"}
    md = (tmp_path / "report.md").read_text()
    assert "Table 5" in md and "| range<5 + rmsd<0.5 |" in md
    for png in ("ranges", "rmsd1", "rmsd2", "strongest_pairs", "rebuilt"):
        assert (tmp_path / f"{png}.png").stat().st_size > 1000


def test_analyze_cli_reports_bad_input_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    assert main(["analyze", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.bvh" in err and "MOTION" in err and "Traceback" not in err


def _naive_counts(x: np.ndarray) -> tuple[list[int], dict[str, dict[str, int]]]:
    """Sections 4-5 written out pair by pair from the definitions (slow, obvious)."""
    n, k = x.shape
    rng = x.max(axis=0) - x.min(axis=0)
    std = np.array([np.sqrt(np.mean((x[:, i] - x[:, i].mean()) ** 2)) for i in range(k)])
    z = np.zeros_like(x)
    for i in range(k):
        if rng[i] > 0:
            z[:, i] = (x[:, i] - x[:, i].mean()) / std[i]

    def rmsd(a: int, b: int, sign: float) -> float:
        return float(np.sqrt(np.sum((z[:, a] + sign * z[:, b]) ** 2) / n))

    def dofs(range_min: float, t: float) -> int:
        keep = [i for i in range(k) if rng[i] >= range_min]
        dependent = set()
        for a in keep:
            for b in keep:
                larger = std[b] > std[a] or (std[b] == std[a] and b < a)
                if a != b and larger and min(rmsd(a, b, -1), rmsd(a, b, 1)) < t:
                    dependent.add(a)
        return len(keep) - len(dependent)

    keep1 = [i for i in range(k) if rng[i] >= 1]
    pairs = {}
    for t in (0.3, 0.5):
        c1 = sum(rmsd(a, b, -1) < t for i, a in enumerate(keep1) for b in keep1[i + 1:])
        c2 = sum(rmsd(a, b, 1) < t for i, a in enumerate(keep1) for b in keep1[i + 1:])
        pairs[f"{t:g}"] = {"rmsd1": c1, "rmsd2": c2}
    stages = [k, len(keep1), dofs(1, 0.3), int((rng >= 5).sum()), dofs(5, 0.5)]
    return stages, pairs


@pytest.mark.parametrize("seed", [0, 1])
def test_agrees_with_a_naive_pairwise_implementation(seed: int) -> None:
    rng = np.random.default_rng(seed)
    ref = mocap.load_reference("raw").curves
    if seed == 0:
        x = ref
    else:  # random mixtures of the real curves, some tiny, some copies, some constant
        x = ref[:300] @ rng.normal(0, 0.3, size=(50, 50))
        x[:, :10] *= rng.uniform(0.001, 0.3, size=10)
        x[:, 10] = x[:, 11] * 0.5
        x[:, 12] = 4.2
    stages, pairs = _naive_counts(x)
    an = analysis.analyze(x)
    assert [s.dofs_left for s in an.stages] == stages
    assert an.pairs_below == pairs


def test_analyze_reports_glitches_and_despikes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from handrig.offline.bvh import Bvh, format_bvh, read_bvh

    b = read_bvh(mocap.REFERENCE_BVH)
    motion = b.motion[:120].copy()
    motion[60, b.column("RightHandRing2", "Zrotation")] += 130.0
    p = tmp_path / "g.bvh"
    p.write_text(format_bvh(Bvh(b.joints, b.frame_time_s, motion)))
    assert main(["analyze", str(p), "--json"]) == 0
    cap = capsys.readouterr()
    obj = json.loads(cap.out)
    assert obj["glitches"][0]["curve"] == "riRingPIPy" and obj["glitches"][0]["frame"] == 60
    assert "--despike" in cap.err
    assert main(["analyze", str(p), "--json", "--despike"]) == 0
    fixed = json.loads(capsys.readouterr().out)
    assert fixed["glitches"][0]["repaired"] is True
    assert fixed["ranges_deg"]["riRingPIPy"] < obj["ranges_deg"]["riRingPIPy"] - 100
