"""``handrig passive``: tune and check the relaxed-hand model (Neff & Seidel) in MuJoCo.

``handrig passive check [--json]`` runs the paper's three calibration orientations and
its release tests on the tuned model and prints paper value vs model value.
``handrig passive tune`` recomputes ks (equation 4) and the damping factors (Table 1)
and writes the file with a new ``[tuned]`` table: to ``--out``, by default back
to ``--config`` when that is your own file, else to your own copy
(``$XDG_CONFIG_HOME/handrig/passive_hand.toml``, ``~/.config/handrig`` when unset);
the installed ``config/passive_hand.toml`` is never rewritten unless named.
Both verbs (and ``handrig bake``) read your own copy when there is one.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from handrig.config.paths import CONFIG_HOME_HELP, config_file, output_for

CONFIG_HELP = (f"passive-hand TOML (default: passive_hand.toml in {CONFIG_HOME_HELP}, else "
               "the installed config/passive_hand.toml)")


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "passive", help="tune or check the relaxed-hand (passive sag) model",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    c = verbs.add_parser("check", help="calibration poses and release tests: paper vs model")
    c.add_argument("--config", default=None, help=CONFIG_HELP)
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_check)
    t = verbs.add_parser("tune", help="re-tune ks and kd and rewrite the [tuned] table")
    t.add_argument("--config", default=None, help=CONFIG_HELP)
    t.add_argument("--out", default=None,
                   help="where to write (default: the --config file if it is yours, else "
                        "passive_hand.toml in the user config directory; the installed file "
                        "is never rewritten)")
    t.set_defaults(func=run_tune)


def run_check(args: argparse.Namespace) -> int:
    from handrig.app import simulator
    cfg = simulator.relaxed_hand().load_passive_params(
        args.config or config_file("passive_hand.toml"))
    result = simulator.relaxed_hand_tuning().check(cfg)
    ok = all(bool(v["ok"]) for part in result.values() for v in part.values())
    if args.json:
        print(json.dumps(result))
        return 0 if ok else 1
    print(f"{'DOF':<18} {'orientation':<10} {'paper':>7} {'model':>8}  (sag from rest, deg)")
    for name, v in result["deviations"].items():
        mark = "" if v["ok"] else "  OUTSIDE 1 deg"
        print(f"{name:<18} {v['orientation']!s:<10} {v['paper']:>+7.1f} {v['model']:>+8.2f}"
              f"{mark}")
    print(f"\n{'release test':<14} {'paper (s)':>12} {'model (s)':>10}   time to"
          f" {cfg.relaxed_fraction:.0%} of the change")
    for name, v in result["relaxation_s"].items():
        mark = "" if v["ok"] else "  OUTSIDE mean +- std"
        print(f"{name:<14} {v['paper']:>5.2f} +- {v['std']:.2f} {v['model']:>10.3f}{mark}")
    print("all within tolerance" if ok else "NOT all within tolerance")
    return 0 if ok else 1


def run_tune(args: argparse.Namespace) -> int:
    from handrig.app import simulator
    tuning = simulator.relaxed_hand_tuning()

    src = Path(args.config) if args.config else config_file("passive_hand.toml")
    cfg = simulator.relaxed_hand().load_passive_params(src)
    tuned = tuning.tune_config(cfg)
    out = Path(args.out) if args.out else output_for(src, "passive_hand.toml")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(tuning.render_config(tuned), encoding="utf-8")
    factors = tuned.tuned.kd_per_ks_s if tuned.tuned is not None else {}
    print(f"wrote {out}: damping factors kd/ks (s) "
          + ", ".join(f"{k}={v:.4f}" for k, v in factors.items()))
    return 0
