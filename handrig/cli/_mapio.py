"""Shared argument handling of fit-map, expand and evaluate (not a command)."""

from __future__ import annotations

import argparse
from pathlib import Path

from handrig import hand
from handrig.cli._numbers import positive_float
from handrig.errors import DataError
from handrig.offline import mocap


def add_input_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--profile", default="perception_neuron",
                   help="joint-mapping profile name or .toml path (default perception_neuron)")
    p.add_argument("--despike", action="store_true",
                   help="repair NaN/absurd values and single-frame spikes by interpolation")
    p.add_argument("--fps", type=positive_float, default=None,
                   help="resample to this frame rate first (default: the file's rate)")


def load(path: str, args: argparse.Namespace) -> mocap.MocapCurves:
    return mocap.load_curves(path, args.profile, "vocabulary", fps=args.fps,
                             despike=args.despike)


def parse_controls(text: str) -> tuple[str, ...]:
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    if not names:
        raise DataError("--controls needs at least one curve name, e.g. riIndexMCPy,riPinkyMCPy")
    for n in names:
        hand.curve(n)  # UnknownJointError (a HandrigError) with a suggestion
    return names


def is_reference(path: str | Path, n_frames: int) -> bool:
    """True for the shipped reference capture (its gesture clips are known)."""
    return Path(path).name == mocap.REFERENCE_BVH.name and n_frames == 1063
