"""Shared argument handling of fit-map, expand and evaluate (not a command)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

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
    p.add_argument("--no-condition", action="store_true",
                   help="use the capture as recorded, without the profile's calibration"
                   " offsets ([calibration] in the profile)")


def load(path: str, args: argparse.Namespace, *, condition: bool | None = None
         ) -> mocap.MocapCurves:
    """The file's vocabulary curves; ``condition`` None: unless ``--no-condition``."""
    cond = not args.no_condition if condition is None else condition
    return mocap.load_curves(path, args.profile, "vocabulary", fps=args.fps,
                             despike=args.despike, condition=cond)


def conditioning_report(path: str, m: mocap.MocapCurves, args: argparse.Namespace
                        ) -> tuple[dict[str, object], list[str]]:
    """What conditioning did to ``m`` (loaded from ``path``): the offsets added, the
    fraction of frames outside the joint limits as recorded and as conditioned, and the
    offsets the file itself suggests on top. JSON object and text lines."""
    from handrig.offline import conditioning

    raw = m if m.offsets_deg is None else load(path, args, condition=False)
    before = conditioning.outside_fraction(raw.curves)
    after = conditioning.outside_fraction(m.curves)
    added = m.offsets_deg if m.offsets_deg is not None else np.zeros(len(m.names))
    more = conditioning.find_offsets(m.curves)

    def named(v: NDArray[np.float64], nd: int = 4) -> dict[str, float]:
        return {n: round(float(x), nd) for n, x in zip(m.names, v, strict=True) if x}

    obj: dict[str, object] = {
        "applied": m.offsets_deg is not None, "offsets_deg": named(added, 2),
        "outside_limits_as_recorded": named(before), "outside_limits": named(after),
        "offsets_this_file_suggests_deg": named(more, 2),
    }

    def worst(frac: NDArray[np.float64]) -> str:
        top = [(f, n) for f, n in sorted(zip(frac, m.names, strict=True), reverse=True)[:3]
               if f > 0]
        return ", ".join(f"{n} {f:.1%}" for f, n in top) or "none"

    if m.offsets_deg is not None:
        lines = [f"conditioning: {int(np.count_nonzero(added))} calibration offsets of profile"
                 f" {m.profile} added (" + ", ".join(f"{n} {v:+.1f}" for n, v in
                                                    named(added, 1).items()) + ")",
                 f"  frames outside the joint limits, as recorded: {worst(before)};"
                 f" conditioned: {worst(after)}"]
    else:
        lines = [f"conditioning: none (--no-condition, or profile {m.profile} has no"
                 f" [calibration]); frames outside the joint limits: {worst(after)}"]
    extra = named(more, 1)
    lines.append("  further offsets this file suggests: " + (", ".join(
        f"{n} {v:+.1f}" for n, v in extra.items()) if extra else "none"))
    return obj, lines


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
