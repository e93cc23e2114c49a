"""``handrig sag``: the relaxed hand's 23 DOF values at one forearm orientation."""

from __future__ import annotations

import argparse
import json
from typing import Any

from handrig.cli._numbers import finite_float
from handrig.cli._rig import add_rig_argument


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "sag", help="look up the passive-sag pose at a forearm orientation")
    p.add_argument("--grid", default=None, metavar="FILE.npz",
                   help="baked grid (default: the rig's grid as a run chooses it: the rig "
                   "file's [loop] sag_grid, else your baked grid in $XDG_DATA_HOME/handrig "
                   "(from `handrig bake`), else the shipped config/sag_grid.npz)")
    add_rig_argument(p, old_name=False)
    p.add_argument("--inclination", type=finite_float, required=True, metavar="DEG",
                   help="forearm above horizontal: -90 hanging down .. 90 pointing up")
    p.add_argument("--rotation", type=finite_float, required=True, metavar="DEG",
                   help="about the forearm: 0 palm down, 90 thumb up, 180 palm up")
    p.add_argument("--hand", choices=("ri", "le"), default="ri", help="DOF names of this hand")
    p.add_argument("--json", action="store_true", help='print {"dofs": {name: degrees}}')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from handrig.errors import DataError
    from handrig.pose.sag import SagGrid

    if not -90.0 <= args.inclination <= 90.0:
        raise DataError(f"--inclination {args.inclination}: must be within -90..90 degrees")
    from handrig.app.sources import grid_file, rig_file
    from handrig.pose.robot_rig import load_rig

    path = args.grid
    if path is None:
        rig = rig_file(args.rig).path
        path = grid_file(rig, load_rig(rig)).path
    grid = SagGrid.load(path, hand=args.hand)
    values = grid.lookup(args.inclination, args.rotation)
    offsets = values - grid.rest_deg
    if args.json:
        print(json.dumps({"dofs": {n: round(float(v), 4)
                                   for n, v in zip(grid.dof_names, values, strict=True)}}))
        return 0
    print(f"inclination {args.inclination:g} deg, rotation {args.rotation:g} deg"
          f" ({grid.source})")
    print(f"{'DOF':<18} {'value':>8} {'rest':>7} {'sag':>7}   (degrees)")
    for n, v, r, o in zip(grid.dof_names, values, grid.rest_deg, offsets, strict=True):
        print(f"{n:<18} {v:>8.2f} {r:>7.1f} {o:>+7.2f}")
    return 0
