"""What ``bayescal compare`` shows: the ranking's figure, its verdicts and its summary page.

The inputs are the two tables :mod:`bayescal.pipeline.compare` writes: the
ranking (one row per variant, best first: ``elpd``, ``se``, ``elpd_diff``,
``se_diff`` ...) and the per-period values (``variant``, ``period``,
``start``, ``elpd_i``, ``pareto_k``, ``method``).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.axes import Axes

from bayescal.report.figures import save_figure

__all__ = [
    "CATALOGUE_TEXT",
    "SMALL_DIFFERENCE",
    "TEST_WINDOW_TEXT",
    "comparison_markdown",
    "diagnostics_mark",
    "failed_diagnostics",
    "is_catalogue",
    "model_mark",
    "plot_comparison",
    "verdict",
]

#: ELPD differences below this many nats are small whatever their SE (Sivula et al. 2022).
SMALL_DIFFERENCE = 4.0

TEST_WINDOW_TEXT = (
    "Only the measurements of the training periods enter this comparison: each period is "
    "left out in turn and predicted from the calibration on the others. The test window is "
    "read by none of it; it is read only for the final metrics of the chosen variant "
    "(`bayescal run`, the report)."
)


CATALOGUE_TEXT = (
    "A catalogue row is the nominal (catalogue) model: every calibrated parameter held at "
    "its nominal value of the study file, the error model of the variant named fitted as "
    "in its calibration, on that variant's emulator, and scored the same way. A calibrated "
    "variant that does not beat it by more than one SE of the paired difference predicts "
    "the left-out periods no better than the catalogue values."
)


def is_catalogue(row: pd.Series) -> bool:
    """Whether a ranking row is a catalogue model (the ``model`` column; ``False`` for
    tables from before it)."""
    return str(row.get("model", "calibrated")) == "catalogue"


def model_mark(row: pd.Series) -> str:
    """What follows a catalogue row's verdict: what it is (``""`` for a calibrated one)."""
    if not is_catalogue(row):
        return ""
    return f" [catalogue: the nominal values, error model of {row.get('catalogue_of', '?')}]"


def failed_diagnostics(row: pd.Series) -> bool:
    """Whether a ranking row's calibration failed its MCMC diagnostics (the
    ``diagnostics`` column; ``False`` for tables from before it)."""
    return str(row.get("diagnostics", "passed")) == "failed"


def diagnostics_mark(row: pd.Series) -> str:
    """What follows a variant's verdict: ``""``, or that its calibration failed."""
    if not failed_diagnostics(row):
        return ""
    return "; its calibration FAILED its MCMC diagnostics: the rank is not reliable (see the notes)"


def verdict(diff: float, se_diff: float) -> str:
    """How to read an ELPD difference to the best variant (``diff >= 0``) and its SE."""
    if not np.isfinite(diff) or diff == 0.0:
        return "best"
    ratio = diff / se_diff if se_diff > 0.0 else np.inf
    if diff < SMALL_DIFFERENCE or ratio < 2.0:
        return f"not clearly worse ({diff:.1f} ± {se_diff:.1f})"
    return f"worse by {diff:.1f} ± {se_diff:.1f} ({ratio:.1f} SE)"


def plot_comparison(
    path: Path,
    table: pd.DataFrame,
    periods: pd.DataFrame,
    pits: dict[str, np.ndarray] | None = None,
) -> Path:
    """ELPD ± SE per variant (and the difference to the best ± its SE); per-period
    differences; the left-out samples' PIT histograms.

    Left: each variant's ELPD with its standard error (black) and, below it,
    its difference to the best with the SE of the paired difference (grey).
    Middle: ``elpd_i(variant) - elpd_i(best)`` per training period; filled
    squares are periods scored by an exact refit, open circles PSIS estimates
    whose Pareto ``k`` exceeds 0.7 (unreliable). Right (with ``pits``,
    variant -> PIT of every left-out training sample): their histograms, flat
    where the bands of a new period mean what they say, U-shaped where they are
    too narrow, peaked where too wide.
    """
    order = list(table["variant"])
    n = len(order)
    shown = {k: np.asarray(v).ravel() for k, v in (pits or {}).items() if np.size(v)}
    ratios = [1.0, 1.4, 0.9] if shown else [1.0, 1.4]
    fig, axes = plt.subplots(
        1,
        len(ratios),
        figsize=(11.0 + 4.0 * bool(shown), max(3.0, 1.2 + 0.55 * n)),
        gridspec_kw={"width_ratios": ratios},
    )
    left, right = axes[0], axes[1]
    if shown:
        _plot_pits(axes[2], shown, order)
    y = np.arange(n)[::-1].astype(float)
    best = float(table["elpd"].iloc[0])
    nominal = np.array([is_catalogue(row) for _, row in table.iterrows()], dtype=bool)
    for mask, fmt, colour in ((~nominal, "o", "black"), (nominal, "s", "tab:blue")):
        if mask.any():
            left.errorbar(table["elpd"][mask], y[mask], xerr=table["se"][mask], fmt=fmt,
                          color=colour, capsize=3)  # fmt: skip
    others = table.iloc[1:]
    if len(others):
        left.errorbar(
            best - others["elpd_diff"],
            y[1:] - 0.25,
            xerr=others["se_diff"],
            fmt="^",
            color="0.55",
            capsize=3,
        )
    left.axvline(best, color="0.3", ls="--", lw=0.8)
    left.set_yticks(y, order)
    for tick, flag in zip(left.get_yticklabels(), nominal, strict=True):
        if flag:  # the catalogue rows: blue squares, labels in italics
            tick.set_color("tab:blue")
            tick.set_fontstyle("italic")
    left.set_ylim(-0.7, n - 0.3)
    left.set_xlabel("ELPD: leave-one-period-out log density [nats]")
    left.set_title("higher is better", fontsize=9)
    _plot_periods(right, periods, order)
    fig.tight_layout()
    return save_figure(fig, path)


def _plot_pits(ax: Axes, pits: dict[str, np.ndarray], order: list[str]) -> None:
    edges = np.linspace(0.0, 1.0, 21)
    for k, name in enumerate(order):
        if name in pits:
            ax.stairs(np.histogram(pits[name], bins=edges, density=True)[0], edges,
                      color="black" if k == 0 else f"C{k - 1}", label=name)  # fmt: skip
    ax.axhline(1.0, color="0.5", ls=":", lw=0.8)
    ax.set_xlabel("PIT of the left-out samples")
    ax.set_ylabel("density")
    ax.set_title("flat: bands of a new period hold", fontsize=9)
    ax.legend(fontsize=7)


def _plot_periods(ax: Axes, periods: pd.DataFrame, order: list[str]) -> None:
    wide = periods.pivot(index="period", columns="variant", values="elpd_i")
    method = periods.pivot(index="period", columns="variant", values="method")
    high = periods.pivot(index="period", columns="variant", values="pareto_k") > 0.7
    x = wide.index.to_numpy()
    base = wide[order[0]].to_numpy()
    for k, name in enumerate(order[1:]):
        diff = wide[name].to_numpy() - base
        colour = f"C{k}"
        ax.plot(x, diff, "-", color=colour, lw=0.8, label=name)
        refit = (method[name] == "refit").to_numpy()
        shaky = high[name].to_numpy() & ~refit
        plain = ~refit & ~shaky
        ax.plot(x[plain], diff[plain], ".", color=colour)
        ax.plot(x[refit], diff[refit], "s", color=colour, ms=5)
        ax.plot(x[shaky], diff[shaky], "o", mfc="none", color=colour, ms=7)
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xlabel("training period")
    ax.set_ylabel("elpd_i − elpd_i of the best [nats]")
    ax.set_title(f"per period, against {order[0]} (■ refit, ○ k > 0.7)", fontsize=9)
    if len(order) > 1:
        ax.legend(fontsize=8)


def _cell(value: object, column: str = "", row: pd.Series | None = None) -> str:
    if isinstance(value, float | np.floating):
        if not column.startswith("loo_band"):
            return f"{float(value):.1f}"
        se = float(row.get(f"{column}_se", np.nan)) if row is not None else np.nan
        return f"{float(value):.3f} ± {se:.3f}" if np.isfinite(se) else f"{float(value):.3f}"
    return str(value).replace("|", "\\|")


def comparison_markdown(
    table: pd.DataFrame,
    periods: pd.DataFrame,
    notes: list[str],
    figure: str | None,
    warnings: list[str] | None = None,
    held_out: pd.DataFrame | None = None,
) -> str:
    """A short Markdown page: the loud warnings, the ranking table, verdicts, the
    held-out sensors' table (:mod:`bayescal.pipeline.heldscore`), notes and the figure."""
    columns = {
        "rank": "rank",
        "variant": "variant",
        "model": "model",
        "elpd": "ELPD",
        "se": "SE",
        "elpd_diff": "ELPD diff",
        "se_diff": "SE diff",
        "p_loo": "p_loo",
        "k_high": "periods k > 0.7",
        "refits": "refits",
        "loo_band95": "left-out 95 % band",
        "loo_band50": "left-out 50 % band",
        "loo_band95_worst": "worst period, 95 % band",
        "scored_on": "scored on",
        "diagnostics": "MCMC diagnostics",
        "parameters": "parameters",
        "priors": "priors",
        "error_model": "error model",
        "standardise": "standardise",
    }
    shown = [c for c in columns if c in table.columns]
    lines = ["# Leave-one-period-out comparison", ""]
    lines += [f"**WARNING: {w}**\n" for w in warnings or []]
    lines += [
        f"{len(table)} variants ranked by ELPD, the expected log density of a left-out "
        f"training period's measurements in their own units (nats, higher is better), summed "
        f"over the {int(table['periods'].iloc[0])} training periods. ELPD diff is the "
        "difference to the best, SE diff its standard error from the paired periods.",
        "",
        "| " + " | ".join(columns[c] for c in shown) + " |",
        "|" + "|".join("---" for _ in shown) + "|",
    ]
    for _, row in table.iterrows():
        cells = {c: _cell(row[c], c, row) for c in shown}
        if failed_diagnostics(row):
            cells["variant"] = f"**{cells['variant']}** ⚠"
            cells["diagnostics"] = "**FAILED**"
        lines.append("| " + " | ".join(cells.values()) + " |")
    lines += ["", "## Reading it", ""]
    for _, row in table.iterrows():
        said = verdict(row["elpd_diff"], row["se_diff"]) + model_mark(row) + diagnostics_mark(row)
        lines.append(f"- **{row['variant']}**: {said}")
    lines += [
        "",
        f"A difference counts when it exceeds both {SMALL_DIFFERENCE:g} nats and twice its "
        "SE; with few training periods the SE itself is rough. A variant marked ⚠ failed "
        "the MCMC diagnostics of its calibration (R-hat above 1.01, bulk or tail ESS below "
        "400, stuck chains, divergences): its scores rest on chains that have not "
        "converged, so its rank is not reliable until longer chains pass.",
        "",
        "The left-out bands are the share of the training samples inside the central 95 % "
        "and 50 % band of their period's prediction by the calibration without that period "
        "(the emulator route's band: parameters, emulator, noise and the discrepancy, "
        "weighted by PSIS or from the refit): what the bands of a new period should hold, "
        "measured before the test window is read. Neighbouring samples fall inside or "
        "outside together, so their standard error (±) takes the period as the unit. The "
        "ranking is by ELPD; the bands are a check of the variant chosen: a band more "
        "than two SE above its rate is conservative, one below it overconfident, and a "
        "period whose 95 % band holds less than half of its samples is predicted "
        "confidently wrong (see the notes).",
        "",
        TEST_WINDOW_TEXT,
    ]
    if "model" in table.columns and (table["model"] == "catalogue").any():
        lines += ["", CATALOGUE_TEXT]
    if held_out is not None and len(held_out):
        lines += ["", *held_out_markdown(held_out)]
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    if figure:
        lines += ["", f"![ELPD per variant and per period]({figure})"]
    return "\n".join(lines) + "\n"


#: What the held-out sensors' scores are, for the page and the terminal.
HELD_OUT_TEXT = (
    "Held-out sensors are never calibrated on: each variant predicts them by its "
    "simulator at posterior draws (the catalogue model by its nominal run) with the "
    "sensor's stated accuracy ([outputs.errors.NAME] sd), scored on the training periods "
    "by the log density of their samples (nats, higher is better; diff and SE paired "
    "by period), the RMSE of the mean prediction and the share of the samples inside the "
    "central 95 % and 50 % of the prediction (± SE over the periods). A calibration that "
    "predicts a sensor it never saw worse than the catalogue values has put model error "
    "into its parameters."
)


def held_out_markdown(held_out: pd.DataFrame) -> list[str]:
    """The held-out sensors' section of the comparison page."""
    lines = ["## Held-out sensors", "", HELD_OUT_TEXT, ""]
    lines += [
        "| sensor | rank | variant | model | log density | SE | diff | SE diff | RMSE | "
        "95 % band | 50 % band | draws | stated SD |",
        "|" + "|".join("---" for _ in range(13)) + "|",
    ]
    for _, r in held_out.iterrows():
        variant = str(r["variant"]).replace("|", "\\|")
        if r["diagnostics"] == "failed":
            variant = f"**{variant}** ⚠"
        lines.append(
            f"| {r['output']} | {int(r['rank'])} | {variant} | {r['model']} | {r['lpd']:.1f} | "
            f"{r['se']:.1f} | {r['lpd_diff']:.1f} | {r['se_diff']:.1f} | {r['rmse']:.3g} | "
            f"{r['band95']:.3f} ± {r['band95_se']:.3f} | {r['band50']:.3f} ± "
            f"{r['band50_se']:.3f} | {int(r['draws'])} | {r['sd']:.3g} |"
        )
    return lines
