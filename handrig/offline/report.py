"""Markdown and PNG report of an analysis (the equivalents of the paper's tables and figures).

Figures are drawn with matplotlib's Agg backend (no display needed): histogram of the
ranges (paper fig. 4), histograms of rmsd1 and rmsd2 over all pairs (figs. 6, 7),
scatter plots of the strongest pairs (figs. 2, 5), original vs rebuilt curves
(figs. 8, 9).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handrig import hand
from handrig.errors import DataError
from handrig.offline.analysis import Analysis, FloatArray, Stage, rebuild


def _fmt(x: float) -> str:
    return f"{x:.3f}" if abs(x) < 1 else f"{x:.2f}"


def tables_markdown(an: Analysis) -> str:
    """Tables 1-5 of the paper, for this motion, as Markdown."""
    th = an.thresholds
    out: list[str] = []
    small = [i for i in range(len(an.names)) if an.range_deg[i] < th.range_small_deg]
    out += [f"## Table 1: curves with a range below {th.range_small_deg:g} deg", "",
            "| curve | range (deg) | mean (deg) |", "|---|---:|---:|"]
    out += [f"| {an.names[i]} | {_fmt(an.range_deg[i])} | {an.mean_deg[i]:.1f} |" for i in small]
    out += ["", _links_table(
        an, an.stages[2], f"Table 2: relationships with rmsd < {th.rmsd_strict:g}"), ""]
    mid = [i for i in range(len(an.names))
           if th.range_small_deg <= an.range_deg[i] < th.range_large_deg]
    out += [f"## Table 3: curves with a range between {th.range_small_deg:g} and"
            f" {th.range_large_deg:g} deg", "",
            "| curve | range (deg) | mean (deg) |", "|---|---:|---:|"]
    out += [f"| {an.names[i]} | {_fmt(an.range_deg[i])} | {an.mean_deg[i]:.1f} |" for i in mid]
    before = {lk.dependent: lk.controller for lk in an.stages[2].links}
    changed = tuple(lk for lk in an.stages[4].links if before.get(lk.dependent) != lk.controller)
    out += ["", _links_table(
        an, Stage(an.stages[4].condition, an.stages[4].dofs_left, (), changed),
        f"Table 4: added or changed relationships with rmsd < {th.rmsd_loose:g}"), ""]
    out += ["## Table 5: remaining degrees of freedom", "", "| condition | DOFs left |",
            "|---|---:|"]
    out += [f"| {s.condition} | {s.dofs_left} |" for s in an.stages]
    out += ["", "## Free curves at the last stage", "", ", ".join(an.stages[4].free), "",
            "## Pairs below the rmsd thresholds (curves with range >="
            f" {th.range_small_deg:g} deg)", "", "| threshold | rmsd1 | rmsd2 |", "|---|---:|---:|"]
    out += [f"| {t} | {c['rmsd1']} | {c['rmsd2']} |" for t, c in an.pairs_below.items()]
    return "\n".join(out) + "\n"


def _links_table(an: Analysis, stage: Stage, title: str) -> str:
    rows = [f"## {title}", "", "| dependent curve | controlling curve | rmsd | via |",
            "|---|---|---|---|"]
    for lk in stage.links:
        via = "" if lk.partner == lk.controller else lk.partner
        rows.append(f"| {lk.dependent} | {lk.controller} | {lk.metric} = {lk.rmsd:.2f} | {via} |")
    return "\n".join(rows)


def strongest_pairs(an: Analysis, count: int = 4) -> list[tuple[int, int, int, float]]:
    """(a, b, slope, rmsd) of the most linear pairs among curves left after range<1.

    Only pairs across digits, like the paper's ring/pinky MCP pair (fig. 2): within a
    digit a capture device may copy one joint to another (PIP = DIP, see the mocap README).
    """
    active = an.range_deg >= an.thresholds.range_small_deg
    k = len(an.names)
    best = np.minimum(an.rmsd1, an.rmsd2)
    iu = np.triu_indices(k, 1)
    digit = np.array([(c.hand + c.digit) if hand.is_joint_name(n) and (c := hand.curve(n))
                      else n for n in an.names])
    keep = active[iu[0]] & active[iu[1]] & (digit[iu[0]] != digit[iu[1]])
    order = np.argsort(best[iu][keep])
    out: list[tuple[int, int, int, float]] = []
    seen: set[tuple[str, str]] = set()
    for o in order:  # one pair per pair of digits, the strongest
        a, b = int(iu[0][keep][o]), int(iu[1][keep][o])
        if (digit[a], digit[b]) in seen:
            continue
        seen.add((digit[a], digit[b]))
        slope = 1 if an.rmsd1[a, b] <= an.rmsd2[a, b] else -1
        out.append((a, b, slope, float(best[a, b])))
        if len(out) == count:
            break
    return out


def write_report(an: Analysis, curves: FloatArray, out_dir: str | Path, *, title: str,
                 fps: float, notes: list[str] | None = None) -> Path:
    """Write ``report.md`` and the PNG figures into ``out_dir``; return the Markdown path."""
    # Figure objects, not pyplot: no global figure registry, no backend switch in the
    # caller's process, nothing left for the garbage collector (as sim.bake.plot)
    from matplotlib.figure import Figure

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"cannot create report directory {out}: {exc}") from None
    k = len(an.names)
    iu = np.triu_indices(k, 1)

    fig = Figure(figsize=(6, 3.5))
    ax = fig.subplots()
    ax.hist(an.range_deg, bins=list(np.arange(0, max(5.0, float(an.range_deg.max())) + 5, 5)))
    ax.set_xlabel("range (deg)")
    ax.set_ylabel("curves")
    ax.set_title(f"Ranges of the {k} rotation curves")
    fig.tight_layout()
    fig.savefig(out / "ranges.png", dpi=100)

    for name, mat in (("rmsd1", an.rmsd1), ("rmsd2", an.rmsd2)):
        fig = Figure(figsize=(6, 3.5))
        ax = fig.subplots()
        ax.hist(mat[iu], bins=list(np.linspace(0.0, 2.0, 41)))
        ax.set_xlabel(name)
        ax.set_ylabel("pairs")
        ax.set_title(f"Distribution of the {len(iu[0])} values of {name}")
        fig.tight_layout()
        fig.savefig(out / f"{name}.png", dpi=100)

    pairs = strongest_pairs(an)
    if pairs:
        fig = Figure(figsize=(3.2 * len(pairs), 3.2))
        axes = fig.subplots(1, len(pairs), squeeze=False)
        for ax, (a, b, slope, r) in zip(axes[0], pairs, strict=True):
            ax.plot(curves[:, b], curves[:, a], "-", lw=0.4, color="0.7")
            ax.plot(curves[:, b], curves[:, a], ".", ms=2)
            ax.set_xlabel(an.names[b])
            ax.set_ylabel(an.names[a])
            ax.set_title(f"rmsd{1 if slope > 0 else 2} = {r:.2f}", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / "strongest_pairs.png", dpi=100)

    final = an.stages[4]
    rebuilt = rebuild(curves, final, an.names)
    idx = {n: i for i, n in enumerate(an.names)}
    shown = sorted(final.links, key=lambda lk: -an.std_deg[idx[lk.dependent]])[:4]
    if shown:
        t_s = np.arange(curves.shape[0]) / fps
        fig = Figure(figsize=(8, 2.0 * len(shown)))
        axes = fig.subplots(len(shown), 1, squeeze=False)
        for ax, lk in zip(axes[:, 0], shown, strict=True):
            i = idx[lk.dependent]
            ax.plot(t_s, curves[:, i], lw=0.8, label="original")
            ax.plot(t_s, rebuilt[:, i], lw=0.8, label=f"from {lk.controller}")
            ax.set_ylabel(f"{lk.dependent}\n(deg)", fontsize=8)
            ax.legend(fontsize=7, loc="upper right")
        axes[-1, 0].set_xlabel("time (s)")
        fig.tight_layout()
        fig.savefig(out / "rebuilt.png", dpi=100)

    err = np.sqrt(np.mean((rebuilt - curves) ** 2))
    md = [f"# Dimensionality of finger motion: {title}", "",
          f"{an.n_frames} frames at {fps:.3g} fps, {k} curves (Jörg & O'Sullivan, sections"
          " 4-5). Curve values are the BVH channel angles in degrees as the profile maps them.",
          ""]
    md += [f"- {n}" for n in notes or []]
    md += ["", tables_markdown(an),
           f"RMS difference, all curves, between the original and the motion rebuilt at the"
           f" last stage ({final.dofs_left} DOFs): {err:.2f} deg.", "",
           "## Figures", "", "![ranges](ranges.png)", "", "![rmsd1](rmsd1.png)", "",
           "![rmsd2](rmsd2.png)", ""]
    if pairs:
        md += ["![strongest pairs](strongest_pairs.png)", ""]
    if shown:
        md += ["![original vs rebuilt](rebuilt.png)", ""]
    path = out / "report.md"
    path.write_text("\n".join(md))
    return path
