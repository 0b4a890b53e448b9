"""The screening page: Morris or Sobol ranks, their figures and the proposal.

:func:`write_screening_report` writes into the screening folder

* ``screening.html`` -- one self-contained page (figures embedded as base64 PNG);
* ``figures/mu_sigma_<output>.png`` and ``figures/mu_star_<output>.png``.

In the mu*-sigma plot (Campolongo et al. 2007) a parameter far to the right
matters; one above the dashed line sigma = mu* acts non-linearly or through
interactions with others, one well below it about linearly. The bar chart
shows mu* with its 95 % bootstrap interval and the screening threshold as a
line.

:func:`write_sobol_report` writes the same page for ``method = "sobol"``: per
output, the GP's leave-one-out accuracy (a warning where Q2 is below
:data:`bayescal.screening.Q2_WARN`), a table of S1 and ST with their 95 %
intervals (GP paths and Saltelli sample) and ``figures/sobol_<output>.png``,
the bars of ST and S1 with those intervals and the threshold. User text
(parameter and output names) is escaped.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from bayescal import __version__
from bayescal.atomic import atomic_write, atomic_write_text
from bayescal.glossary import GLOSSARY
from bayescal.report.html import CSS
from bayescal.screening import Q2_WARN, MorrisIndices, Proposal, SobolIndices

__all__ = [
    "PAGE",
    "plot_mu_sigma",
    "plot_mu_star",
    "plot_sobol",
    "write_screening_report",
    "write_sobol_report",
]

#: The page, in the screening folder.
PAGE = "screening.html"
_CANDIDATE, _CALIBRATED = "tab:blue", "tab:orange"


def _unit(output: str) -> str:
    quantity = GLOSSARY.get(output)
    return quantity.unit if quantity is not None else ""


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def _save(fig: Figure, path: Path) -> Path:
    """Lay ``fig`` out, write it to ``path`` as PNG and close it."""
    fig.tight_layout()
    target = atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=100))
    plt.close(fig)
    return target


def plot_mu_sigma(path: Path, ix: MorrisIndices, candidates: Sequence[str], label: str) -> Path:
    """The mu*-sigma plane of one output, each parameter labelled, saved as PNG."""
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    colours = [_CANDIDATE if n in candidates else _CALIBRATED for n in ix.names]
    ax.errorbar(
        ix.mu_star, ix.sigma, xerr=ix.mu_star_conf, fmt="none", ecolor="0.7", lw=0.8, zorder=1
    )
    ax.scatter(ix.mu_star, ix.sigma, c=colours, s=28, zorder=2)
    top = float(max(np.max(ix.mu_star + ix.mu_star_conf), np.max(ix.sigma), 1e-300))
    line = np.array([0.0, top])
    ax.plot(line, line, color="0.5", lw=0.8, ls="--", label="sigma = mu*")
    order = np.argsort(-ix.mu_star)
    labelled = [j for j in order[:10] if ix.normalised[j] >= 0.1]  # the crowd near 0 stays quiet
    for j in labelled:
        ax.annotate(ix.names[j], (ix.mu_star[j], ix.sigma[j]), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")  # fmt: skip
    ax.set_xlabel(f"mu* [{label} per prior range]")
    ax.set_ylabel(f"sigma [{label} per prior range]")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.scatter([], [], c=_CANDIDATE, s=28, label="candidate (screen = true)")
    ax.scatter([], [], c=_CALIBRATED, s=28, label="calibrated")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(f"Morris mu*-sigma: {ix.output} ({ix.trajectories} trajectories)")
    ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_mu_star(
    path: Path, ix: MorrisIndices, candidates: Sequence[str], label: str, threshold: float
) -> Path:
    """mu* of one output as horizontal bars with 95 % intervals, most influential on top."""
    order = np.argsort(ix.mu_star)
    fig, ax = plt.subplots(figsize=(7.5, 0.28 * len(order) + 1.4))
    colours = [_CANDIDATE if ix.names[j] in candidates else _CALIBRATED for j in order]
    ax.barh(np.arange(order.size), ix.mu_star[order], xerr=ix.mu_star_conf[order],
            color=colours, ecolor="0.3", capsize=2)  # fmt: skip
    ax.set_yticks(np.arange(order.size), [ix.names[j] for j in order], fontsize=8)
    cut = threshold * float(np.max(ix.mu_star))
    ax.axvline(cut, color="tab:red", lw=0.9, ls="--", label=f"threshold {threshold:g} × max")
    ax.set_xlabel(f"mu* [{label} per prior range]")
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"Morris mu* with 95 % intervals: {ix.output}")
    ax.grid(alpha=0.3, axis="x")
    return _save(fig, path)


def _table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows
    )
    return f"<table><tr>{head}</tr>{body}</table>"


def _g(value: float) -> str:
    return "–" if not np.isfinite(value) else f"{value:.4g}"


def _row(
    ix: MorrisIndices | SobolIndices,
    j: int,
    candidates: Sequence[str],
    selected: set[str],
    cells: Sequence[object],
) -> list[object]:
    """A parameter's row of an output's table: rank, name, role, ``cells``, proposed."""
    name = ix.names[j]
    role = "candidate" if name in candidates else "calibrated"
    return [int(ix.ranks[j]), name, role, *cells, "yes" if name in selected else ""]


def _image(path: Path, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (
        f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


def _page(
    folder: Path,
    proposal: Proposal,
    facts: Mapping[str, Any],
    sections: Sequence[str],
    *,
    study_name: str,
    measure: str,
    short: str,
    method: str,
) -> Path:
    """Write ``screening.html``: the proposal and ``facts``, then the outputs' ``sections``.

    ``measure`` names the index the proposal compares (``short`` in the score's
    heading); ``method`` is the sentence under the title (HTML, not escaped).
    """
    chosen = [[i + 1, n, f"{proposal.score[n]:.3f}", proposal.deciding[n]]
              for i, n in enumerate(proposal.selected)]  # fmt: skip
    cap = "" if proposal.max_parameters is None else f", at most {proposal.max_parameters}"
    summary = (
        f"<h2>Proposed parameters</h2><p>Parameters whose {measure} reaches "
        f"{proposal.threshold:g} of the largest {short} for at least one output{cap}. Set "
        "<code>screen = false</code> on them (<code>bayescal screen --apply</code> does) and "
        "<code>screen = true</code> on the others.</p>"
        + _table(["#", "parameter", f"score ({short}/max)", "deciding output"], chosen)
        + _table(["", ""], [[k, v] for k, v in facts.items()])
    )
    title = html.escape(f"Screening: {study_name}")
    page = (
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{title}</title>"
        f"<style>{CSS}</style></head><body><h1>{title}</h1><p class='note'>bayescal "
        f"{html.escape(__version__)}; {method}</p>{summary}{''.join(sections)}</body></html>\n"
    )
    return atomic_write_text(folder / PAGE, page)


def write_screening_report(
    folder: Path,
    indices: Sequence[MorrisIndices],
    proposal: Proposal,
    *,
    study_name: str,
    candidates: Sequence[str],
    statistic: str,
    facts: Mapping[str, Any],
) -> Path:
    """Write the figures and ``screening.html`` into ``folder``; returns the page.

    Parameters
    ----------
    folder
        The screening folder.
    indices
        Morris indices, one per output.
    proposal
        The proposed parameters.
    study_name
        Shown in the title.
    candidates
        The screening candidates (the other parameters are calibrated already).
    statistic
        The scalar screened per output (``"mean"`` or ``"rmse"``).
    facts
        Lines of the summary table (runs, failures, time...).
    """
    figures = folder / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    sections = []
    selected = set(proposal.selected)
    for ix in indices:
        unit = _unit(ix.output)
        label = f"{statistic} of {ix.output}" + (f", {unit}" if unit else "")
        scatter = plot_mu_sigma(figures / f"mu_sigma_{_slug(ix.output)}.png", ix, candidates, label)
        bars = plot_mu_star(
            figures / f"mu_star_{_slug(ix.output)}.png", ix, candidates, label, proposal.threshold
        )
        order = np.argsort(-ix.mu_star, kind="stable")
        rows = [
            _row(ix, j, candidates, selected, [_g(ix.mu_star[j]), _g(ix.mu_star_conf[j]),
                 _g(ix.mu[j]), _g(ix.sigma[j]), f"{ix.normalised[j]:.3f}"])
            for j in order
        ]  # fmt: skip
        header = ["rank", "parameter", "role", "mu*", "± 95 %", "mu", "sigma", "mu*/max",
                  "proposed"]  # fmt: skip
        sections.append(
            f"<h2>{html.escape(ix.output)}</h2><p class='note'>{html.escape(label)} per whole "
            f"prior range; {ix.trajectories} complete trajectories.</p>"
            + _table(header, rows)
            + _image(scatter, f"mu*-sigma, {ix.output}")
            + _image(bars, f"mu* with 95 % intervals, {ix.output}")
        )
    return _page(
        folder, proposal, facts, sections, study_name=study_name, measure="mu*", short="mu*",
        method=f"Morris elementary effects (SALib) of the {statistic} of each output over the "
        "training periods.",
    )  # fmt: skip


def plot_sobol(
    path: Path, ix: SobolIndices, candidates: Sequence[str], label: str, threshold: float
) -> Path:
    """ST (bars) and S1 (dots) of one output with their 95 % intervals, most influential on top."""
    order = np.argsort(ix.st)
    y = np.arange(order.size)
    fig, ax = plt.subplots(figsize=(7.5, 0.28 * len(order) + 1.6))
    colours = [_CANDIDATE if ix.names[j] in candidates else _CALIBRATED for j in order]
    st, low, high = ix.st[order], ix.st_lower[order], ix.st_upper[order]
    ax.barh(y, st, xerr=np.vstack([np.maximum(st - low, 0), np.maximum(high - st, 0)]),
            color=colours, ecolor="0.3", capsize=2, label="ST (total)")  # fmt: skip
    s1 = ix.s1[order]
    s1_err = np.vstack(
        [np.maximum(s1 - ix.s1_lower[order], 0), np.maximum(ix.s1_upper[order] - s1, 0)]
    )
    ax.errorbar(s1, y, xerr=s1_err, fmt="o", color="k", ms=3, lw=0.8, label="S1 (first order)")
    ax.set_yticks(y, [ix.names[j] for j in order], fontsize=8)
    cut = threshold * float(max(np.max(ix.st), 0.0))
    ax.axvline(cut, color="tab:red", lw=0.9, ls="--", label=f"threshold {threshold:g} × max ST")
    ax.set_xlabel(f"Sobol index of the {label} [-]")
    ax.set_xlim(left=min(0.0, float(np.min(low))))
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"Sobol indices with 95 % intervals: {ix.output} (GP Q2 {ix.q2:.2f})")
    ax.grid(alpha=0.3, axis="x")
    return _save(fig, path)


def _interval(point: float, low: float, high: float) -> str:
    return f"{_g(point)} [{_g(low)}, {_g(high)}]"


def write_sobol_report(
    folder: Path,
    indices: Sequence[SobolIndices],
    proposal: Proposal,
    *,
    study_name: str,
    candidates: Sequence[str],
    statistic: str,
    facts: Mapping[str, Any],
) -> Path:
    """Write the figures and ``screening.html`` of a Sobol screening; returns the page.

    The parameters are those of :func:`write_screening_report`, with Sobol indices.
    """
    figures = folder / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    sections = []
    selected = set(proposal.selected)
    for ix in indices:
        unit = _unit(ix.output)
        label = f"{statistic} of {ix.output}"
        bars = plot_sobol(
            figures / f"sobol_{_slug(ix.output)}.png", ix, candidates, label, proposal.threshold
        )
        s1_low, s1_high, st_low, st_high = ix.s1_lower, ix.s1_upper, ix.st_lower, ix.st_upper
        rows = [
            _row(ix, j, candidates, selected, [_interval(ix.s1[j], s1_low[j], s1_high[j]),
                 _interval(ix.st[j], st_low[j], st_high[j]), f"{ix.normalised[j]:.3f}",
                 _g(ix.lengths[j])])
            for j in np.argsort(-ix.st, kind="stable")
        ]  # fmt: skip
        header = ["rank", "parameter", "role", "S1 [95 %]", "ST [95 %]", "ST/max",
                  "GP length scale", "proposed"]  # fmt: skip
        sd = _g(ix.sd) + (f" {unit}" if unit else "")
        accuracy = (
            f"GP fitted to {ix.runs} runs: leave-one-out Q2 {ix.q2:.3f}, RMSE "
            f"{_g(ix.loo_rmse)} against the statistic's SD {sd} over the runs."
        )
        warning = (
            ""
            if ix.reliable
            else f"<p><strong>Warning:</strong> Q2 is below {Q2_WARN:g}: the GP does not "
            "predict the runs it leaves out well, so this ranking is unreliable. Raise "
            '<code>[screening] runs</code> or use <code>method = "morris"</code>.</p>'
        )
        sections.append(
            f"<h2>{html.escape(ix.output)}</h2><p class='note'>{html.escape(accuracy)} The "
            "intervals hold the GP's uncertainty (its posterior paths, "
            f"{ix.paths} of them, at fixed hyperparameters) and the Saltelli sample's error "
            f"(N = {ix.base}).</p>{warning}"
            + _table(header, rows)
            + _image(bars, f"Sobol indices with 95 % intervals, {ix.output}")
        )
    return _page(
        folder, proposal, facts, sections, study_name=study_name,
        measure="total Sobol index ST", short="ST",
        method=f"Sobol indices (SALib) of the {statistic} of each output over the training "
        "periods, computed on a GP fitted to a Latin hypercube of runs over the prior ranges.",
    )  # fmt: skip
