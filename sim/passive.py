"""The relaxed hand of Neff & Seidel, "Modeling Relaxed Hand Shape", in MuJoCo.

Control law per DOF (paper equations 1-3)::

    tau = ks (rest - q) + c0 klim (low - q) + c1 klim (high - q) - kd qdot

``ks``/``rest``/``kd`` are MuJoCo joint springs (``stiffness``/``springref``/
``damping``, exact, handled by ``implicitfast``); the limit terms (c0 = 1 below
``low``, c1 = 1 above ``high``) are added here through ``qfrc_applied`` in dynamic
runs and analytically in the static solve. ``klim = limit_gain_factor x ks``
("many times higher than the normal gain").

Table 2 signs, mapped to the vocabulary convention by the physics
---------------------------------------------------------------
The paper gives the rest pose ("Angle") and the sag in the calibration
orientation ("Deviation"). In the vocabulary convention (flexion positive,
abduction and deviation radial positive):

* fingers, hanging straight down: gravity straightens them, Deviation is
  negative = less flexion: signs kept (index MCP 40 -> 19).
* wrist forward, forearm horizontal palm down: the hand droops palmar = wrist
  flexion, +22 kept.
* wrist side, palm vertical thumb up: the hand droops toward the little finger =
  ulnar = negative here: the paper's +29 becomes **-29**.
* thumb CMC flexion, palm down: the thumb drops palmar; in this model CMC
  flexion moves the thumb palmar and across the palm, so +6 kept.
* thumb CMC abduction, thumb up: the thumb drops toward the index, i.e. less
  (radial) abduction: -2 kept.
* thumb MCP and IP, thumb up: the thumb curls down, across the palm, = more
  flexion: +2 and +2 kept.

``tests/sim/test_passive.py`` checks each of these with the model: the gravity
torque in the calibration orientation has the sign of the mapped deviation, so
every tuned ks comes out positive (the paper's own signs are consistent with
flexion positive for every row but Wrist Side, whose +29 can only be an ulnar
droop). Finger MCP abduction and thumb CMC twist
(absent from Table 2: rest 0) are untuned: their ks is set so that the largest
gravity torque at the rest pose, over all orientations, moves them at most
``untuned_max_sag_deg``.

What Table 2 implies for the fingers
------------------------------------
The fingers are calibrated per joint, hanging straight down: ks = T / (q - rest)
with T the gravity moment of the joint's distal chain at the observed pose
(equation 4). For a distal phalanx T = m g r sin(phi), phi its angle from the
vertical in that pose (about 37-46 deg: the DIPs end nearly straight), so
ks / (m g r) = sin(phi) / deviation, whatever the masses. For the distal chain of
every finger joint, ks over its largest gravity moment (chain straight and
horizontal) comes out 0.9-1.6 (index MCP 0.92, PIP 1.12, DIP 1.01): each joint is
about as stiff as its own weight's largest moment.

* **Palm down** (forearm horizontal) the wrist droops 22 deg (Table 2), and the rest
  pose already curls each distal phalanx past straight down (MCP + PIP + DIP =
  111-130 deg at rest, wrist straight); gravity turns it back toward the vertical,
  so every DIP *opens*, for any positive stiffness: flexing it would only carry
  the phalanx further past the vertical. The same holds for the index, middle and
  ring PIPs (their middle phalanx points straight down at rest, wrist straight);
  in the model the little finger's PIP opens too (42 -> 33 deg). What flexes
  is each finger as a whole: the MCP (+8 to +14 deg) and the finger's centre of
  mass, which swings palmar about the knuckle (+4 to +12 deg). That is what
  "palm down flexes the fingers" is tested as (tests/sim/test_bake.py). Palm up,
  every finger joint extends.
* **Raised hand**: with ks about m g r a finger whose segments point upward is an
  inverted pendulum at its buckling load. Palm up with the forearm 40-55 deg up, the
  fully relaxed model has two stable poses about 90 deg apart (fingers bent back on
  their limits, or folded into the palm) and jumps between them; no grid can be
  interpolated across that, and a real relaxed hand does not do it. The paper
  itself finds its relaxed hand "too loose" at head height ("it is rare for a person
  to have their wrist fully relaxed in this position ... stiffness values should be
  increased", section 5). So every gain (ks, kd and the limit gain) is multiplied by
  ``1 + (raised_stiffness_factor - 1) sin(inclination)`` above the horizontal and by
  1 at and below it (:func:`stiffness_scale`), where all of Table 2 and Table 1 was
  measured: calibration and release tests are unchanged. With the factor 3 the
  smallest eigenvalue of K^-1/2 H K^-1/2 (H the Hessian of the potential energy, K
  the springs; 1 = gravity takes nothing away, 0 = buckling) stays above 0.2
  everywhere (lowest 0.215 at inclination 24, palm up; 0.86 at and below the
  horizontal); at factor 1 it falls to 0 where the pose folds, palm up at 40-55
  deg. There is then one equilibrium per orientation (static solves from the rest
  pose, from the hanging pose and from the previous sample agree).

Damping (Table 1) and "time to relaxed pose"
--------------------------------------------
``kd = factor x ks`` with one factor (in seconds) per group: wrist flexion,
wrist deviation, digits (fingers and thumb), as the paper does. The factors are
found by bisection so that the simulated release tests take Table 1's mean time.
The paper's "kd about 5-7 ks" does not carry over (SI units, radians): the tuned
factors are about 0.21-0.28 s; below about 0.1 s the joints oscillate and the
time to relaxed pose rises again, so the search stays on the overdamped side.
**Time to relaxed pose** = the first time after which the DOF (for the fingers,
the sum of the 12 finger flexion DOFs) stays within 10 % of the total change of
its start-to-equilibrium distance (i.e. 90 % of the change is done and stays so).
Release tests: wrist forward = palm down, wrist held straight (0) while the rest
settles, then released; wrist side = thumb up, wrist deviation held at 0, then
released; fingers = hanging straight down, fingers held in a loose fist
(``LOOSE_FIST_DEG``) then released.

The tuned values (ks per DOF, the three damping factors) are written into
``config/passive_hand.toml`` by ``handrig passive tune`` together with a hash of
the inputs they were tuned from; loading refuses stale values (edit the rest pose,
re-run the tune step).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from handrig.errors import ConfigError
from handrig.hand import DOF_NAMES, Hand, dof_limits_deg
from sim.hand_model import dof_qpos_indices, gravity_in_forearm, hand_model_xml
from sim.passive_config import (
    DAMPING_GROUPS,
    ORIENTATIONS,
    PASSIVE_CONFIG,
    RAISED_STIFFNESS_FACTOR,
    RELEASE_TESTS,
    TABLE1_S,
    TABLE2_MAP,
    TABLE2_PAPER,
    Calibration,
    Orientation,
    PassiveHandConfig,
    PassiveParams,
    Tuned,
    load_passive_params,
    table2_vocabulary,
)

__all__ = [  # the config names are re-exported: callers know them as sim.passive's
    "DAMPING_GROUPS", "ORIENTATIONS", "PASSIVE_CONFIG", "RAISED_STIFFNESS_FACTOR",
    "RELEASE_TESTS", "TABLE1_S", "TABLE2_MAP", "TABLE2_PAPER", "Calibration", "Orientation",
    "PassiveHand", "PassiveHandConfig", "PassiveParams", "StaticSolution", "Tuned", "check",
    "default_config", "load_passive_params", "release_test", "render_config",
    "stiffness_scale", "table2_vocabulary", "time_to_relaxed", "tune", "tune_config",
    "tune_damping", "tune_stiffness", "untuned_stiffness",
]

LOOSE_FIST_DEG: dict[str, float] = {"MCPy": 60.0, "PIPy": 85.0, "DIPy": 55.0}


def stiffness_scale(inclination_deg: float, raised_factor: float) -> float:
    """Gain multiplier at a forearm inclination: 1 at and below the horizontal (where Table
    2 was measured), ``1 + (raised_factor - 1) sin(inclination)`` above it."""
    return 1.0 + (raised_factor - 1.0) * max(0.0, math.sin(math.radians(inclination_deg)))


@dataclass
class StaticSolution:
    """A static equilibrium: DOF values (23, degrees, vocabulary order) and diagnostics."""

    q_deg: NDArray[np.float64]
    iterations: int
    residual_nm: float
    stable: bool
    max_eigenvalue: float


class PassiveHand:
    """The tuned relaxed hand as a MuJoCo model with static and dynamic solvers.

    Arrays in vocabulary DOF order (``DOF_NAMES[hand]``) unless named ``*_qpos``.
    Stiffness/damping can be changed in place with :meth:`set_gains` (used by tuning).
    """

    def __init__(
        self,
        cfg: PassiveHandConfig,
        hand: Hand = "ri",
        *,
        springs: PassiveParams | None = None,
        timestep_s: float = 0.001,
        limits_deg: NDArray[np.float64] | None = None,
    ) -> None:
        self.cfg = cfg
        self.hand: Hand = hand
        springs = springs if springs is not None else cfg.springs()
        self.names = DOF_NAMES[hand]
        self.model = mujoco.MjModel.from_xml_string(hand_model_xml(
            hand, cfg.hand_length_m, passive=springs, limits_deg=limits_deg,
            mujoco_limits=False, timestep_s=timestep_s))
        self.data = mujoco.MjData(self.model)
        self.idx = dof_qpos_indices(self.model, hand)
        lim = dof_limits_deg(hand) if limits_deg is None else np.asarray(limits_deg, float)
        nv = self.model.nv
        self.low_qpos = np.empty(nv)
        self.high_qpos = np.empty(nv)
        self.low_qpos[self.idx] = np.radians(lim[:, 0])
        self.high_qpos[self.idx] = np.radians(lim[:, 1])
        self.rest_deg = np.array([cfg.rest_deg["ri" + n[2:]] for n in self.names])
        self._dfdq = np.zeros((nv, nv))
        self._klim_qpos = np.zeros(nv)
        self.scale = 1.0
        self._ks = np.zeros(23)
        self._kd = np.zeros(23)
        self.set_gains(
            np.array([springs.ks_nm_per_rad["ri" + n[2:]] for n in self.names]),
            np.array([springs.kd_nms_per_rad["ri" + n[2:]] for n in self.names]),
        )

    # -- parameters

    def set_gains(self, ks: NDArray[np.float64], kd: NDArray[np.float64]) -> None:
        """Set the relaxed (calibrated) stiffness (N m/rad) and damping (N m s/rad) per DOF,
        vocabulary order; the model uses them times the current :attr:`scale`."""
        self._ks = np.array(ks, dtype=np.float64)
        self._kd = np.array(kd, dtype=np.float64)
        self._apply_gains()

    def _apply_gains(self) -> None:
        m = self.model
        m.jnt_stiffness[m.dof_jntid[self.idx]] = self.scale * self._ks
        m.dof_damping[self.idx] = self.scale * self._kd
        self._klim_qpos[self.idx] = self.cfg.limit_gain_factor * self.scale * self._ks

    @property
    def ks(self) -> NDArray[np.float64]:
        """Relaxed stiffness per DOF (N m/rad), before the raised-hand :attr:`scale`."""
        return self._ks.copy()

    @property
    def kd(self) -> NDArray[np.float64]:
        """Relaxed damping per DOF (N m s/rad), before the raised-hand :attr:`scale`."""
        return self._kd.copy()

    def set_orientation(self, inclination_deg: float, rotation_deg: float) -> None:
        """Put the forearm orientation into ``opt.gravity`` and scale the gains by
        :func:`stiffness_scale` (1 at and below the horizontal)."""
        self.model.opt.gravity[:] = gravity_in_forearm(inclination_deg, rotation_deg, self.hand)
        scale = stiffness_scale(inclination_deg, self.cfg.raised_stiffness_factor)
        if scale != self.scale:
            self.scale = scale
            self._apply_gains()

    # -- torques

    def _limit_qpos(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        # equations 2-3: c0 klim (low - q) + c1 klim (high - q)
        below = np.maximum(self.low_qpos - q, 0.0)
        above = np.minimum(self.high_qpos - q, 0.0)
        return self._klim_qpos * (below + above)

    def limit_torque(self, q_deg: NDArray[np.float64]) -> NDArray[np.float64]:
        """The limit terms of equations 2-3 (N m) at ``q_deg``, vocabulary order."""
        q = np.zeros(self.model.nq)
        q[self.idx] = np.radians(q_deg)
        return self._limit_qpos(q)[self.idx]

    def gravity_torque(self, q_deg: NDArray[np.float64]) -> NDArray[np.float64]:
        """Generalised gravity torque (N m) at ``q_deg``, qvel = 0: ``-qfrc_bias``."""
        d = self.data
        d.qpos[self.idx] = np.radians(q_deg)
        d.qvel[:] = 0.0
        mujoco.mj_forward(self.model, d)
        return np.array(-d.qfrc_bias[self.idx])

    def _residual_qpos(self, q: NDArray[np.float64], jac: bool) -> NDArray[np.float64]:
        m, d = self.model, self.data
        d.qpos[:] = q
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        mujoco.mj_inverse(m, d)
        # qfrc_inverse = bias - passive: spring + gravity torque = -qfrc_inverse
        r = -d.qfrc_inverse + self._limit_qpos(q)
        if jac:
            mujoco.mjd_inverseFD(m, d, 1e-7, False, self._dfdq, None, None,
                                 None, None, None, None)
        return np.asarray(r)

    def _energy_qpos(self, q: NDArray[np.float64]) -> float:
        """Potential energy whose negative gradient is the residual: springs, limit
        penalties and gravity (valid right after :meth:`_residual_qpos` at ``q``)."""
        m, d = self.model, self.data
        ks = m.jnt_stiffness[m.dof_jntid]
        viol = np.maximum(self.low_qpos - q, 0.0) + np.maximum(q - self.high_qpos, 0.0)
        spring = 0.5 * float(np.sum(ks * (q - m.qpos_spring) ** 2))
        limit = 0.5 * float(np.sum(self._klim_qpos * viol**2))
        gravity = -float(np.sum(m.body_mass[:, None] * d.xipos * m.opt.gravity))
        return spring + limit + gravity

    # -- static equilibrium

    def solve_static(
        self,
        inclination_deg: float,
        rotation_deg: float,
        q0_deg: NDArray[np.float64] | None = None,
        *,
        fixed: Mapping[int, float] | None = None,
        tol_nm: float = 1e-10,
        max_iter: int = 60,
        check_stability: bool = True,
    ) -> StaticSolution:
        """Static equilibrium ks (rest - q) + limits + gravity torque = 0, warm-started at
        ``q0_deg`` (default: the rest pose).

        The equilibrium is a stationary point of the potential energy (springs, limit
        penalties, gravity), so the solver is Newton's method on that energy with an
        Armijo line search and a Levenberg shift where the Hessian is not positive
        definite: it always descends, so it ends in a local minimum near the warm start,
        the one the dynamics would also settle in. ``fixed``: DOF index -> value held
        (degrees), as when the subject holds the wrist straight. Stability: every
        eigenvalue of the residual's Jacobian (over the free DOFs) must be negative."""
        self.set_orientation(inclination_deg, rotation_deg)
        nv = self.model.nv
        q = np.zeros(nv)
        q[self.idx] = np.radians(self.rest_deg if q0_deg is None else q0_deg)
        free = np.ones(nv, dtype=bool)
        for i, v in (fixed or {}).items():
            q[self.idx[i]] = math.radians(v)
            free[self.idx[i]] = False
        iterations = 0
        r = self._residual_qpos(q, jac=True)
        energy = self._energy_qpos(q)
        res = float(np.max(np.abs(r[free])))
        while res >= tol_nm and iterations < max_iter:
            iterations += 1
            hess = -self._jacobian(q)[np.ix_(free, free)]
            hess = 0.5 * (hess + hess.T)
            shift = 0.0
            scale = float(np.max(np.abs(np.diag(hess))))
            while True:
                try:
                    chol = np.linalg.cholesky(hess + shift * np.eye(len(hess)))
                    break
                except np.linalg.LinAlgError:
                    shift = max(2.0 * shift, 1e-6 * scale)
            step = np.linalg.solve(chol.T, np.linalg.solve(chol, r[free]))
            slope = -float(r[free] @ step)  # directional derivative of the energy (< 0)
            alpha = 1.0
            while True:
                qn = q.copy()
                qn[free] += alpha * step
                self._residual_qpos(qn, jac=False)
                en = self._energy_qpos(qn)
                if en <= energy + 1e-4 * alpha * slope or alpha < 1e-6:
                    break
                alpha *= 0.5
            q, energy = qn, en
            r = self._residual_qpos(q, jac=True)
            res = float(np.max(np.abs(r[free])))
            if float(np.max(np.abs(alpha * step))) < 1e-13:
                break
        eig = math.nan
        stable = True
        if check_stability:
            jmat = self._jacobian(q)[np.ix_(free, free)]
            eig = float(np.max(np.linalg.eigvalsh(0.5 * (jmat + jmat.T))))
            stable = eig < 0.0
        return StaticSolution(np.degrees(q[self.idx]), iterations, res, stable, eig)

    def _jacobian(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        # d r / d q = -(d qfrc_inverse / d q) + d limit / d q; mjd output is transposed.
        active = (q < self.low_qpos) | (q > self.high_qpos)
        return np.asarray(-self._dfdq.T - np.diag(self._klim_qpos * active))

    # -- dynamics

    def simulate(
        self,
        inclination_deg: float,
        rotation_deg: float,
        q0_deg: NDArray[np.float64],
        duration_s: float,
        *,
        record_every: int = 1,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Release from ``q0_deg`` at rest velocity and integrate (implicitfast; the limit
        terms through ``qfrc_applied``). Returns times (n,) and DOF values (n, 23) in deg."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        self.set_orientation(inclination_deg, rotation_deg)
        d.qpos[self.idx] = np.radians(q0_deg)
        steps = round(duration_s / m.opt.timestep)
        n = steps // record_every + 1
        ts, qs = np.empty(n), np.empty((n, 23))
        ts[0], qs[0] = 0.0, q0_deg
        k = 1
        for s in range(1, steps + 1):
            d.qfrc_applied[:] = self._limit_qpos(d.qpos)
            mujoco.mj_step(m, d)
            if s % record_every == 0:
                ts[k] = d.time
                qs[k] = np.degrees(d.qpos[self.idx])
                k += 1
        return ts[:k], qs[:k]

    def settle(
        self,
        inclination_deg: float,
        rotation_deg: float,
        q0_deg: NDArray[np.float64] | None = None,
        *,
        max_s: float = 5.0,
        vel_tol_deg_s: float = 0.01,
    ) -> tuple[NDArray[np.float64], float]:
        """Dynamic settle (the reference for the static solve): integrate from ``q0_deg``
        (default rest) until every joint is slower than ``vel_tol_deg_s``. Returns the
        pose (23,) in degrees and the simulated time it took."""
        m, d = self.model, self.data
        self.set_orientation(inclination_deg, rotation_deg)
        d.qpos[self.idx] = np.radians(self.rest_deg if q0_deg is None else q0_deg)
        d.qvel[:] = 0.0
        d.time = 0.0
        tol = math.radians(vel_tol_deg_s)
        steps = round(max_s / m.opt.timestep)
        for s in range(steps):
            d.qfrc_applied[:] = self._limit_qpos(d.qpos)
            mujoco.mj_step(m, d)
            if s > 10 and float(np.max(np.abs(d.qvel))) < tol:
                break
        return np.degrees(d.qpos[self.idx]), float(d.time)


# --------------------------------------------------------------------------- tuning

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
