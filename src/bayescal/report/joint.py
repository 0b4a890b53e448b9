"""The figure of ``bayescal joint``: each parameter's posterior from each record and jointly."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from bayescal.calibration.posterior import Posterior
from bayescal.report.figures import label, save_figure

__all__ = ["interval_cell", "joint_markdown", "plot_joint"]

BINS = 40


def _column(post: Posterior, name: str) -> np.ndarray | None:
    """The draws of ``name`` (a parameter or a derived quantity) in ``post``, or None
    where it is not calibrated there."""
    if name in post.derived:
        column = post.derived[name].draws.reshape(-1)
    elif name in post.names:
        column = post.draws.reshape(-1, len(post.names))[:, post.names.index(name)]
    else:
        return None
    return None if np.ptp(column) == 0.0 else column


def _axis_label(post: Posterior, name: str) -> str:
    unit = post.derived[name].unit if name in post.derived else post.priors[name].unit
    return f"{name} [{unit}]" if unit else label(name)


def plot_joint(path: str | Path, joint: Posterior, alone: Mapping[str, Posterior]) -> Path:
    """One panel per parameter and derived quantity of ``joint``: the histogram of each
    study's own posterior (outlines) and of the joint one (filled), their 95 % intervals
    below.

    Parameters
    ----------
    path
        PNG file to write.
    joint
        The joint posterior.
    alone
        Study name -> its own posterior.
    """
    names = [*joint.names, *joint.derived]
    cols = min(len(names), 3)
    rows = -(-len(names) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    colours = [f"C{k}" for k in range(10)]
    for ax, name in zip(axes.flat, names, strict=False):
        sources = [(s, c) for s, p in alone.items() if (c := _column(p, name)) is not None]
        together = _column(joint, name)
        columns = [c for _, c in sources] + ([] if together is None else [together])
        if not columns:  # constant everywhere: nothing to draw
            ax.set_visible(False)
            continue
        low = min(float(np.quantile(c, 0.001)) for c in columns)
        high = max(float(np.quantile(c, 0.999)) for c in columns)
        edges = np.linspace(low, high, BINS + 1) if high > low else BINS
        for k, (source, column) in enumerate(sources):
            colour = colours[k % len(colours)]
            ax.hist(
                column,
                bins=edges,
                density=True,
                histtype="step",
                lw=1.4,
                color=colour,
                label=source,
            )
        if together is not None:
            ax.hist(together, bins=edges, density=True, color="0.25", alpha=0.35, label="joint")
        bottom = ax.get_ylim()[1]
        items = [*sources, *([] if together is None else [("joint", together)])]
        for k, (source, column) in enumerate(items):
            lo, hi = np.quantile(column, [0.025, 0.975])
            colour = "0.25" if source == "joint" else colours[k % len(colours)]
            y = -bottom * 0.06 * (k + 1)
            ax.plot([lo, hi], [y, y], color=colour, lw=2.5, solid_capstyle="butt")
        ax.set_ylim(-bottom * 0.06 * (len(items) + 1), bottom)
        ax.set_yticks([])
        ax.set_xlabel(_axis_label(joint, name))
    for ax in list(axes.flat)[len(names) :]:
        ax.set_visible(False)
    shown = [ax for ax in axes.flat if ax.get_visible()]
    if shown:
        shown[0].legend(fontsize=8, frameon=False)
    fig.suptitle("Each record alone and both together (bars: 95 % intervals)", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def interval_cell(by: pd.DataFrame, source: str) -> str:
    """``mean [lower, upper]`` of ``source``'s row in ``by`` (a summary indexed by source)."""
    mean, low, high = by.loc[source, ["mean", "lower", "upper"]].to_numpy(dtype=float)
    return f"{mean:.4g} [{low:.4g}, {high:.4g}]"


def joint_markdown(
    summary: pd.DataFrame,
    labels: Sequence[str],
    warnings: Sequence[str],
    figure: str,
    notes: Sequence[str] = (),
) -> str:
    """``joint.md``: the warnings first, then each parameter's mean and 95 % interval
    from each study alone and jointly, then the figure."""
    sources = [*labels, "joint"]
    lines = ["# Joint calibration", ""]
    lines += [f"**WARNING:** {w}" for w in warnings]
    if warnings:
        lines.append("")
    lines += [
        "Means [95 % intervals]: each study alone, then all records together.",
        "",
        "| quantity | unit | " + " | ".join(sources) + " |",
        "|---|---|" + "---|" * len(sources),
    ]
    for name, group in summary.groupby("parameter", sort=False):
        by = group.set_index("source")
        cells = [interval_cell(by, s) if s in by.index else "–" for s in sources]
        unit = str(group["unit"].iloc[0])
        lines.append(f"| {name!s} | {unit} | " + " | ".join(cells) + " |")
    lines += [""] + [f"Note: {n}" for n in notes] + ([""] if notes else [])
    lines += [f"![each record alone and together]({figure})", ""]
    return "\n".join(lines)
