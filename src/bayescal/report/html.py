"""The calibration report: one self-contained HTML page, its figures and the posterior draws.

:func:`write_report` writes into a folder

* ``report.html`` -- one file, no external CSS, JavaScript or images: every
  figure is embedded as a base64 PNG;
* ``figures/*.png`` -- the same figures as files (older PNGs there are removed);
* ``posterior_draws.csv`` -- ``chain, draw``, each theta* (physical units),
  ``lambda`` and ``lambda_star``, one row per kept draw.

Every file is written atomically. Every string that comes from the user
(study name, description, parameter and series names, error messages,
settings) is escaped with :func:`html.escape`.
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import xarray as xr

from bayescal import __version__
from bayescal.atomic import atomic_write_text
from bayescal.calibration.posterior import Posterior
from bayescal.design import Design
from bayescal.emulator.gp import Emulator, LooResult
from bayescal.emulator.noise import RELATIVE_UNIT
from bayescal.glossary import GLOSSARY
from bayescal.metrics import MODELS, MetricColumn, band_notes, metric_columns
from bayescal.report import figures as fg
from bayescal.report.answer import (
    band_lines,
    convergence_line,
    discrepancy_used,
    fit_table,
    quantities_table,
    route_used,
)
from bayescal.report.uncertainty import uncertainty_figures, uncertainty_section
from bayescal.runner import RunFailure

__all__ = ["SECTIONS", "ReportInputs", "write_draws_csv", "write_figures", "write_report"]

#: Section headers of the page, in order.
SECTIONS = (
    "Summary",
    "Calibration parameters",
    "Uncertainty",
    "Fit metrics",
    "Emulator",
    "Discrepancy",
    "Figures",
    "Failed runs",
    "Design",
    "Settings",
)
WINDOWS = {"train": "training window", "test": "test window"}
#: Warnings shown open on the first screen; the others fold under them.
SHOWN_WARNINGS = 5

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:1em auto;max-width:1150px;
padding:0 1em;color:#222;line-height:1.4;overflow-wrap:break-word}
h1{margin:.3em 0 .2em;font-size:1.7em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;
margin:1.2em 0 .4em;font-size:1.35em}h3{margin:.8em 0 .3em;font-size:1.08em}
details>summary{cursor:pointer}section>details>summary{border-bottom:2px solid #ddd}
details>summary>h2{display:inline-block;margin:.6em 0 .2em;border:none;padding:0}
.answer td{white-space:nowrap}.answer td:last-child,.answer th:last-child,.fit td:nth-child(2),
.fit th:nth-child(2){text-align:left}
.answer td:last-child{white-space:normal;min-width:16em}
section{margin-bottom:.3em}
.scroll{overflow-x:auto;max-width:100%;margin:.4em 0 1em}
table{border-collapse:collapse;font-size:.9em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}
.warn{background:#fff3cd;border:2px solid #e0a800;padding:.6em 1em;border-radius:4px}
.ok{background:#e8f5e9;border:1px solid #66bb6a;padding:.6em 1em;border-radius:4px}
.catalogue{border:1px solid #bbb;padding:.4em 1em;border-radius:4px;margin-top:.6em}
.verdict p{margin:.3em 0}.verdict ul{margin:.1em 0 .3em}.fail{color:#b00020;font-weight:bold}
.desc{white-space:pre-wrap}.note{color:#555;font-size:.9em}
figure{margin:1em 0}img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.9em;color:#444}code{background:#f6f6f6;padding:0 .2em}
"""


@dataclass(frozen=True)
class ReportInputs:
    """Everything the report shows (built by :func:`bayescal.report.study.write_study_report`).

    Attributes
    ----------
    study_name, description
        From the study file (user text, escaped in the page).
    config_hash
        Hash of the validated study configuration.
    design
        The full design (all rows, failed ones included).
    failures
        The runs that failed (may be empty).
    emulator
        The trained emulator.
    loo
        ``emulator.loo_cv()``.
    posterior
        The calibration posterior of theta*, lambda, lambda*.
    discrepancy_posterior
        theta* of the discrepancy phase, if it was run.
    predictions
        Measured, nominal, calibrated (and corrected) series on the study clock
        (:func:`bayescal.pipeline.predict.predictions_dataset`).
    metrics
        Fit metrics per output, model and window
        (:func:`bayescal.pipeline.predict.metrics_table`).
    delta_correlation
        Pearson r of Delta (rows: outputs) with each boundary condition (columns).
    delta_explained
        Output -> fraction of the training residual variance explained by Delta. [-]
    warnings
        Diagnostics and other warnings, shown at the top.
    settings
        Key settings shown in a table.
    catalogue
        One line per output: the calibrated prediction against the nominal
        (catalogue) one out of sample (:mod:`bayescal.report.trust`), shown at
        the top under the warnings.
    nominal
        Catalogue values: the nominal parameters and the derived quantities at
        them, shown beside the posterior's on the first screen (a name missing
        here shows "–").
    """

    study_name: str
    description: str
    config_hash: str
    design: Design
    failures: tuple[RunFailure, ...]
    emulator: Emulator
    loo: LooResult
    posterior: Posterior
    discrepancy_posterior: Posterior | None
    predictions: xr.Dataset
    metrics: pd.DataFrame
    delta_correlation: pd.DataFrame | None
    delta_explained: dict[str, float] | None
    warnings: tuple[str, ...]
    settings: dict[str, object]
    catalogue: tuple[str, ...] = ()
    nominal: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class FigureEntry:
    """A figure written to disk with its place in the page."""

    group: str
    title: str
    caption: str
    path: Path


# ----------------------------------------------------------------------------- small helpers


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _num(value: object, digits: int = 4) -> str:
    if value is None:
        return "–"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return str(value)
    return "–" if not np.isfinite(x) else f"{x:.{digits}g}"


def _table(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """An HTML table; every cell is converted with ``str`` and escaped."""
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_e(c)}</td>" for c in row) + "</tr>" for row in rows)
    table = f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
    return f'<div class="scroll">{table}</div>'


def _unit(name: str) -> str:
    q = GLOSSARY.get(name)
    return q.unit if q else ""


def _outputs(ds: xr.Dataset) -> list[str]:
    return [o for o in str(ds.attrs.get("outputs", "")).split(",") if o]


def _held_out(ds: xr.Dataset) -> set[str]:
    return {o for o in str(ds.attrs.get("held_out", "")).split(",") if o}


HELD_OUT_NOTE = (
    " Held-out sensor: never calibrated on; its band is the simulator at posterior draws "
    "plus the sensor's stated noise."
)


def _boundary(ds: xr.Dataset) -> list[str]:
    return [b for b in str(ds.attrs.get("boundary", "")).split(",") if b and f"bc_{b}" in ds]


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name) or "series"


def _values(ds: xr.Dataset, name: str) -> np.ndarray | None:
    return np.asarray(ds[name].values, dtype=float) if name in ds else None


# ----------------------------------------------------------------------------- outputs on disk


def write_draws_csv(posterior: Posterior, path: str | Path) -> Path:
    """Write the posterior draws as CSV: ``chain, draw``, theta*, ``lambda``, ``lambda_star``.

    Parameters
    ----------
    posterior
        The calibration posterior (theta* in physical units).
    path
        CSV file to write (atomically).

    Returns
    -------
    pathlib.Path
        The CSV written.
    """
    draws = posterior.all_draws()
    n_chains, n_draws, n_cols = draws.shape
    frame = pd.DataFrame(draws.reshape(-1, n_cols), columns=list(posterior.all_names))
    frame.insert(0, "draw", np.tile(np.arange(n_draws), n_chains))
    frame.insert(0, "chain", np.repeat(np.arange(n_chains), n_draws))
    return atomic_write_text(path, frame.to_csv(index=False))


def _posterior_figures(inputs: ReportInputs, folder: Path) -> list[FigureEntry]:
    post, disc = inputs.posterior, inputs.discrepancy_posterior
    overlay = " The outline is the posterior of the discrepancy phase." if disc else ""
    return [
        FigureEntry(
            "Posterior",
            "Posterior of θ*",
            "Histograms of the posterior draws over the prior density (dashed)." + overlay,
            fg.plot_posterior_histograms(folder / "posterior.png", post, disc),
        ),
        FigureEntry(
            "Posterior",
            "MCMC traces",
            "Kept draws of every chain; well-mixed chains overlap.",
            fg.plot_traces(folder / "traces.png", post),
        ),
        FigureEntry(
            "Posterior",
            "Pair plot of θ*",
            "Joint posterior draws: correlated parameters show elongated clouds.",
            fg.plot_pairs(folder / "pairs.png", post),
        ),
    ]


def _uncertainty_figures(inputs: ReportInputs, folder: Path) -> list[FigureEntry]:
    made = uncertainty_figures(
        inputs.posterior, inputs.predictions, _outputs(inputs.predictions), folder
    )
    return [FigureEntry("Uncertainty", title, text, path) for title, text, path in made]


def _emulator_figures(inputs: ReportInputs, folder: Path) -> list[FigureEntry]:
    em, loo = inputs.emulator, inputs.loo
    loo_means = fg.loo_predictions(em)
    slices = em.outputs.slices
    z = {name: loo.z[:, sl] for name, sl in slices.items()}
    return [
        FigureEntry(
            "Emulator",
            "Emulator sensitivity",
            "ρ = exp(−β/4) of each input and basis at the MAP: small values mark inputs "
            "that change the basis weight strongly; ρ near 1 means no influence.",
            fg.plot_rho_sensitivity(folder / "emulator_rho.png", em.rho, em.input_labels),
        ),
        FigureEntry(
            "Emulator",
            "Output PCA",
            "Variance of the standardised simulations explained per component and "
            "cumulatively (kept components coloured), and the variance left outside the "
            "first k components on a log scale.",
            fg.plot_pca_variance(folder / "emulator_pca.png", em.basis.explained, em.basis.p),
        ),
        FigureEntry(
            "Emulator",
            "Leave-one-run-out check",
            "Each run predicted by the emulator trained on the others: predicted against "
            "simulated, and the standardised residuals against N(0, 1).",
            fg.plot_emulator_loo(
                folder / "emulator_loo.png",
                {n: v[0] for n, v in loo_means.items()},
                {n: v[1] for n, v in loo_means.items()},
                z,
                loo.rmse,
                [o.name for o in inputs.posterior.noise if o.unit == RELATIVE_UNIT],
            ),
        ),
    ]


def _prediction_figures(inputs: ReportInputs, folder: Path) -> list[FigureEntry]:
    ds = inputs.predictions
    times, window = ds["time"].values, ds["window"].values
    out: list[FigureEntry] = []
    for o in _outputs(ds):
        measured, slug = _values(ds, f"{o}_measured"), _slug(o)
        if measured is None or f"{o}_calibrated" not in ds:
            continue
        out.append(
            FigureEntry(
                "Predictions",
                f"{o}: calibrated model" + (" (held out)" if o in _held_out(ds) else ""),
                "Measured, nominal (dashed) and calibrated prediction with the 95 % and 50 % "
                "bands of a measurement (see Uncertainty for what they include)."
                + (HELD_OUT_NOTE if o in _held_out(ds) else ""),
                fg.plot_fit(
                    folder / f"fit_{slug}.png",
                    times,
                    window,
                    o,
                    measured,
                    ds[f"{o}_calibrated"].values,
                    _values(ds, f"{o}_calibrated_lower"),
                    _values(ds, f"{o}_calibrated_upper"),
                    nominal=_values(ds, f"{o}_nominal"),
                    band50=(
                        _values(ds, f"{o}_calibrated_lower50"),
                        _values(ds, f"{o}_calibrated_upper50"),
                    ),
                ),
            )
        )
        if f"{o}_corrected" in ds:
            out.append(
                FigureEntry(
                    "Predictions",
                    f"{o}: calibrated model + Δ",
                    "Measured and the calibrated prediction corrected by the discrepancy Δ, "
                    "with its 95 % band.",
                    fg.plot_fit(
                        folder / f"fit_delta_{slug}.png",
                        times,
                        window,
                        o,
                        measured,
                        ds[f"{o}_corrected"].values,
                        _values(ds, f"{o}_corrected_lower"),
                        _values(ds, f"{o}_corrected_upper"),
                        model_label="calibrated + Δ",
                    ),
                )
            )
    return out


def _delta_figures(inputs: ReportInputs, folder: Path) -> list[FigureEntry]:
    ds = inputs.predictions
    train = np.asarray(ds["window"].values == "train")
    bcs = _boundary(ds)
    out: list[FigureEntry] = []
    for o in _outputs(ds):
        delta = _values(ds, f"{o}_delta")
        if delta is None or not bcs:
            continue
        corr = None
        table = inputs.delta_correlation
        if table is not None and o in table.index:
            row = np.asarray(table.loc[o], dtype=float).ravel()
            corr = {str(b): float(v) for b, v in zip(table.columns, row, strict=True)}
        boundary = {b: np.asarray(ds[f"bc_{b}"].values, dtype=float)[train] for b in bcs}
        path = folder / f"delta_bc_{_slug(o)}.png"
        out.append(
            FigureEntry(
                "Discrepancy",
                f"{o}: Δ against the boundary conditions",
                "Discrepancy on the training samples against each boundary condition, "
                "with the Pearson correlation r.",
                fg.plot_delta_vs_boundary(path, o, delta[train], boundary, corr),
            )
        )
    return out


def write_figures(inputs: ReportInputs, folder: str | Path) -> list[FigureEntry]:
    """Write every figure of the report into ``folder`` (PNG) and list them.

    PNG files in ``folder`` that this call did not write are removed, so the
    folder holds exactly the report's figures.

    Parameters
    ----------
    inputs
        What the report shows.
    folder
        Folder of the PNG files (created if missing).

    Returns
    -------
    list of FigureEntry
        The figures in page order.
    """
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    makers: list[Callable[[ReportInputs, Path], list[FigureEntry]]] = [
        _posterior_figures,
        _uncertainty_figures,
        _emulator_figures,
        _prediction_figures,
        _delta_figures,
    ]
    entries = [entry for make in makers for entry in make(inputs, target)]
    written = {e.path.resolve() for e in entries}
    for old in target.glob("*.png"):
        if old.resolve() not in written:
            old.unlink()
    return entries


# ----------------------------------------------------------------------------- sections


def _summary(inputs: ReportInputs) -> str:
    """The first screen: warnings, the verdicts, the fit, the calibrated quantities."""
    post, ds = inputs.posterior, inputs.predictions
    chains, draws = post.lam.shape
    inside, difference = discrepancy_used(post, inputs.discrepancy_posterior)
    facts = [
        ("study", inputs.study_name),
        ("configuration hash", inputs.config_hash),
        ("report written", datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")),
        ("bayescal version", __version__),
        ("simulator runs", f"{inputs.design.runs} ({len(inputs.failures)} failed)"),
        ("calibration parameters", ", ".join(post.names)),
        ("outputs", ", ".join(_outputs(ds))),
        ("posterior draws", f"{chains} chains × {draws} draws"),
        ("bands from ([predict] method)", route_used(dict(ds.attrs))),
        ("in-likelihood discrepancy ([outputs.errors.NAME] discrepancy)", inside),
        ("difference process Δ ([discrepancy] enabled)", difference),
    ]
    if inputs.warnings:
        # the first few open (the trust warnings come first), the rest fold: the answer
        # below stays on the first screen when every diagnostic of a short run fails
        shown, more = inputs.warnings[:SHOWN_WARNINGS], inputs.warnings[SHOWN_WARNINGS:]
        items = "".join(f"<li>{_e(w)}</li>" for w in shown)
        rest = "".join(f"<li>{_e(w)}</li>" for w in more)
        if more:
            rest = (
                f"<details><summary>{len(more)} more warning(s)</summary><ul>{rest}</ul></details>"
            )
        box = f'<div class="warn"><strong>Warnings</strong><ul>{items}</ul>{rest}</div>'
    else:
        box = (
            '<div class="ok">No warnings: every diagnostic check passed, no parameter leans '
            "on a bound of its prior, and no calibrated prediction is worse than the nominal "
            "out of sample.</div>"
        )
    passed, converged = convergence_line(post, inputs.discrepancy_posterior)
    css = "" if passed else ' class="fail"'
    verdicts = f"<p><b>Converged?</b> <span{css}>{_e(converged)}</span></p>"
    if inputs.catalogue:
        items = "".join(f"<li>{_e(line)}</li>" for line in inputs.catalogue)
        verdicts += (
            "<p><b>Did the calibration help?</b> Out of sample, calibrated against nominal "
            f"(catalogue) parameters (RMSE; within 5 %: no better):</p><ul>{items}</ul>"
        )
    bands = band_lines(inputs.metrics, float(ds.attrs.get("level", 0.95)))
    if bands:
        items = "".join(f"<li>{_e(line)}</li>" for line in bands)
        verdicts += f"<p><b>Do the bands hold?</b></p><ul>{items}</ul>"
    box += f'<div class="catalogue verdict">{verdicts}</div>'
    fit = (
        "<h3>RMSE of the nominal (catalogue) and the calibrated prediction</h3>"
        f'<div class="fit">{fit_table(inputs.metrics, _held_out(ds), _table)}</div>'
    )
    quantities = (
        "<h3>Calibrated quantities beside their catalogue values</h3>"
        + f'<div class="answer">{quantities_table(post, inputs.nominal, _table)}</div>'
        + '<p class="note">Catalogue: the nominal parameters of the study file and the '
        "derived quantities computed at them. Posterior mean and central 95 % credible "
        "interval, to two significant digits of the interval's width; they are the "
        "uncertainty of the calibrated parameters given this model and these data: what "
        "the model holds fixed (layer thicknesses, densities, the parameters not "
        "calibrated) adds none. Contraction: how much the data narrowed a parameter's "
        "prior (100 %: fixed by the data, 0 %: the prior unchanged). R-hat and ESS: "
        "Calibration parameters.</p>"
    )
    desc = f'<p class="desc">{_e(inputs.description)}</p>' if inputs.description else ""
    run = f"<details><summary>The run</summary>{_table(['item', 'value'], facts)}</details>"
    return desc + box + fit + quantities + run


def _ess(value: object) -> str:
    x = float(value)  # type: ignore[arg-type]
    return _num(round(x) if np.isfinite(x) else None)


def _posterior_table(post: Posterior) -> str:
    table = post.summary().drop(index=list(post.held_names))  # held: in the note above
    units = {name: prior.unit for name, prior in post.priors.items()}
    units |= {name: "1" for name in post.aux_names}
    units |= {
        ("noise_sd" if len(post.noise) == 1 else f"noise_sd_{o.name}"): o.unit for o in post.noise
    }
    units |= {name: d.unit for name, d in post.derived.items()}
    rows = [
        [
            name,
            units.get(str(name)) or "–",
            _num(r["mean"], 5),
            _num(r["sd"], 3),
            _num(r["lower"], 5),
            _num(r["upper"], 5),
            _num(r["r_hat"], 4),
            _ess(r["ess_bulk"]),
            _ess(r["ess_tail"]),
        ]
        for name, r in table.iterrows()
    ]
    header = ["parameter", "unit", "mean", "sd", "2.5 %", "97.5 %", "R-hat"]
    header += ["ESS bulk", "ESS tail"]
    return _table(header, rows)


def _parameters(inputs: ReportInputs) -> str:
    note = (
        '<p class="note">Posterior mean, standard deviation and central 95 % credible '
        "interval in the parameters' units (column unit); <code>lambda</code> and "
        "<code>lambda_star</code> are the precisions of the simulator's out-of-basis part "
        "and of the measurement error (standardised units). R-hat should be ≤ 1.01 and "
        "both ESS ≥ 400. All draws: <code>posterior_draws.csv</code>.</p>"
    )
    if held := ", ".join(inputs.posterior.held_names):
        note += f'<p class="note">Held at their nominal values, not calibrated: {held}.</p>'
    return note + _posterior_table(inputs.posterior)


METRIC_NOTE = (
    '<p class="note">Errors are <i>predicted − measured</i> over the samples of each window. '
    "The paper's “MAE” is the <b>maximum</b> absolute error (column “max abs error”); "
    "“mean abs error” is the mean of the absolute errors. CV(RMSE) and NMBE follow "
    "ASHRAE Guideline 14 with p = 1 degree of freedom: "
    "CV(RMSE) = √(Σe² / (n − 1)) / |mean(measured)| and "
    "NMBE = Σ(−e) / ((n − 1) · mean(measured)), both in %; NMBE &gt; 0 when the model "
    "under-predicts. Coverage is the share of measured samples inside the 95 % band "
    "(not defined for the nominal model). “Meets Guideline 14” checks the hourly criteria "
    "CV(RMSE) ≤ 30 % and |NMBE| ≤ 10 %, written for whole-building energy use and shown "
    "for orientation only. The test window is read only for these final metrics: "
    "parameters, priors and error models are chosen on the training periods "
    "(<code>bayescal compare</code>, leave-one-period-out cross-validation).</p>"
)


def _yes_no(value: object) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "–"
    return "yes" if bool(value) else "no"


def _metric_cell(column: MetricColumn, value: Any) -> str:
    if column.kind == "flag":
        return _yes_no(value)
    if column.kind == "count":
        return _num(int(value))
    return _num(float(value) * column.scale)


def _metrics_block(metrics: pd.DataFrame, output: str, window: str, held: bool = False) -> str:
    rows = metrics[(metrics["output"] == output) & (metrics["window"] == window)]
    if rows.empty:
        return ""
    unit = _unit(output) or "-"
    squared = f"({unit})²" if re.search(r"[/·*^²³ ]", unit) else f"{unit}²"
    # older runs lack newer columns: those are left out
    columns = [c for c in metric_columns("report") if c.name in rows.columns]
    header = ["model", *(c.title.format(u=unit, u2=squared) for c in columns)]
    order = [m for m in MODELS if m in set(rows["model"])]
    order += [m for m in rows["model"].unique() if m not in order]
    body = []
    for model in order:
        r = rows[rows["model"] == model].iloc[0]
        cells = [_metric_cell(c, r[c.name]) for c in columns]
        body.append([model.replace("+delta", " + Δ"), *cells])
    title = f"{output} [{unit}], {WINDOWS.get(window, window)}"
    if held:
        title += " (held-out sensor: never calibrated on)"
    return f"<h3>{_e(title)}</h3>" + _table(header, body)


def _metrics(inputs: ReportInputs) -> str:
    m = inputs.metrics
    outputs = list(dict.fromkeys([*_outputs(inputs.predictions), *m["output"].unique()]))
    held = _held_out(inputs.predictions)
    blocks = [_metrics_block(m, o, w, o in held) for o in outputs for w in ("train", "test")]
    text = "".join(b for b in blocks if b)
    level = float(inputs.predictions.attrs.get("level", 0.95))
    notes = "".join(f"<li>{_e(n)}</li>" for n in band_notes(m, level=level))
    if notes:
        text += f"<p>Why a band's coverage is off its rate:</p><ul>{notes}</ul>"
    return METRIC_NOTE + (text or "<p>No metrics were computed.</p>")


def _emulator(inputs: ReportInputs) -> str:
    em, loo = inputs.emulator, inputs.loo
    rows = [
        [o, _num(loo.rmse[o]), _num(loo.output_sd[o]), _num(loo.rmse[o] / loo.output_sd[o])]
        for o in loo.rmse
        if o in loo.output_sd
    ]
    kept = 100.0 * float(np.sum(em.basis.explained_kept))
    text = (
        f"<p>{em.basis.p} basis vectors explain {kept:.2f} % of the variance of the "
        f"standardised simulations; inputs: {_e(', '.join(em.input_labels))}. "
        f"Leave-one-run-out: {100.0 * loo.coverage(0.95):.1f} % of the held-out samples lie "
        "inside their 95 % predictive band (about 95 % expected).</p>"
    )
    header = ["output", "LOO RMSE", "SD of the simulations", "RMSE / SD"]
    return text + _table(header, rows)


def _discrepancy(inputs: ReportInputs) -> str:
    inside, _ = discrepancy_used(inputs.posterior, inputs.discrepancy_posterior)
    used = (
        "<p>In-likelihood discrepancy (<code>[outputs.errors.NAME] discrepancy</code>): "
        f"{_e(inside)}."
        + (
            " Its variance is sampled with θ* inside the calibration's likelihood (the rows "
            "<code>delta_rel</code> or <code>delta_ind</code> under Calibration parameters), "
            "and the prediction bands add it conditioned on the training residuals "
            "(Uncertainty)."
            if inside != "none"
            else ""
        )
        + "</p>"
    )
    if inputs.discrepancy_posterior is None and inputs.delta_explained is None:
        return used + (
            "<p>The difference process Δ (<code>[discrepancy] enabled</code>, the paper's "
            "second phase) was not used: no Δ was estimated.</p>"
        )
    parts = [
        used,
        "<p>The difference process Δ (<code>[discrepancy] enabled</code>) was estimated.</p>",
    ]
    if inputs.delta_explained:
        rows = [[o, _num(100.0 * v)] for o, v in inputs.delta_explained.items()]
        parts.append(_table(["output", "training residual variance explained by Δ [%]"], rows))
    corr = inputs.delta_correlation
    if corr is not None and not corr.empty:
        rows = [[str(o), *(_num(v, 3) for v in corr.loc[o])] for o in corr.index]
        parts.append("<h3>Pearson correlation of Δ with the boundary conditions</h3>")
        parts.append(_table(["output", *map(str, corr.columns)], rows))
    if inputs.discrepancy_posterior is not None:
        parts.append("<h3>θ* of the discrepancy phase</h3>")
        parts.append(_posterior_table(inputs.discrepancy_posterior))
    return "".join(parts)


def _figures(entries: Sequence[FigureEntry]) -> str:
    parts: list[str] = []
    group = None
    for entry in entries:
        if entry.group != group:
            group = entry.group
            parts.append(f"<h3>{_e(group)}</h3>")
        data = base64.b64encode(entry.path.read_bytes()).decode("ascii")
        parts.append(
            f'<figure><img src="data:image/png;base64,{data}" alt="{_e(entry.title)}">'
            f"<figcaption><b>{_e(entry.title)}.</b> {_e(entry.caption)} "
            f"(<code>figures/{_e(entry.path.name)}</code>)</figcaption></figure>"
        )
    return "".join(parts)


def _failures(failures: Sequence[RunFailure]) -> str:
    if not failures:
        return "<p>No simulator run failed.</p>"
    rows = [
        [
            f.index,
            ", ".join(f"{k} = {_num(v, 6)}" for k, v in f.parameters.items()),
            f.error_type,
            f.message,
            f.attempts,
            "–" if f.exit_code is None else f.exit_code,
        ]
        for f in failures
    ]
    header = ["run", "parameters", "error", "message", "attempts", "exit code"]
    return f"<p>{len(failures)} run(s) failed and were left out.</p>" + _table(header, rows)


def _design(design: Design, failures: Sequence[RunFailure]) -> str:
    failed = {f.index for f in failures}
    values = design.values
    rows = [
        [k, *(_num(v, 6) for v in values[k]), "failed" if k in failed else "ok"]
        for k in range(design.runs)
    ]
    table = _table(["run", *design.names, "status"], rows)
    return (
        f"<details><summary>{design.runs} runs over {len(design.names)} parameters "
        f"(Latin hypercube over the prior bounds)</summary>{table}</details>"
    )


def _settings(settings: Mapping[str, object]) -> str:
    if not settings:
        return "<p>No settings recorded.</p>"
    return _table(["setting", "value"], [[k, v] for k, v in settings.items()])


def render(inputs: ReportInputs, entries: Sequence[FigureEntry]) -> str:
    """The report page as one HTML string (figures embedded from ``entries``' files)."""
    bodies = {
        "Summary": _summary(inputs),
        "Calibration parameters": _parameters(inputs),
        "Uncertainty": uncertainty_section(
            inputs.posterior, inputs.predictions, _outputs(inputs.predictions), _table
        ),
        "Fit metrics": _metrics(inputs),
        "Emulator": _emulator(inputs),
        "Discrepancy": _discrepancy(inputs),
        "Figures": _figures(entries),
        "Failed runs": _failures(inputs.failures),
        "Design": _design(inputs.design, inputs.failures),
        "Settings": _settings(inputs.settings),
    }
    # The first screen is the answer (Summary); every other section folds.
    sections = "".join(
        f'<section id="{_slug(title).lower()}">'
        + (
            f"<h2>{_e(title)}</h2>{bodies[title]}"
            if title == SECTIONS[0]
            else f"<details><summary><h2>{_e(title)}</h2></summary>{bodies[title]}</details>"
        )
        + "</section>"
        for title in SECTIONS
    )
    title = _e(f"bayescal report: {inputs.study_name}")
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{title}</title><style>{CSS}</style></head><body>"
        f"<h1>{title}</h1>{sections}</body></html>\n"
    )


def write_report(inputs: ReportInputs, folder: Path) -> Path:
    """Write the report: ``report.html``, ``figures/*.png`` and ``posterior_draws.csv``.

    Parameters
    ----------
    inputs
        What the report shows.
    folder
        Output folder (created if missing).

    Returns
    -------
    pathlib.Path
        ``folder / "report.html"``.
    """
    target = Path(folder)
    entries = write_figures(inputs, target / "figures")
    write_draws_csv(inputs.posterior, target / "posterior_draws.csv")
    return atomic_write_text(target / "report.html", render(inputs, entries))
