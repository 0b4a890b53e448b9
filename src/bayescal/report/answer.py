"""The report's first screen: the answer, before the evidence.

What a reader of a calibration wants first, each a pure function of results
already computed (the page's layout is :mod:`bayescal.report.html`'s):

* :func:`fit_table` -- per calibrated output and held-out sensor, the RMSE of
  the nominal (catalogue) and of the calibrated prediction on the training
  periods and on the test window;
* :func:`quantities_table` -- the calibrated parameters and the quantities
  derived from them (the wall's U-value, resistance and areal heat capacity, a
  study's ``[derived]`` expressions): posterior mean and 95 % interval beside
  the catalogue value (the quantity at the nominal parameters);
* :func:`convergence_line` -- whether the MCMC diagnostics passed;
* :func:`band_lines` -- one line per output: does its 95 % band cover what an
  honest band covers on a window of that many independent samples
  (:func:`bayescal.metrics.honest_range` with the metrics' ``n_eff95``)?
* :func:`route_used` -- which route made the bands, with what ``method = "auto"``
  measured to choose it;
* :func:`discrepancy_used` -- which discrepancy the calibration used: the
  in-likelihood one of an output (``[outputs.errors.NAME] discrepancy``) or
  the difference process (``[discrepancy] enabled``), which are not the same.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence

import numpy as np
import pandas as pd

from bayescal.calibration.identifiability import identifiability
from bayescal.calibration.posterior import Posterior
from bayescal.glossary import GLOSSARY
from bayescal.metrics import honest_range

__all__ = [
    "DISCREPANCY_KINDS",
    "band_lines",
    "convergence_line",
    "discrepancy_used",
    "fit_table",
    "quantities_table",
    "route_used",
]

Table = Callable[[Sequence[str], list[list[object]]], str]

#: How each kind of in-likelihood discrepancy is named on the page.
DISCREPANCY_KINDS = {
    "conditions": "over the periods' conditions",
    "independent": "independent from period to period",
    "both": "over the conditions plus one independent per period",
    "orthogonal": "over the conditions, orthogonal to the parameters' effects",
}
MODEL_TITLES = {"nominal": "nominal (catalogue)", "calibrated": "calibrated"}


def _unit(name: str) -> str:
    q = GLOSSARY.get(name)
    return q.unit if q else ""


def _g(value: float, digits: int = 4) -> str:
    return f"{value:.{digits}g}" if np.isfinite(value) else "–"


def _digits(width: float) -> Callable[[float], str]:
    """A formatter that shows a posterior's values to two significant digits of its
    interval's ``width`` (fixed decimals, trailing zeros kept: 0.32340 – 0.32380)."""
    if not (np.isfinite(width) and width > 0):
        return lambda v: _g(v, 5)
    step = int(np.floor(np.log10(width))) - 1
    decimals = min(max(0, -step), 12)
    return lambda v: f"{round(v, -step):.{decimals}f}" if np.isfinite(v) else "–"


def _rmse(rows: pd.DataFrame, model: str) -> float:
    found = rows.loc[rows["model"] == model, "rmse"]
    return float(found.iloc[0]) if len(found) else float("nan")


def fit_table(metrics: pd.DataFrame, held_out: Collection[str], table: Table) -> str:
    """RMSE of the nominal and the calibrated prediction, per output and window.

    Parameters
    ----------
    metrics
        The metrics table (``metrics.csv``).
    held_out
        The held-out sensors (never calibrated on: every window is out of sample).
    table
        Renders a header and rows as the report does.
    """
    models = [
        m for m in ("nominal", "calibrated", "calibrated+delta") if m in set(metrics["model"])
    ]
    header = ["output", "window", *(MODEL_TITLES.get(m, "calibrated + Δ") for m in models)]
    header.append("calibrated against nominal")
    rows: list[list[object]] = []
    for output in dict.fromkeys(metrics["output"]):
        unit = _unit(str(output))
        label = f"{output} [{unit}]" if unit else str(output)
        held = output in held_out
        for window, what in (("train", "training periods"), ("test", "test window")):
            part = metrics[(metrics["output"] == output) & (metrics["window"] == window)]
            if part.empty:
                continue
            if held:
                what += " (held-out sensor: out of sample)"
            else:
                what += " (fitted)" if window == "train" else " (out of sample)"
            values = [_rmse(part, m) for m in models]
            nominal, calibrated = _rmse(part, "nominal"), _rmse(part, "calibrated")
            change = (
                f"{100.0 * (calibrated / nominal - 1.0):+.0f} %"
                if np.isfinite(nominal) and np.isfinite(calibrated) and nominal > 0
                else "–"
            )
            rows.append([label, what, *(_g(v) for v in values), change])
    return table(header, rows)


def quantities_table(
    posterior: Posterior, nominal: Mapping[str, float], table: Table, level: float = 0.95
) -> str:
    """The calibrated parameters and derived quantities beside their catalogue values.

    Parameters
    ----------
    posterior
        The calibration posterior (its ``derived`` draws included).
    nominal
        Catalogue values: the nominal parameters and the derived quantities at
        them (a name missing here shows "–").
    table
        Renders a header and rows as the report does.
    level
        Probability of the credible interval.
    """
    # what a physicist quotes first (U, R, heat capacity), then the parameters
    columns = [(name, d.draws, d.unit, d.description) for name, d in posterior.derived.items()]
    for k, name in enumerate(posterior.names):
        if name in posterior.held_names:  # held at its nominal value, not calibrated
            continue
        prior = posterior.priors[name]
        columns.append((name, posterior.draws[..., k], prior.unit, prior.description))
    ident = identifiability(posterior)
    contraction = dict(zip(ident.names, ident.contraction, strict=True))
    tail = 50.0 * (1.0 - level)
    rows: list[list[object]] = []
    for name, draws, unit, text in columns:
        flat = np.asarray(draws, dtype=float).reshape(-1)
        low, high = np.percentile(flat, [tail, 100.0 - tail])
        mean = float(np.mean(flat))
        cat = float(nominal.get(name, float("nan")))
        shift = f"{100.0 * (mean / cat - 1.0):+.1f} %" if np.isfinite(cat) and cat != 0 else "–"
        shown = _digits(float(high - low))
        interval = f"{shown(low)} – {shown(high)}"
        fixed = f"{100 * contraction[name]:.0f} %" if name in contraction else "–"
        rows.append([name, unit or "–", shown(mean), interval, _g(cat, 5), shift, fixed, text])
    pct = f"{100 * level:g} %"
    header = ["quantity", "unit", "posterior mean", f"{pct} interval", "catalogue (nominal)"]
    header += ["mean against catalogue", "contraction", "what"]
    return table(header, rows)


def convergence_line(
    posterior: Posterior, discrepancy: Posterior | None = None
) -> tuple[bool, str]:
    """``(passed, sentence)``: did the chains' diagnostics pass?"""
    chains, draws = posterior.lam.shape
    problems = [*posterior.warnings, *(() if discrepancy is None else discrepancy.warnings)]
    if not problems:
        return True, (
            "passed: every R-hat ≤ 1.01, bulk and tail ESS ≥ 400 "
            f"({chains} chains × {draws} draws"
            + (", and the difference process's)" if discrepancy is not None else ")")
        )
    return False, (
        f"NOT passed: {len(problems)} diagnostic warning(s), listed above; intervals and "
        "bands may be too narrow or off"
    )


def _band_part(row: pd.Series, level: float) -> tuple[str, str]:
    cover = float(row.get("coverage95", float("nan")))
    n_eff = float(row.get("n_eff95", float("nan")))
    window = "training periods" if row["window"] == "train" else "test window"
    if not np.isfinite(cover):
        return "unknown", f"no band on the {window}"
    if not np.isfinite(n_eff):
        return "unknown", f"covers {cover:.3f} of the {window} (no honest range: an older run)"
    low, high = honest_range(level, n_eff)
    verdict = "holds" if low <= cover <= high else ("too wide" if cover > high else "too narrow")
    return verdict, (
        f"covers {cover:.3f} of the {window} (an honest band {low:.2f}-{high:.2f} "
        f"on about {n_eff:.0f} independent samples)"
    )


def band_lines(metrics: pd.DataFrame, level: float = 0.95) -> list[str]:
    """One sentence per output (and per model with a band): does its band hold?

    A band *holds* on a window when its coverage lies within
    :func:`bayescal.metrics.honest_range` of the level with the window's
    ``n_eff95`` independent samples; it is *too wide* above, *too narrow* below.
    """
    if "coverage95" not in metrics.columns:
        return []
    lines = []
    for output in dict.fromkeys(metrics["output"]):
        for model in ("calibrated", "calibrated+delta"):
            rows = metrics[(metrics["output"] == output) & (metrics["model"] == model)]
            if rows.empty:
                continue
            parts = [_band_part(r, level) for _, r in rows.iterrows()]
            verdicts = {v for v, _ in parts if v != "unknown"}
            if not verdicts:
                verdict = "is not known"
            elif verdicts == {"holds"}:
                verdict = "holds"
            else:
                verdict = "is " + " on one window, ".join(sorted(verdicts - {"holds"}))
            who = output if model == "calibrated" else f"{output} (calibrated + Δ)"
            lines.append(
                f"{who}: the {100 * level:g} % band {verdict}: " + "; ".join(t for _, t in parts)
            )
    return lines


def discrepancy_used(posterior: Posterior, discrepancy: Posterior | None) -> tuple[str, str]:
    """``(in_likelihood, difference_process)``: what the calibration used, in words."""
    inside = [
        f"{o.name} ({DISCREPANCY_KINDS.get(str(o.discrepancy), str(o.discrepancy))})"
        for o in posterior.noise
        if o.discrepancy
    ]
    return (
        ", ".join(inside) if inside else "none",
        "estimated" if discrepancy is not None else "not used",
    )


def route_used(attrs: Mapping[str, object]) -> str:
    """Which route made the bands (the predictions' attributes: ``route``, and what
    ``method = "auto"`` measured and chose, ``route_check``, with ``off_basis`` where the
    emulator's centre was completed by the held-out runs)."""
    route = str(attrs.get("route", ""))
    said = {
        "simulator": "the simulator re-run at posterior draws",
        "emulator": "the emulator at posterior draws",
    }.get(route, "not recorded (predictions from an earlier bayescal)")
    if route == "emulator" and attrs.get("off_basis"):
        said += ", its centre completed off the output basis by the held-out runs"
    if check := str(attrs.get("route_check", "")):
        said += f" ({check.removeprefix('predict: ')})"
    return said
