"""``handrig bake``: bake the relaxed-hand sag grid from the MuJoCo model (``sim/``).

Static equilibrium solves by default (fast); ``--dynamic`` uses the dynamic settle
sweep instead, ``--compare`` runs both and reports their difference. ``--plot``
draws every DOF over inclination x rotation next to the grid; ``--report DIR``
writes the plot and a JSON summary (timings, solver statistics, comparison) there.

The installed grid (``config/sag_grid.npz``) is never rewritten unless ``--out``
names it: by default the grid goes to the user's data directory
(``$XDG_DATA_HOME/handrig/sag_grid.npz``, ``~/.local/share/handrig`` when
unset), and a rig uses it through ``sag_grid`` in the ``[loop]`` table of its
``rig.toml``. The shipped grid is regenerated with ``--out config/sag_grid.npz``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from handrig.cli._numbers import positive_float
from handrig.config.paths import DATA_HOME_HELP, config_file, user_data


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "bake", help="bake the passive-sag grid (23 DOFs over forearm inclination x rotation)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--step-deg", type=positive_float, default=2.5,
                   help="grid step in degrees, dividing 90 (default 2.5; 5 gives 37 x 72)")
    p.add_argument("--fine-step-deg", type=positive_float, default=None,
                   help="step in the palm-up band (inclination 0..45, |rotation| >= 100)"
                        " where the fingers bend fastest; 0 = no band (default step / 2.5:"
                        " 1 at step 2.5, 100 x 240 samples, the shipped grid)")
    p.add_argument("--out", default=None, metavar="FILE.npz",
                   help=f"output grid (default sag_grid.npz in {DATA_HOME_HELP}; the installed "
                        "config/sag_grid.npz only when named here)")
    p.add_argument("--config", default=None, metavar="FILE",
                   help="passive-hand TOML (default: yours from `handrig passive tune` if "
                        "there is one, else the installed config/passive_hand.toml)")
    p.add_argument("--dynamic", action="store_true",
                   help="bake with the dynamic settle sweep (slow reference) instead")
    p.add_argument("--compare", action="store_true",
                   help="also run the other solver and report the difference")
    p.add_argument("--plot", action="store_true",
                   help="also write the plot next to the grid (<out>.png): each DOF as a map")
    p.add_argument("--report", default=None, metavar="DIR",
                   help="write sag_grid.png and bake_report.json into DIR")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from handrig.app import simulator
    bake = simulator.baker()
    load_passive_params = simulator.relaxed_hand().load_passive_params

    fine = args.step_deg / 2.5 if args.fine_step_deg is None else args.fine_step_deg or None
    bake.grid_axes(args.step_deg, fine)  # validates the steps before any work
    cfg = load_passive_params(args.config or config_file("passive_hand.toml"))
    out = Path(args.out) if args.out else user_data("sag_grid.npz")
    out.parent.mkdir(parents=True, exist_ok=True)
    primary = bake.bake_dynamic if args.dynamic else bake.bake_static
    other = bake.bake_static if args.dynamic else bake.bake_dynamic
    columns = (TextColumn("{task.description}"), BarColumn(),
               TextColumn("{task.completed}/{task.total} rotations"), TimeElapsedColumn())
    with Progress(*columns, disable=args.quiet, transient=False) as progress:
        name = "dynamic settle" if args.dynamic else "static solve"
        task = progress.add_task(f"baking ({name})", total=None)

        def tick(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        grid = primary(cfg, args.step_deg, fine_step_deg=fine, progress=tick)
        cmp: dict[str, Any] | None = None
        if args.compare:
            task = progress.add_task("reference (other solver)", total=None)
            ref = other(cfg, args.step_deg, fine_step_deg=fine, progress=tick)
            cmp = {"other_solver": ref.metadata["solver"],
                   "other_seconds": ref.metadata["seconds"], **bake.compare(grid, ref)}
            grid.metadata["comparison"] = cmp
    path = grid.save(out)
    meta = grid.metadata
    n_inc, n_rot = grid.dofs_deg.shape[:2]
    print(f"wrote {path}: {n_inc} x {n_rot} samples ({meta['solver']}) in"
          f" {meta['seconds']:.2f} s")
    if "unstable_samples" in meta:
        print(f"  Newton iterations per sample {meta['newton_iterations_mean']:.2f}, max residual"
              f" {meta['max_residual_nm']:.1e} N m, unstable samples {meta['unstable_samples']}")
    print(f"  limit overshoot clipped: {meta['max_limit_overshoot_deg']:.3f} deg")
    if cmp is not None:
        print(f"  vs {cmp['other_solver']} ({cmp['other_seconds']:.1f} s): max"
              f" {cmp['max_deg']:.4f} deg, median {cmp['median_deg']:.2e} deg")
    if args.plot:
        print(f"plot: {bake.plot(grid, path.with_suffix('.png'))}")
    if not args.out:
        print("  `handrig run` and `handrig demo` read it from now on (your baked grid) unless "
              "the rig file's [loop] sag_grid names another; delete it to go back to the "
              "shipped config/sag_grid.npz")
    else:
        print(f"  to use it: sag_grid = \"{path}\" in the [loop] table of the rig file")
    if args.report:
        rdir = Path(args.report)
        rdir.mkdir(parents=True, exist_ok=True)
        png = bake.plot(grid, rdir / "sag_grid.png")
        summary = {k: v for k, v in meta.items()
                   if k not in ("ks_nm_per_rad", "kd_nms_per_rad", "rest_deg")}
        (rdir / "bake_report.json").write_text(json.dumps(summary, indent=2) + "\n")
        print(f"report: {png}, {rdir / 'bake_report.json'}")
    return 0
