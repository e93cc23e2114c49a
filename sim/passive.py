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
every tuned ks comes out positive. Finger MCP abduction and thumb CMC twist
(absent from Table 2: rest 0) are untuned: their ks is set so that the largest
gravity torque at the rest pose, over all orientations, moves them at most
``untuned_max_sag_deg``.

Damping (Table 1) and "time to relaxed pose"
--------------------------------------------
``kd = factor x ks`` with one factor (in seconds) per group: wrist flexion,
wrist deviation, digits (fingers and thumb), as the paper does. The factors are
found by bisection so that the simulated release tests take Table 1's mean time.
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

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from handrig.config import CONFIG_DIR, check_joint_name, load
from handrig.errors import ConfigError
from handrig.hand import DOF_NAMES
from sim.hand_model import PassiveParams

PASSIVE_CONFIG = CONFIG_DIR / "passive_hand.toml"
MODEL_VERSION = "hand_model 1"  # bump when sim/hand_model.py geometry changes

Orientation = Literal["hang", "palm_down", "thumb_up"]
ORIENTATIONS: dict[str, tuple[float, float]] = {
    # (inclination_deg, rotation_deg) of the paper's three calibration orientations
    "hang": (-90.0, 0.0),
    "palm_down": (0.0, 0.0),
    "thumb_up": (0.0, 90.0),
}
RELEASE_TESTS: tuple[str, ...] = ("wrist_forward", "wrist_side", "fingers")
DAMPING_GROUPS: tuple[str, ...] = ("wrist_flexion", "wrist_deviation", "digits")

# Table 2 of the paper, raw: paper DOF label -> (Angle, Deviation or None).
TABLE2_PAPER: dict[str, tuple[float, float | None]] = {
    "1 CMC Abduction": (42.0, -2.0), "1 CMC Flexion": (28.0, 6.0),
    "1 MCP Flexion": (36.0, 2.0), "1 IP Flexion": (24.0, 2.0),
    "2 MCP Abduction": (1.0, None), "2 MCP Flexion": (40.0, -21.0),
    "2 PIP Flexion": (50.0, -30.0), "2 DIP Flexion": (35.0, -34.0),
    "3 MCP Abduction": (0.0, None), "3 MCP Flexion": (42.0, -21.0),
    "3 PIP Flexion": (50.0, -25.0), "3 DIP Flexion": (38.0, -35.0),
    "4 MCP Abduction": (-1.5, None), "4 MCP Flexion": (42.0, -21.0),
    "4 PIP Flexion": (50.0, -25.0), "4 DIP Flexion": (38.0, -35.0),
    "5 MCP Abduction": (-6.0, None), "5 MCP Flexion": (29.0, -14.0),
    "5 PIP Flexion": (42.0, -24.0), "5 DIP Flexion": (40.0, -28.0),
    "Wrist Side": (0.0, 29.0), "Wrist Forward": (0.0, 22.0),
}
# Paper label -> (vocabulary DOF stem, sign of Deviation in the vocabulary, orientation).
TABLE2_MAP: dict[str, tuple[str, float, Orientation]] = {
    "1 CMC Abduction": ("ThumbCMCy", 1.0, "thumb_up"),
    "1 CMC Flexion": ("ThumbCMCz", 1.0, "palm_down"),
    "1 MCP Flexion": ("ThumbMCPz", 1.0, "thumb_up"),
    "1 IP Flexion": ("ThumbIPz", 1.0, "thumb_up"),
    "Wrist Side": ("WristDeviation", -1.0, "thumb_up"),  # droops ulnar = negative
    "Wrist Forward": ("WristFlexion", 1.0, "palm_down"),
}
for _n, _f in enumerate(("Index", "Middle", "Ring", "Pinky"), start=2):
    TABLE2_MAP[f"{_n} MCP Abduction"] = (f"{_f}MCPx", 1.0, "hang")
    for _j, _s in (("MCP Flexion", "MCPy"), ("PIP Flexion", "PIPy"), ("DIP Flexion", "DIPy")):
        TABLE2_MAP[f"{_n} {_j}"] = (f"{_f}{_s}", 1.0, "hang")
# Table 1: mean and standard deviation of the time to relaxed pose, seconds.
TABLE1_S: dict[str, tuple[float, float]] = {
    "wrist_forward": (0.48, 0.06), "wrist_side": (0.41, 0.06), "fingers": (0.38, 0.13),
}
LOOSE_FIST_DEG: dict[str, float] = {"MCPy": 60.0, "PIPy": 85.0, "DIPy": 55.0}


def table2_vocabulary() -> tuple[dict[str, float], dict[str, tuple[float, Orientation]]]:
    """Table 2 in the vocabulary convention: rest_deg per ``ri`` DOF (23, 0 where the
    table has none) and ``{dof: (deviation_deg, orientation)}`` for the tuned DOFs."""
    rest = dict.fromkeys(DOF_NAMES["ri"], 0.0)
    dev: dict[str, tuple[float, Orientation]] = {}
    for label, (angle, deviation) in TABLE2_PAPER.items():
        stem, sign, orient = TABLE2_MAP[label]
        rest["ri" + stem] = angle
        if deviation is not None:
            dev["ri" + stem] = (sign * deviation, orient)
    return rest, dev


@dataclass(frozen=True)
class Calibration:
    """One tuned DOF: sag from rest (degrees, vocabulary convention) in an orientation."""

    deviation_deg: float
    orientation: Orientation


@dataclass(frozen=True)
class Tuned:
    """Values written by ``handrig passive tune`` (do not edit by hand)."""

    inputs_sha256: str
    ks_nm_per_rad: dict[str, float]
    kd_per_ks_s: dict[str, float]  # keys DAMPING_GROUPS


@dataclass(frozen=True)
class PassiveHandConfig:
    """``config/passive_hand.toml``: the relaxed-hand model's inputs and tuned gains."""

    hand_length_m: float
    limit_gain_factor: float
    untuned_max_sag_deg: float
    relaxed_fraction: float
    rest_deg: dict[str, float]
    calibration: dict[str, Calibration]
    release_s: dict[str, tuple[float, float]]
    tuned: Tuned | None = None
    source: str = field(default="", compare=False)

    def check(self) -> None:
        if not 0.10 <= self.hand_length_m <= 0.30:
            raise ConfigError("implausible hand length", key="hand_length_m",
                              value=self.hand_length_m, allowed="0.10 .. 0.30 m")
        if self.limit_gain_factor < 1.0:
            raise ConfigError("limit gain must exceed the normal gain",
                              key="limit_gain_factor", value=self.limit_gain_factor,
                              allowed=">= 1 (the paper: many times higher)")
        if not 0.0 < self.untuned_max_sag_deg <= 20.0:
            raise ConfigError("out of range", key="untuned_max_sag_deg",
                              value=self.untuned_max_sag_deg, allowed="0 < x <= 20")
        if not 0.5 <= self.relaxed_fraction < 1.0:
            raise ConfigError("out of range", key="relaxed_fraction",
                              value=self.relaxed_fraction, allowed="0.5 <= x < 1")
        missing = [n for n in DOF_NAMES["ri"] if n not in self.rest_deg]
        if missing:
            raise ConfigError("rest pose incomplete", key=f"rest_deg.{missing[0]}",
                              allowed="all 23 ri DOF names")
        for name in self.rest_deg:
            check_joint_name(name, f"rest_deg.{name}")
            if name not in DOF_NAMES["ri"]:
                raise ConfigError("not a right-hand relaxed-hand DOF", key=f"rest_deg.{name}",
                                  allowed="the 23 ri DOF names")
        for name in self.calibration:
            if name not in DOF_NAMES["ri"]:
                raise ConfigError("not a right-hand relaxed-hand DOF",
                                  key=f"calibration.{name}", allowed="the 23 ri DOF names")
        for test in RELEASE_TESTS:
            if test not in self.release_s:
                raise ConfigError("missing release test", key=f"release_s.{test}",
                                  allowed=", ".join(RELEASE_TESTS))
        if self.tuned is not None:
            for name in DOF_NAMES["ri"]:
                if name not in self.tuned.ks_nm_per_rad:
                    raise ConfigError("missing", key=f"tuned.ks_nm_per_rad.{name}")
            for g in DAMPING_GROUPS:
                if g not in self.tuned.kd_per_ks_s:
                    raise ConfigError("missing", key=f"tuned.kd_per_ks_s.{g}",
                                      allowed=", ".join(DAMPING_GROUPS))

    def inputs_sha256(self) -> str:
        """Hash of everything the tuned gains depend on (and of the model version)."""
        data = {
            "model": MODEL_VERSION, "hand_length_m": self.hand_length_m,
            "limit_gain_factor": self.limit_gain_factor,
            "untuned_max_sag_deg": self.untuned_max_sag_deg,
            "relaxed_fraction": self.relaxed_fraction,
            "rest_deg": self.rest_deg, "release_s": self.release_s,
            "calibration": {k: [c.deviation_deg, c.orientation]
                            for k, c in self.calibration.items()},
        }
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()

    @property
    def is_tuned(self) -> bool:
        """True when tuned gains are present and match the current inputs."""
        return self.tuned is not None and self.tuned.inputs_sha256 == self.inputs_sha256()

    def group_of(self, name: str) -> str:
        """The damping group of DOF ``name``."""
        stem = name[2:]
        if stem == "WristFlexion":
            return "wrist_flexion"
        if stem == "WristDeviation":
            return "wrist_deviation"
        return "digits"

    def springs(self) -> PassiveParams:
        """Rest, ks and kd per ``ri`` DOF for ``sim.hand_model.hand_model_xml``."""
        if self.tuned is None or not self.is_tuned:
            state = "missing" if self.tuned is None else "stale (inputs changed)"
            raise ConfigError(f"tuned gains {state}; run `handrig passive tune`",
                              file=self.source or str(PASSIVE_CONFIG), key="tuned")
        ks = self.tuned.ks_nm_per_rad
        kd = {n: self.tuned.kd_per_ks_s[self.group_of(n)] * ks[n] for n in DOF_NAMES["ri"]}
        return PassiveParams(rest_deg=dict(self.rest_deg), ks_nm_per_rad=dict(ks),
                             kd_nms_per_rad=kd)


def load_passive_params(path: str | Path | None = None) -> PassiveHandConfig:
    """Load ``config/passive_hand.toml`` (or ``path``)."""
    p = Path(path) if path is not None else PASSIVE_CONFIG
    cfg = load(p, PassiveHandConfig)
    return PassiveHandConfig(**{**cfg.__dict__, "source": str(p)})


def radians(deg: float) -> float:
    """Degrees to radians (MuJoCo models here are built with ``angle="radian"``)."""
    return math.radians(deg)
