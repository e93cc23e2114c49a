"""The relaxed hand's inputs and tuned gains: ``config/passive_hand.toml``.

The paper's tables (Neff & Seidel, Table 1 and Table 2, mapped to the vocabulary
convention as ``sim/passive.py`` explains), the config file's dataclasses and the
springs they give the MJCF hand (:class:`PassiveParams`). Both the hand model
(``sim.hand_model``, for its default springs) and the relaxed-hand solver
(``sim.passive``) import this module; it imports neither.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from handrig.config.loading import CONFIG_DIR, check_joint_name, load
from handrig.errors import ConfigError
from handrig.hand import DOF_NAMES


@dataclass(frozen=True)
class PassiveParams:
    """Per-DOF spring parameters keyed by the ``ri`` DOF names (``riIndexMCPy``); the
    left hand uses the same values (the vocabulary convention is anatomical).

    ``rest_deg``: set point (equation 1), vocabulary convention.
    ``ks_nm_per_rad``: stiffness; ``kd_nms_per_rad``: damping.
    """

    rest_deg: Mapping[str, float]
    ks_nm_per_rad: Mapping[str, float]
    kd_nms_per_rad: Mapping[str, float]


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
# Gain factor with the forearm pointing straight up ("Raised hand" in the module docstring).
RAISED_STIFFNESS_FACTOR = 3.0


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
    raised_stiffness_factor: float
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
        if not 1.0 <= self.raised_stiffness_factor <= 20.0:
            raise ConfigError("out of range", key="raised_stiffness_factor",
                              value=self.raised_stiffness_factor,
                              allowed="1 (the fully relaxed hand everywhere) .. 20")
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
            "raised_stiffness_factor": self.raised_stiffness_factor,
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


# --------------------------------------------------------------------------- model
