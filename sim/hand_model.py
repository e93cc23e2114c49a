"""The one MJCF hand: passive relaxed-hand model and servo-driven puppet share it.

Geometry (``hand_model_xml``)
-----------------------------
* **Forearm frame** (the world frame of the model; the forearm body is fixed to
  the world): x distal along the forearm, z dorsal (palm down = z up), y = z × x.
  For the right hand y points radial (toward the thumb); the left hand is the
  mirror image (positions y -> -y, joint axes (ax, ay, az) -> (-ax, ay, -az)), so
  in its frame y points ulnar. The frame stays right-handed for both hands.
* Gravity is not applied by moving bodies: the forearm orientation goes into
  ``opt.gravity`` as gravity expressed in the forearm frame
  (:func:`gravity_in_forearm`, REFERENCE.md section 4).
* Bodies: forearm (fixed) -> hand (wrist flexion, then wrist deviation; palm
  mass) -> per finger MCP (abduction, then flexion) -> PIP -> DIP; thumb CMC
  (abduction, flexion, twist) -> MCP -> IP. Every body frame is axis-aligned with
  the forearm frame at zero joint angles; at zero all digits point along +x.
* 23 hinge joints named exactly as ``handrig.hand.DOF_NAMES[hand]``. Axes are
  chosen so that a positive joint angle is the vocabulary's positive direction
  (flexion positive, abduction/deviation radial positive):
  wrist flexion +y (hand moves palmar, -z), wrist deviation +z (radial, +y);
  finger MCP flexion, PIP, DIP +y; finger MCP abduction +z; thumb CMC abduction
  +z (thumb swings radially in the palm plane, away from the index); thumb CMC
  flexion +y of the abducted metacarpal (the thumb drops palmar: the paper's
  "downward rotation of the thumb CMC", tuned palm down); thumb MCP and IP
  flexion (0, sin 30°, -cos 30°) in their (abducted, flexed) frames (the tip
  curls across the palm, toward the little finger, and a little palmar: the
  thumb is rotated about 90° against the fingers); thumb CMC twist -x
  (pronation-like for the right hand). The thumb's zero pose lies along the index
  metacarpal; its rest pose (abduction 42°, flexion 28°) puts it out radially and
  palmar. tests/sim/test_hand_model.py checks each sign with gravity.
* Segment lengths are fractions of the hand length HL (REFERENCE.md section 4,
  Buchholz et al. 1992); digit bases sit at the carpus, ``CARPUS_FRAC`` x HL distal
  of the wrist axis, so wrist-to-middle-fingertip = HL. Lateral offsets use the
  hand breadth HB = ``BREADTH_PER_LENGTH`` x HL (0.085 m at HL 0.19 m).
  Phalanx masses are the table's (cylinders at 1.1 g/cm^3, HL 0.19 m) scaled by
  (HL / 0.19)^3; each segment is a cylinder with an explicit ``<inertial>``
  (radius from mass and length). The thumb metacarpal (no mass in the table) is
  a cylinder with the thumb proximal phalanx's radius (assumed). The palm takes
  the remainder of 0.45 kg x (HL / 0.19)^3, with its centre of mass placed so that
  the straight hand's centre of mass lies at 0.506 of the wrist-to-middle-MCP
  distance.
* Joint ranges come from ``handrig.hand.dof_limits_deg`` (or the ``limits_deg``
  argument). With ``mujoco_limits=True`` they are MuJoCo joint limits
  (constraints, for the puppet); with ``False`` the joints are unlimited and the
  caller applies the relaxed-hand paper's limit terms (equations 2-3, see
  ``sim.passive``).
* Contacts are disabled (REFERENCE.md: with contacts on, static and dynamic
  answers disagreed by 31 deg); integrator ``implicitfast``; angles in radians.

Springs and actuators
---------------------
``passive`` gives each joint a spring ``stiffness=ks springref=rest damping=kd``,
which MuJoCo applies as exactly tau = ks (rest - q) - kd qdot (equation 1 of the
paper). ``actuated`` adds a MuJoCo ``position`` actuator on each named joint
(``kp``, ``kv``, ``forcerange``); such a joint has no spring and no joint damping
(the servo holds it; its damping is the actuator's ``kv``) and gets the actuator's
``armature``.
MuJoCo has no speed limit for position actuators: the caller limits speed by
moving ``data.ctrl`` toward the goal at most ``max_speed_rad_s`` x dt per step,
like a servo's profile velocity (:func:`ramp_ctrl`). Stability: keep
sqrt(kp / (armature + link inertia)) x timestep well below 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig.hand import DIGITS, DOF_NAMES, FINGERS, Hand, dof_limits_deg
from handrig.pose.hand_geometry import (
    REFERENCE_HAND_LENGTH_M,
    HandGeometry,
    Segment,
    hand_geometry,
    joint_axis,
    mirror_pos,
)
from sim.passive_config import PassiveParams, load_passive_params

__all__ = [
    "REFERENCE_HAND_LENGTH_M", "ActuatorParams", "HandGeometry", "PassiveParams", "Segment",
    "default_passive", "dof_qpos_indices", "gravity_grid_in_forearm", "gravity_in_forearm",
    "hand_geometry", "hand_model_xml", "joint_axis", "ramp_ctrl", "two_hands_xml",
]

G_MPS2 = 9.81


@dataclass(frozen=True)
class ActuatorParams:
    """A position servo on one joint (MuJoCo ``position`` actuator).

    ``kp_nm_per_rad``: proportional gain; ``kv_nms_per_rad``: velocity gain (damping
    from the actuator, handled implicitly by ``implicitfast``); ``force_limit_nm``:
    torque saturation (``forcerange``); ``max_speed_rad_s``: the speed limit the
    caller enforces with :func:`ramp_ctrl` (not part of the MJCF); ``armature_kgm2``:
    reflected rotor inertia added to the joint (keeps stiff servos stable on tiny
    distal links).
    """

    kp_nm_per_rad: float = 1.0
    kv_nms_per_rad: float = 0.02
    force_limit_nm: float = 0.5
    max_speed_rad_s: float = 6.0
    armature_kgm2: float = 1e-4


def gravity_in_forearm(
    inclination_deg: float, rotation_deg: float, hand: Hand = "ri", g_mps2: float = G_MPS2
) -> NDArray[np.float64]:
    """Gravity (3,) in m/s^2 expressed in ``hand``'s forearm frame (``opt.gravity``).

    ``inclination_deg``: forearm axis above the horizontal, -90 hanging straight down,
    +90 pointing up. ``rotation_deg``: about the forearm axis, anatomical and the same
    for both hands: 0 palm down, +90 palm vertical thumb up, 180 palm up. World up in
    the right forearm frame is (sin i, cos i sin r, cos i cos r); the left hand's y
    axis points ulnar, so there thumb up is -y and the y component flips.
    """
    inc, rot = math.radians(inclination_deg), math.radians(rotation_deg)
    up_y = math.cos(inc) * math.sin(rot)
    if hand == "le":
        up_y = -up_y
    up = np.array([math.sin(inc), up_y, math.cos(inc) * math.cos(rot)])
    return -g_mps2 * up


def gravity_grid_in_forearm(
    inclination_deg: NDArray[np.float64], rotation_deg: NDArray[np.float64], hand: Hand = "ri"
) -> NDArray[np.float64]:
    """Vectorised :func:`gravity_in_forearm`: arrays broadcast, result (..., 3)."""
    inc, rot = np.radians(inclination_deg), np.radians(rotation_deg)
    inc, rot = np.broadcast_arrays(inc, rot)
    sign = -1.0 if hand == "le" else 1.0
    up = np.stack([np.sin(inc), sign * np.cos(inc) * np.sin(rot), np.cos(inc) * np.cos(rot)], -1)
    return np.asarray(-G_MPS2 * up, dtype=np.float64)


def _fmt(v: Sequence[float]) -> str:
    return " ".join(f"{x:.9g}" for x in v)


def _cyl_inertial(seg: Segment) -> str:
    m, r, length = seg.mass_kg, seg.radius_m, seg.length_m
    axial = 0.5 * m * r * r
    perp = m * (3 * r * r + length * length) / 12.0
    return (f'<inertial pos="{length / 2:.9g} 0 0" mass="{m:.9g}" '
            f'diaginertia="{axial:.9g} {perp:.9g} {perp:.9g}"/>')


def default_passive() -> PassiveParams:
    """The tuned relaxed-hand springs from ``config/passive_hand.toml``."""
    return load_passive_params().springs()


def hand_model_xml(
    hand: Literal["ri", "le"] = "ri",
    hand_length_m: float = REFERENCE_HAND_LENGTH_M,
    *,
    passive: PassiveParams | None = None,
    actuated: Mapping[str, ActuatorParams] | None = None,
    limits_deg: NDArray[np.float64] | None = None,
    mujoco_limits: bool = True,
    timestep_s: float = 0.001,
    gravity: Sequence[float] = (0.0, 0.0, -G_MPS2),
) -> str:
    """MJCF text of one hand (see the module docstring for frames, axes and masses).

    ``passive``: springs per DOF (keys: ``ri`` DOF names, used for both hands); None
    loads the tuned defaults from ``config/passive_hand.toml`` via
    ``sim.passive_config.load_passive_params``. ``actuated``: DOF name (of ``hand``) ->
    :class:`ActuatorParams`; the actuator is named like its joint. ``limits_deg``:
    (23, 2) ranges in DOF order (default ``handrig.hand.dof_limits_deg``).
    ``gravity``: initial ``opt.gravity`` (forearm frame), default palm down horizontal.
    """
    if hand not in ("ri", "le"):
        raise ValueError(f"hand must be 'ri' or 'le', got {hand!r}")
    if passive is None:
        passive = default_passive()
    actuated = dict(actuated or {})
    names = DOF_NAMES[hand]
    unknown = sorted(set(actuated) - set(names))
    if unknown:
        raise ValueError(f"actuated names not DOFs of hand {hand!r}: {unknown}")
    lim = dof_limits_deg(hand) if limits_deg is None else np.asarray(limits_deg, float)
    if lim.shape != (23, 2):
        raise ValueError(f"limits_deg must be (23, 2), got {lim.shape}")
    lim_by_name = {n: (float(lim[i, 0]), float(lim[i, 1])) for i, n in enumerate(names)}
    geo = hand_geometry(hand_length_m)

    def joint(name: str) -> str:
        ri_name = "ri" + name[2:]
        lo, hi = (math.radians(v) for v in lim_by_name[name])
        attrs = [f'name="{name}"', 'type="hinge"', 'pos="0 0 0"',
                 f'axis="{_fmt(joint_axis(name, hand))}"', f'range="{lo:.9g} {hi:.9g}"',
                 f'limited="{"true" if mujoco_limits else "false"}"']
        if name in actuated:
            attrs.append(f'armature="{actuated[name].armature_kgm2:.9g}"')
        else:
            rest = math.radians(passive.rest_deg[ri_name])
            attrs += [f'stiffness="{passive.ks_nm_per_rad[ri_name]:.9g}"',
                      f'springref="{rest:.9g}"',
                      f'damping="{passive.kd_nms_per_rad[ri_name]:.9g}"']
        return f'<joint {" ".join(attrs)}/>'

    def seg_geom(seg: Segment, rgba: str) -> str:
        return (f'<geom type="cylinder" fromto="0 0 0 {seg.length_m:.9g} 0 0" '
                f'size="{seg.radius_m:.9g}" rgba="{rgba}" contype="0" conaffinity="0" '
                f'mass="0"/>')

    skin = "0.85 0.68 0.58 1"
    out: list[str] = []
    for digit in DIGITS:
        segs = geo.segments[digit]
        pos = mirror_pos(geo.base_pos_m[digit], hand)
        if digit == "Thumb":
            jnames = [[f"{hand}ThumbCMCy", f"{hand}ThumbCMCz", f"{hand}ThumbCMCx"],
                      [f"{hand}ThumbMCPz"], [f"{hand}ThumbIPz"]]
        else:
            p = f"{hand}{digit}"
            jnames = [[f"{p}MCPx", f"{p}MCPy"], [f"{p}PIPy"], [f"{p}DIPy"]]
        chain = ""
        for k in range(len(segs) - 1, -1, -1):
            seg = segs[k]
            bpos = pos if k == 0 else (segs[k - 1].length_m, 0.0, 0.0)
            joints = "".join(joint(j) for j in jnames[k])
            chain = (f'<body name="{hand}{digit}{seg.body}" pos="{_fmt(bpos)}">'
                     f"{_cyl_inertial(seg)}{joints}{seg_geom(seg, skin)}{chain}</body>")
        out.append(chain)
    px, py, pz = geo.palm_size_m
    palm_i = [geo.palm_mass_kg / 12.0 * (b * b + c * c)
              for b, c in ((py, pz), (px, pz), (px, py))]
    palm = (f'<body name="{hand}Palm" pos="0 0 0">'
            f'<inertial pos="{_fmt(geo.palm_com_m)}" mass="{geo.palm_mass_kg:.9g}" '
            f'diaginertia="{_fmt(palm_i)}"/>'
            f"{joint(f'{hand}WristFlexion')}{joint(f'{hand}WristDeviation')}"
            f'<geom type="box" pos="{px / 2:.9g} 0 0" size="{px / 2:.9g} {py / 2:.9g} '
            f'{pz / 4:.9g}" rgba="{skin}" contype="0" conaffinity="0" mass="0"/>'
            + "".join(out) + "</body>")
    acts = []
    for name, a in actuated.items():
        lo, hi = (math.radians(v) for v in lim_by_name[name])
        acts.append(
            f'<position name="{name}" joint="{name}" kp="{a.kp_nm_per_rad:.9g}" '
            f'kv="{a.kv_nms_per_rad:.9g}" forcelimited="true" '
            f'forcerange="{-a.force_limit_nm:.9g} {a.force_limit_nm:.9g}" '
            f'ctrllimited="true" ctrlrange="{lo:.9g} {hi:.9g}"/>'
        )
    fl = 0.25 * hand_length_m / REFERENCE_HAND_LENGTH_M
    fr = 0.03 * hand_length_m / REFERENCE_HAND_LENGTH_M
    return (
        f'<mujoco model="handrig_{hand}_hand">'
        '<compiler angle="radian" autolimits="false"/>'
        f'<option timestep="{timestep_s:.9g}" integrator="implicitfast" '
        f'gravity="{_fmt(gravity)}"><flag contact="disable"/></option>'
        "<worldbody>"
        f'<body name="{hand}Forearm" pos="0 0 0">'
        f'<geom type="capsule" fromto="{-fl:.9g} 0 0 0 0 0" size="{fr:.9g}" '
        f'rgba="{skin}" contype="0" conaffinity="0"/>'
        f"{palm}</body></worldbody>"
        f"<actuator>{''.join(acts)}</actuator></mujoco>"
    )


def dof_qpos_indices(model: object, hand: Hand = "ri") -> NDArray[np.intp]:
    """For each of the 23 DOFs of ``hand`` (vocabulary order), its ``qpos``/``qvel`` index.

    ``model`` is an ``mujoco.MjModel`` built from :func:`hand_model_xml` (hinges only, so
    qpos and qvel indices coincide)."""
    import mujoco

    out = np.empty(23, dtype=np.intp)
    for i, name in enumerate(DOF_NAMES[hand]):
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise ValueError(f"model has no joint {name!r}")
        out[i] = model.jnt_qposadr[jid]  # type: ignore[attr-defined]
    return out


def ramp_ctrl(
    ctrl: NDArray[np.float64], goal: NDArray[np.float64], max_step: NDArray[np.float64] | float
) -> NDArray[np.float64]:
    """Move ``ctrl`` toward ``goal`` in place by at most ``max_step`` (= max_speed x dt).

    The servo speed limit for :class:`ActuatorParams` (``max_speed_rad_s``): call once per
    physics step with ``max_step = max_speed_rad_s * timestep_s``."""
    delta = np.clip(goal - ctrl, -np.asarray(max_step), np.asarray(max_step))
    ctrl += delta
    return ctrl


FINGER_NAMES: tuple[str, ...] = FINGERS


TWO_HANDS_APART_M = 0.3  # the two forearms side by side, this far apart (a puppeteer's)


def two_hands_xml(
    hand_length_m: float = REFERENCE_HAND_LENGTH_M,
    *,
    passive: PassiveParams | None = None,
    actuated: Mapping[str, ActuatorParams] | None = None,
    apart_m: float = TWO_HANDS_APART_M,
    timestep_s: float = 0.001,
) -> str:
    """MJCF text of both hands in one model: :func:`hand_model_xml` of each hand, the
    right forearm at ``y = -apart_m / 2`` and the left at ``+apart_m / 2`` (palms down,
    forearms along x), every body, joint and actuator keeping its hand's prefix.
    ``actuated``: DOF name (of either hand) -> :class:`ActuatorParams`. One model has
    one gravity: the emulated puppet keeps a model per hand (:class:`sim.puppet.Puppet`,
    each forearm's gravity its own); this one draws and poses both hands together."""
    actuated = dict(actuated or {})
    unknown = sorted(set(actuated) - set(DOF_NAMES["ri"]) - set(DOF_NAMES["le"]))
    if unknown:
        raise ValueError(f"actuated names not DOFs of either hand: {unknown}")
    bodies, actuators = [], []
    sides: tuple[tuple[Literal["ri", "le"], float], ...] = (("ri", -apart_m / 2),
                                                          ("le", apart_m / 2))
    for hand, y in sides:
        mine = {k: v for k, v in actuated.items() if k in DOF_NAMES[hand]}
        xml = hand_model_xml(hand, hand_length_m, passive=passive, actuated=mine,
                             timestep_s=timestep_s)
        world = xml[xml.index("<worldbody>") + len("<worldbody>"):xml.index("</worldbody>")]
        bodies.append(f'<body name="{hand}Side" pos="0 {y:.9g} 0">{world}</body>')
        actuators.append(xml[xml.index("<actuator>") + len("<actuator>"):
                             xml.index("</actuator>")])
        head = xml[:xml.index("<worldbody>")]
    head = head.replace('model="handrig_le_hand"', 'model="handrig_two_hands"')
    return (f"{head}<worldbody>{''.join(bodies)}</worldbody>"
            f"<actuator>{''.join(actuators)}</actuator></mujoco>")
