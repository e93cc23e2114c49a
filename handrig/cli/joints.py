"""``handrig joints``: the hand vocabulary, with limits."""

from __future__ import annotations

import argparse
import json
from typing import Any

from handrig import hand
from handrig.config.loading import load_joint_limits


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "joints", help="list the 50 curves and 23 DOFs per hand, with axes and limits"
    )
    p.add_argument("--limits", default=None, help="joint-limit overrides TOML file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    limits = load_joint_limits(args.limits)
    rows: list[dict[str, Any]] = []
    for c in hand.CURVES:
        low, high = limits.of(c.name)
        rows.append({"name": c.name, "motion": c.motion.value, "limits_deg": [low, high],
                     "relaxed_hand_dof": c.name in hand.DOF_NAMES[c.hand]})
    wrist: list[dict[str, Any]] = [
        {"name": d.name, "motion": d.motion.value, "limits_deg": list(limits.of(d.name))}
        for h in hand.HANDS for d in hand.DOFS[h] if d.curve is None
    ]
    if args.json:
        print(json.dumps({"curves": rows, "wrist_dofs": wrist}))
        return 0
    print(f"{'curve':<18} {'motion':<10} {'limits (deg)':>16}  relaxed-hand DOF")
    for r in rows:
        lo, hi = r["limits_deg"]
        print(f"{r['name']:<18} {r['motion']:<10} {lo:>7.1f} .. {hi:<6.1f}  "
              f"{'yes' if r['relaxed_hand_dof'] else 'no (no DOF in the 23-DOF model)'}")
    for w in wrist:
        lo, hi = w["limits_deg"]
        print(f"{w['name']:<18} {w['motion']:<10} {lo:>7.1f} .. {hi:<6.1f}  yes (wrist)")
    print(f"{len(rows)} curves ({hand.CURVES_PER_HAND} per hand), "
          f"{hand.DOFS_PER_HAND} relaxed-hand DOFs per hand")
    return 0
