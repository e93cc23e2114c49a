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
    "PassiveHand", "PassiveHandConfig", "PassiveParams", "StaticSolution", "Tuned",
    "load_passive_params", "stiffness_scale", "table2_vocabulary",
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
