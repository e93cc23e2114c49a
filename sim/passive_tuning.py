"""Tuning the relaxed hand of :mod:`sim.passive` to the paper's Table 2, and
writing, defaulting and checking its config (``handrig passive``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from handrig.errors import ConfigError
from handrig.hand import DOF_NAMES
from sim.passive import (
    LOOSE_FIST_DEG,
    PassiveHand,
)
from sim.passive_config import (
    DAMPING_GROUPS,
    ORIENTATIONS,
    RAISED_STIFFNESS_FACTOR,
    RELEASE_TESTS,
    TABLE1_S,
    TABLE2_MAP,
    TABLE2_PAPER,
    Calibration,
    PassiveHandConfig,
    PassiveParams,
    Tuned,
    table2_vocabulary,
)

PROVISIONAL_KS_NM_PER_RAD = 0.05
PROVISIONAL_KD_PER_KS_S = 0.1


def _provisional_springs(cfg: PassiveHandConfig) -> PassiveParams:
    names = DOF_NAMES["ri"]
    return PassiveParams(
        rest_deg=dict(cfg.rest_deg),
        ks_nm_per_rad=dict.fromkeys(names, PROVISIONAL_KS_NM_PER_RAD),
        kd_nms_per_rad=dict.fromkeys(names, PROVISIONAL_KS_NM_PER_RAD * PROVISIONAL_KD_PER_KS_S),
    )


def _targets(cfg: PassiveHandConfig) -> dict[str, dict[int, float]]:
    """Orientation -> {DOF index: target value in degrees} for the tuned DOFs."""
    out: dict[str, dict[int, float]] = {o: {} for o in ORIENTATIONS}
    for name, cal in cfg.calibration.items():
        i = DOF_NAMES["ri"].index(name)
        out[cal.orientation][i] = cfg.rest_deg[name] + cal.deviation_deg
    return out


def untuned_stiffness(ph: PassiveHand, indices: list[int], max_sag_deg: float) -> dict[int, float]:
    """ks for DOFs without a calibration: the largest gravity torque at the rest pose over
    all gravity directions, 9.81 |a_i| with T_i = a_i . g_hat, moves them ``max_sag_deg``."""
    a = np.empty((23, 3))
    for k in range(3):
        ph.model.opt.gravity[:] = 0.0
        ph.model.opt.gravity[k] = 1.0
        a[:, k] = ph.gravity_torque(ph.rest_deg)
    return {i: float(9.81 * np.linalg.norm(a[i]) / math.radians(max_sag_deg)) for i in indices}


def tune_stiffness(
    cfg: PassiveHandConfig, ph: PassiveHand | None = None, *, tol_deg: float = 1e-6
) -> NDArray[np.float64]:
    """ks per DOF (23, N m/rad) by equation 4, ks = T / (q - rest) with T the gravity torque
    at the observed pose in the DOF's calibration orientation. The observed pose fixes the
    tuned DOFs; the others (e.g. the wrist while the fingers hang) come from the model's own
    equilibrium, so the tuning is iterated to a fixed point (each tuned DOF then sits at its
    Table 2 value in the full equilibrium)."""
    ph = ph if ph is not None else PassiveHand(cfg, springs=_provisional_springs(cfg))
    targets = _targets(cfg)
    tuned = {i for t in targets.values() for i in t}
    untuned = [i for i in range(23) if i not in tuned]
    ks = ph.ks.copy()
    for i, k in untuned_stiffness(ph, untuned, cfg.untuned_max_sag_deg).items():
        ks[i] = k
    ph.set_gains(ks, ph.kd)
    wrong: dict[int, str] = {}
    for _ in range(100):
        worst = 0.0
        wrong.clear()
        for orient in ("palm_down", "thumb_up", "hang"):  # wrist first: it tilts the fingers
            tgt = targets[orient]
            sol = ph.solve_static(*ORIENTATIONS[orient], check_stability=False)
            worst = max(worst, *(abs(sol.q_deg[i] - v) for i, v in tgt.items()))
            q = sol.q_deg.copy()
            for i, v in tgt.items():
                q[i] = v
            torque = ph.gravity_torque(q) + ph.limit_torque(q)
            for i, v in tgt.items():
                k = float(torque[i] / math.radians(v - ph.rest_deg[i]))
                if k > 0:
                    ks[i] = k
                else:
                    wrong[i] = orient
            ph.set_gains(ks, ph.kd)
        if worst < tol_deg and not wrong:
            break
    for i, orient in wrong.items():
        name = DOF_NAMES["ri"][i]
        raise ConfigError(f"{name}: gravity in orientation {orient!r} pushes against the"
                          " calibrated deviation; check its sign", key=f"calibration.{name}")
    return ks


def time_to_relaxed(
    t_s: NDArray[np.float64], x: NDArray[np.float64], final: float, fraction: float = 0.9
) -> float:
    """First time after which ``x`` stays within (1 - fraction) of its total change of
    ``final``: "time to relaxed pose" (90 % of the change done, for good)."""
    band = (1.0 - fraction) * abs(x[0] - final)
    outside = np.nonzero(np.abs(x - final) > band)[0]
    if len(outside) == 0:
        return 0.0
    last = int(outside[-1])
    if last + 1 >= len(t_s):
        return math.inf
    return float(t_s[last + 1])


FINGER_FLEXION = [i for i, n in enumerate(DOF_NAMES["ri"])
                  if not n.startswith("riThumb") and n[-4:] in ("MCPy", "PIPy", "DIPy")]
WRIST_FLEXION = DOF_NAMES["ri"].index("riWristFlexion")
WRIST_DEVIATION = DOF_NAMES["ri"].index("riWristDeviation")


@dataclass(frozen=True)
class ReleaseResult:
    """One simulated release test: the time to relaxed pose and the traces."""

    test: str
    time_s: float
    t_s: NDArray[np.float64]
    signal_deg: NDArray[np.float64]
    start_deg: float
    final_deg: float


def release_test(ph: PassiveHand, test: str, duration_s: float = 2.0) -> ReleaseResult:
    """Run one of :data:`RELEASE_TESTS` (see the module docstring) in simulation."""
    if test == "wrist_forward":
        orient, held = "palm_down", {WRIST_FLEXION: 0.0}
        watch = [WRIST_FLEXION]
    elif test == "wrist_side":
        orient, held = "thumb_up", {WRIST_DEVIATION: 0.0}
        watch = [WRIST_DEVIATION]
    elif test == "fingers":
        orient = "hang"
        held = {i: LOOSE_FIST_DEG[DOF_NAMES["ri"][i][-4:]] for i in FINGER_FLEXION}
        watch = FINGER_FLEXION
    else:
        raise ValueError(f"unknown release test {test!r}; tests are {', '.join(RELEASE_TESTS)}")
    inc, rot = ORIENTATIONS[orient]
    start = ph.solve_static(inc, rot, fixed=held, check_stability=False).q_deg
    final = ph.solve_static(inc, rot, start, check_stability=False).q_deg
    t, q = ph.simulate(inc, rot, start, duration_s)
    signal = q[:, watch].sum(axis=1)
    f = float(final[watch].sum())
    return ReleaseResult(test, time_to_relaxed(t, signal, f, ph.cfg.relaxed_fraction),
                         t, signal, float(signal[0]), f)


_TEST_GROUP = {"wrist_forward": "wrist_flexion", "wrist_side": "wrist_deviation",
               "fingers": "digits"}


def tune_damping(
    cfg: PassiveHandConfig, ph: PassiveHand, ks: NDArray[np.float64], *, rounds: int = 2
) -> dict[str, float]:
    """kd / ks factor (seconds) per damping group, by bisection (in log space) so each
    release test takes Table 1's mean time (``cfg.release_s``)."""
    factor = dict.fromkeys(DAMPING_GROUPS, PROVISIONAL_KD_PER_KS_S)
    groups = np.array([DAMPING_GROUPS.index(cfg.group_of(n)) for n in DOF_NAMES["ri"]])

    def apply() -> None:
        f = np.array([factor[g] for g in DAMPING_GROUPS])[groups]
        ph.set_gains(ks, f * ks)

    for _ in range(rounds):
        for test in ("fingers", "wrist_forward", "wrist_side"):
            group, target = _TEST_GROUP[test], cfg.release_s[test][0]
            # Overdamped branch: below about 0.1 s the joints oscillate and the time
            # to relaxed pose rises again, so the bracket starts there.
            lo, hi = math.log(0.1), math.log(2.0)
            for _ in range(16):
                mid = 0.5 * (lo + hi)
                factor[group] = math.exp(mid)
                apply()
                t = release_test(ph, test, duration_s=max(2.0, 4 * target)).time_s
                if t < target:
                    lo = mid
                else:
                    hi = mid
            factor[group] = math.exp(0.5 * (lo + hi))
    apply()
    return factor


def tune(cfg: PassiveHandConfig) -> Tuned:
    """The tune step: stiffness (equation 4) then damping (Table 1)."""
    ph = PassiveHand(cfg, springs=_provisional_springs(cfg))
    ks = tune_stiffness(cfg, ph)
    factor = tune_damping(cfg, ph, ks)
    return Tuned(
        inputs_sha256=cfg.inputs_sha256(),
        ks_nm_per_rad={n: float(k) for n, k in zip(DOF_NAMES["ri"], ks, strict=True)},
        kd_per_ks_s=factor,
    )


# --------------------------------------------------------------------------- config file

_PAPER_LABEL = {"ri" + stem: label for label, (stem, _s, _o) in TABLE2_MAP.items()}


def render_config(cfg: PassiveHandConfig) -> str:
    """The TOML text of ``cfg``, commented (what ``handrig passive tune`` writes)."""
    lines = [
        "# The relaxed hand (Neff & Seidel, sim/passive.py). Degrees, vocabulary convention:",
        "# flexion positive, abduction/deviation positive toward the thumb (radial).",
        "# Edit the inputs, then run `handrig passive tune` to rewrite [tuned]",
        "# (loading refuses [tuned] values whose inputs_sha256 no longer matches).",
        "",
        f"hand_length_m = {cfg.hand_length_m!r}",
        "# klim = limit_gain_factor x ks (paper eq. 2: 'many times higher than the normal gain')",
        f"limit_gain_factor = {cfg.limit_gain_factor!r}",
        "# untuned DOFs (finger MCP abduction, thumb CMC twist): the worst gravity torque",
        "# at rest moves them at most this far",
        f"untuned_max_sag_deg = {cfg.untuned_max_sag_deg!r}",
        "# 'time to relaxed pose' = this fraction of the change done, for good",
        f"relaxed_fraction = {cfg.relaxed_fraction!r}",
        "# gains (ks, kd, limit gain) x this with the forearm pointing straight up,",
        "# 1 + (factor - 1) sin(inclination) above the horizontal, 1 at and below it: the",
        "# paper's fully relaxed fingers buckle when raised (sim/passive.py docstring);",
        "# 3 (chosen) keeps the smallest stiffness margin above 0.2, 1 = the paper's hand",
        f"raised_stiffness_factor = {cfg.raised_stiffness_factor!r}",
        "",
        "# Set point per DOF (paper eq. 1) = Table 2 'Angle'.",
        "[rest_deg]",
    ]
    for n in DOF_NAMES["ri"]:
        label = _PAPER_LABEL.get(n, "not in Table 2")
        lines.append(f"{n} = {cfg.rest_deg[n]!r}  # {label}")
    lines += ["", "# Table 2 'Deviation', sign mapped by the physics (sim/passive.py docstring);",
              "# orientation: hang = forearm straight down, palm_down / thumb_up = forearm",
              "# horizontal with the palm down / vertical, thumb up."]
    for n, c in cfg.calibration.items():
        paper = TABLE2_PAPER[_PAPER_LABEL[n]][1]
        lines.append(f"[calibration.{n}]  # paper: {_PAPER_LABEL[n]} {paper:+g}")
        lines.append(f"deviation_deg = {c.deviation_deg!r}")
        lines.append(f'orientation = "{c.orientation}"')
    lines += ["", "# Table 1: time to relaxed pose, [mean, standard deviation] in seconds.",
              "[release_s]"]
    for t, (mean, sd) in cfg.release_s.items():
        lines.append(f"{t} = [{mean!r}, {sd!r}]")
    if cfg.tuned is not None:
        lines += ["", "# Written by `handrig passive tune`: ks by equation 4, kd = factor x ks",
                  "# with one factor per group found by matching Table 1. Do not edit.",
                  "[tuned]", f'inputs_sha256 = "{cfg.tuned.inputs_sha256}"', "",
                  "[tuned.kd_per_ks_s]"]
        for g, f in cfg.tuned.kd_per_ks_s.items():
            lines.append(f"{g} = {f!r}")
        lines += ["", "[tuned.ks_nm_per_rad]"]
        for n, k in cfg.tuned.ks_nm_per_rad.items():
            lines.append(f"{n} = {k!r}")
    return "\n".join(lines) + "\n"


def default_config(hand_length_m: float = 0.19) -> PassiveHandConfig:
    """The paper's inputs (Table 2 mapped, Table 1), untuned."""
    rest, dev = table2_vocabulary()
    return PassiveHandConfig(
        hand_length_m=hand_length_m, limit_gain_factor=20.0, untuned_max_sag_deg=3.0,
        relaxed_fraction=0.9, raised_stiffness_factor=RAISED_STIFFNESS_FACTOR, rest_deg=rest,
        calibration={n: Calibration(d, o) for n, (d, o) in dev.items()},
        release_s=dict(TABLE1_S),
    )


def tune_config(cfg: PassiveHandConfig) -> PassiveHandConfig:
    """``cfg`` with fresh [tuned] values."""
    import dataclasses

    return dataclasses.replace(cfg, tuned=tune(cfg))


def check(cfg: PassiveHandConfig) -> dict[str, dict[str, dict[str, float | str | bool]]]:
    """Run the calibration poses and the release tests on the tuned model.

    Returns ``{"deviations": {dof: {paper, model, orientation, ok}},
    "relaxation_s": {test: {paper, std, model, ok}}}``; deviations are sag from rest in
    degrees (vocabulary convention); ok = within 1 degree / within mean +- std."""
    ph = PassiveHand(cfg)
    sols = {o: ph.solve_static(*ORIENTATIONS[o]) for o in ORIENTATIONS}
    dev: dict[str, dict[str, float | str | bool]] = {}
    for name, cal in cfg.calibration.items():
        i = DOF_NAMES["ri"].index(name)
        model = float(sols[cal.orientation].q_deg[i] - cfg.rest_deg[name])
        dev[name] = {"paper": cal.deviation_deg, "model": round(model, 4),
                     "orientation": cal.orientation,
                     "ok": abs(model - cal.deviation_deg) <= 1.0}
    rel: dict[str, dict[str, float | str | bool]] = {}
    for test in RELEASE_TESTS:
        mean, sd = cfg.release_s[test]
        t = release_test(ph, test).time_s
        rel[test] = {"paper": mean, "std": sd, "model": round(t, 4),
                     "ok": abs(t - mean) <= sd}
    return {"deviations": dev, "relaxation_s": rel}
