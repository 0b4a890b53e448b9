"""The calibrated model on new conditions: ``bayescal predict STUDY --data FILE``.

A finished calibration predicts another record of the same construction (another
season, another house, the rest of a campaign) from that record's boundary
conditions, with the study's whole uncertainty:

* the **parameters**: ``[predict] runs`` posterior draws, thinned evenly over
  the chains (``--set NAME=VALUE`` fixes a calibrated parameter at a value in
  every draw);
* the **model**: the simulator re-run at every draw on the new boundary
  conditions (``method = "simulator"``), or the emulator where the new
  periods' conditions ``x`` lie inside the range of its training periods
  (``method = "emulator"``; refused outside it, since a GP far from its data
  reverts to its mean);
* the **error model**: the calibration's noise of every output (its
  ``lambda*``, or with ``[predict] noise = "simulator"`` the noise estimated
  again from the re-run simulator on the study's training periods), white or
  AR(1) (a band is the marginal distribution of one sample);
* the **in-likelihood discrepancy** (``[outputs.errors.NAME] discrepancy``)
  kriged from the study's training residuals at the new periods' conditions
  (method.md section 6, "New conditions"): near a training period it carries
  that period's residual over, far from all of them it reverts to its prior
  (mean 0, its full variance);
* the **difference process** Delta(x) of ``[discrepancy]`` where the study
  estimated it, for the corrected prediction;
* **held-out sensors**: the simulator at the draws plus their stated accuracy.

The new record is read with the study's ``[data]`` mapping
(:func:`bayescal.data.measured.load_new_record`): the same format, step and
columns; measured outputs may be missing. After the study's warm-up it is cut
into whole periods in the phase of the study's, all of them predicted. Where
the file holds measurements, the same metrics as the study's test window are
computed (RMSE against the nominal model, coverage of the 50 % and 95 % bands,
PIT, the n_eff that says how much one window's coverage tells).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import xarray as xr

from bayescal.data.measured import MeasuredData, load_new_record
from bayescal.design import Design
from bayescal.emulator.assemble import Assembled, with_history
from bayescal.errors import ConfigError, SimulatorError
from bayescal.metrics import band_notes, honest_range
from bayescal.pipeline.predict import (
    Band,
    conditioned_discrepancy,
    delta_series,
    held_out_band,
    merge_bands,
    metrics_table,
    predict_band,
    predictions_dataset,
    simulator_band,
)
from bayescal.pipeline.simnoise import simulator_noise
from bayescal.pipeline.stages import (
    Context,
    Options,
    held_out_sd,
    level_values,
    nominal_run,
    simulate,
)
from bayescal.report.trust import ABSORBS, NO_BETTER

if TYPE_CHECKING:
    from bayescal.calibration.posterior import Posterior
    from bayescal.config import Study
    from bayescal.discrepancy import Discrepancy
    from bayescal.pipeline.run import Results

__all__ = [
    "NEW_WINDOW",
    "NewPrediction",
    "conditions_outside",
    "new_assembled",
    "posterior_draws",
    "predict_as",
    "predict_new",
    "runs_at",
]

#: The window label of the new record's predicted samples.
NEW_WINDOW = "new"
#: How far (in the normalised units of ``x``, whose training periods span [0, 1]) a
#: new period's condition may lie outside the training range for the emulator route.
RANGE_SLACK = 1e-9

Say = Callable[[str], None]


@dataclass(frozen=True)
class NewPrediction:
    """The calibrated model's prediction of a new record.

    Attributes
    ----------
    dataset
        Measured (NaN where the file has none), nominal and calibrated series
        with their bands on the new record's clock (window ``"new"`` for the
        predicted periods), as :func:`~bayescal.pipeline.predict.predictions_dataset`.
    metrics
        Fit metrics on the window ``"new"`` where the record holds measurements.
    method
        ``"simulator"`` or ``"emulator"``: what gave the model part.
    outside
        Labels of the conditions ``x`` where a new period lies outside the
        training periods' range (``"temp_surf_out:pc1 (max 1.37)"``).
    record
        The new record as read.
    notes
        What the user should know (method chosen, conditions outside the range,
        outputs without measurements, draws whose runs failed).
    """

    dataset: xr.Dataset
    metrics: pd.DataFrame
    method: str
    outside: tuple[str, ...]
    record: MeasuredData
    notes: tuple[str, ...] = ()


def new_x(assembled: Assembled, record: MeasuredData, history: int) -> np.ndarray:
    """The normalised conditions ``x`` of the new record's periods ``(P, s)``.

    The same transform as the study's training periods (its boundary-condition
    PCA and normalisation, with ``history`` preceding periods); values outside
    [0, 1] are conditions the training periods did not span.
    """
    layout = record.layout
    bc = with_history(dict(record.forcing.series), history, layout.period)
    return assembled.inputs.transform({n: layout.cut(v, "test").T for n, v in bc.items()})


def new_assembled(assembled: Assembled, record: MeasuredData, history: int) -> Assembled:
    """``assembled`` with the new record as its test window (no runs, no measurement there).

    What the study learnt (basis, standardisation, training periods and their
    measurements, error models) is kept; the layout and ``x_test`` are the new
    record's, so the prediction functions of :mod:`bayescal.pipeline.predict`
    predict its periods.
    """
    x = new_x(assembled, record, history)
    nan = np.full((assembled.y_std.shape[0], x.shape[0]), np.nan)
    return dataclasses.replace(
        assembled, layout=record.layout, x_test=x, y_star_test_std=nan, y_test_sim_std=None
    )


def conditions_outside(assembled: Assembled, x_new: np.ndarray) -> tuple[str, ...]:
    """Labels of the columns of ``x_new`` outside the training periods' range, with how far."""
    lo, hi = assembled.x.min(axis=0), assembled.x.max(axis=0)
    out = []
    for j, label in enumerate(assembled.inputs.labels):
        below, above = float(x_new[:, j].min()), float(x_new[:, j].max())
        if below < lo[j] - RANGE_SLACK:
            out.append(f"{label} (min {below:.3g} < {lo[j]:.3g})")
        if above > hi[j] + RANGE_SLACK:
            out.append(f"{label} (max {above:.3g} > {hi[j]:.3g})")
    return tuple(out)


def posterior_draws(
    posterior: Posterior, n: int, fixed: Mapping[str, float]
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` draws thinned evenly: theta* ``(S, t)`` with ``fixed`` set, and their indices."""
    names = list(posterior.names)
    theta = posterior.draws.reshape(-1, len(names))
    pick = np.unique(np.linspace(0, theta.shape[0] - 1, min(n, theta.shape[0])).astype(int))
    chosen = np.array(theta[pick], dtype=float)
    for name, value in fixed.items():
        chosen[:, names.index(name)] = value
    return chosen, pick


def runs_at(ctx: Context, theta: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The simulator at ``theta`` on ``ctx``'s record: outputs of the runs that succeeded
    and their rows in ``theta``."""
    res = simulate(ctx, Design.from_values(ctx.priors, theta))
    return dict(res.outputs), np.asarray(res.indices, dtype=int)


def _check_fixed(ctx: Context, fixed: Mapping[str, float]) -> None:
    priors = ctx.priors
    for name, value in fixed.items():
        if name not in priors:
            raise ConfigError(
                f"--set {name}: not a calibrated parameter of the study",
                hint=f"calibrated: {', '.join(priors)}; a fixed input is changed by a scenario",
            )
        prior = priors[name]
        if not prior.lower <= value <= prior.upper:
            raise ConfigError(
                f"--set {name}={value:g} lies outside its prior [{prior.lower:g}, "
                f"{prior.upper:g}], where the calibration never ran the model",
                hint="give a value inside the prior's bounds",
            )


def _simulator_band(
    ctx: Context,
    new_ctx: Context,
    at: Assembled,
    results: Results,
    posterior: Posterior,
    fixed: Mapping[str, float],
    discrepancy: Discrepancy | None,
) -> tuple[Band, int]:
    """The band of the re-run simulator on the new record, and the draws it holds."""
    section = ctx.study.predict
    em = results.emulator
    assert em is not None  # checked by the caller
    theta, pick = posterior_draws(posterior, section.runs, fixed)
    new_runs, ok_new = runs_at(new_ctx, theta)
    train_runs, ok_train = runs_at(ctx, theta)
    both = np.intersect1d(ok_new, ok_train)
    if both.size < 2:
        raise SimulatorError(
            f"only {both.size} of {theta.shape[0]} posterior draws ran on both records",
            hint=f"see {ctx.out / 'simulations' / 'failures'} for the failed runs",
        )
    rows_new = np.searchsorted(ok_new, both)
    rows_train = np.searchsorted(ok_train, both)
    names = list(em.emulator.outputs.names)
    model_new = level_values(new_ctx, {o: new_runs[o][rows_new] for o in names}, "simulated")
    model_train = level_values(ctx, {o: train_runs[o][rows_train] for o in names}, "simulated")
    drawn = pick[both]
    lam = posterior.lam_stars.reshape(-1, len(names))[drawn]
    if discrepancy is None:
        lam = simulator_noise(
            em.assembled, model_train, posterior, drawn, section.noise, em.emulator
        )
    measured = {o: new_ctx.measured.outputs[o] for o in names}
    band = simulator_band(
        at,
        model_new,
        lam,
        level=section.level,
        discrepancy=discrepancy,
        measured=measured,
        model_error=conditioned_discrepancy(
            em.emulator, em.assembled, posterior, drawn, model_train, at=at, lam_stars=lam
        ),
        transforms=ctx.transforms,
    )
    held = ctx.study.outputs.held_out
    if discrepancy is None and held:
        extra = held_out_band(
            at.layout,
            {o: new_runs[o][rows_new] for o in held},
            {o: held_out_sd(ctx, o) for o in held},
            new_ctx.measured.held_out,
            section.level,
        )
        band = merge_bands(band, extra)
    return band, int(both.size)


def _emulator_band(
    ctx: Context,
    at: Assembled,
    results: Results,
    posterior: Posterior,
    discrepancy: Discrepancy | None,
) -> Band:
    em = results.emulator
    assert em is not None  # checked by the caller
    section = ctx.study.predict
    measured = {o: ctx.measured.outputs[o] for o in ctx.study.outputs.calibrate}
    return predict_band(
        em.emulator,
        at,
        posterior,
        draws=section.draws,
        level=section.level,
        discrepancy=discrepancy,
        measured=measured,
        transforms=ctx.transforms,
    )


def predict_new(
    results: Results,
    data: Path,
    *,
    start: pd.Timestamp | None = None,
    end: pd.Timestamp | None = None,
    fixed: Mapping[str, float] | None = None,
    method: str | None = None,
    options: Options | None = None,
    say: Say | None = None,
) -> NewPrediction:
    """Predict another record with a finished calibration (see the module docstring).

    Parameters
    ----------
    results
        The study's results (:func:`bayescal.pipeline.load_results`), calibrated.
    data
        The new record: a file in the study's format and column mapping.
    start, end
        Cut the file to this window (local time of the data, end exclusive).
    fixed
        Calibrated parameters fixed at a value in every draw (physical units).
    method
        ``"simulator"``, ``"emulator"`` or ``None`` (the study's ``[predict]
        method``, with the simulator where the emulator would extrapolate).
    options
        Where the simulator runs and progress callbacks (they do not change results).
    say
        Receives one-line notes.

    Raises
    ------
    ConfigError
        The study has no finished calibration, an unknown or out-of-prior
        ``fixed`` parameter, or the emulator asked for outside its range.
    DataError
        The file cannot be read with the study's mapping (see
        :func:`~bayescal.data.measured.load_new_record`).
    """
    tell = say or (lambda _: None)
    ctx = (
        results.context
        if options is None
        else dataclasses.replace(results.context, options=options)
    )
    if results.emulator is None or results.posterior is None:
        raise ConfigError(
            f"{ctx.out} holds no finished calibration (stages missing: "
            f"{', '.join(results.missing())})",
            hint=f"run `bayescal run {ctx.study.path}` first",
        )
    fixed = dict(fixed or {})
    _check_fixed(ctx, fixed)
    layout = ctx.measured.layout
    anchor = ctx.measured.times[int(layout.train_starts[0])]
    record = load_new_record(ctx.study, data, anchor, start=start, end=end)
    em = results.emulator
    history = ctx.study.emulator.history_periods
    at = new_assembled(em.assembled, record, history)
    outside = conditions_outside(em.assembled, at.x_test)
    notes: list[str] = []
    chosen = method or ctx.study.predict.method
    if chosen == "auto":  # its check measured the study's own test window, not this record
        chosen = "simulator"
    if chosen == "emulator" and outside:
        if method == "emulator":
            raise ConfigError(
                "the new record's conditions lie outside the emulator's training range: "
                + "; ".join(outside[:4])
                + (f" and {len(outside) - 4} more" if len(outside) > 4 else ""),
                hint="predict with --method simulator (the simulator re-run at posterior draws)",
            )
        chosen = "simulator"
        notes.append(
            "the new conditions lie outside the emulator's training range "
            f"({'; '.join(outside[:3])}): the simulator is re-run at the posterior draws"
        )
    elif outside:
        notes.append(
            "the new conditions lie outside the training periods' range "
            f"({'; '.join(outside[:3])}{' ...' if len(outside) > 3 else ''}): the simulator "
            "carries the physics there, and an in-likelihood discrepancy reverts toward its prior"
        )
    if chosen == "emulator" and fixed:
        raise ConfigError(
            "--set fixes parameters in the simulator's runs only",
            hint="predict with --method simulator",
        )
    new_ctx = dataclasses.replace(ctx, measured=record)
    absent = [
        o
        for o in (*ctx.study.outputs.calibrate, *ctx.study.outputs.held_out)
        if not np.isfinite(
            ({**record.outputs, **record.held_out})[o][record.layout.test_begin :]
        ).any()
    ]
    if absent:
        notes.append(f"no measurement of {', '.join(absent)} in the new record: predicted only")
    tell(
        f"predict: {record.layout.test_starts.size} period(s) of {record.source.name}, "
        f"{'simulator re-run at posterior draws' if chosen == 'simulator' else 'emulator'}"
    )
    if chosen == "simulator":
        band, n_ok = _simulator_band(ctx, new_ctx, at, results, results.posterior, fixed, None)
        if n_ok < min(ctx.study.predict.runs, results.posterior.draws[..., 0].size):
            notes.append(f"the band holds the {n_ok} posterior draws whose runs succeeded")
    else:
        band = _emulator_band(new_ctx, at, results, results.posterior, None)
    corrected = delta = None
    disc = results.discrepancy
    if disc is not None:
        if chosen == "simulator":
            corrected = _simulator_band(ctx, new_ctx, at, results, disc.posterior, fixed, disc)[0]
        else:
            corrected = _emulator_band(new_ctx, at, results, disc.posterior, disc)
        delta = delta_series(at, disc, list(em.emulator.outputs.names))
    return _prediction(
        new_ctx, band, corrected, delta, chosen, fixed, outside, tuple(notes), ctx.study
    )


def _prediction(
    new_ctx: Context,
    band: Band,
    corrected: Band | None,
    delta: Mapping[str, np.ndarray] | None,
    method: str,
    fixed: Mapping[str, float],
    outside: tuple[str, ...],
    notes: tuple[str, ...],
    calibrated: Study,
) -> NewPrediction:
    """The dataset and metrics of a prediction of ``new_ctx``'s record (its study's
    outputs, its nominal run), made with the calibration of ``calibrated``."""
    record, study = new_ctx.measured, new_ctx.study
    held = study.outputs.held_out
    ds = predictions_dataset(
        record.times,
        record.layout,
        {o: record.outputs[o] for o in study.outputs.calibrate} | dict(record.held_out),
        nominal_run(new_ctx),
        band,
        record.forcing.series,
        corrected,
        delta,
        attrs={
            "level": calibrated.predict.level,
            "study": calibrated.study.name,
            "held_out": ",".join(held),
            "source": str(record.source),
            "method": method,
            "fixed": ",".join(f"{k}={v:g}" for k, v in fixed.items()),
        },
    )
    metrics = metrics_table(ds)
    metrics = metrics[metrics["rmse"].notna()].reset_index(drop=True)  # measured samples only
    metrics["window"] = metrics["window"].replace({"test": NEW_WINDOW})
    label = np.where(ds["window"].values == "test", NEW_WINDOW, ds["window"].values)
    ds = ds.assign_coords(window=("time", label.astype(str), ds["window"].attrs))
    return NewPrediction(ds, metrics, method, outside, record, notes)


def predict_as(
    results: Results,
    other: Study,
    data: Path | None = None,
    *,
    start: pd.Timestamp | None = None,
    end: pd.Timestamp | None = None,
    fixed: Mapping[str, float] | None = None,
    options: Options | None = None,
    say: Say | None = None,
) -> NewPrediction:
    """Predict another experiment's record with this calibration: ``predict --as OTHER``.

    ``other`` is a study of the same building in another set-up (the test box
    calibrated on its co-heating phase, predicting its free-float phase): its
    data mapping, simulator settings (mode, fixed inputs) and outputs. Its
    parameters take this calibration's posterior draws where the names agree,
    their nominal values elsewhere (``fixed`` sets one in every draw); the
    simulator is re-run at ``[predict] runs`` draws on its record (``data``,
    default its own file). Its outputs are not those the calibration learnt an
    error model for, so each band holds the parameters' uncertainty and the
    output's **stated** accuracy (``[outputs.errors.NAME] sd`` of ``other``,
    required), like a held-out sensor's; no discrepancy carries over.

    Raises
    ------
    ConfigError
        No finished calibration, an output of ``other`` without a stated
        accuracy, no shared parameter, or draws outside ``other``'s bounds.
    """
    from bayescal.config import nominal_parameters
    from bayescal.pipeline.reuse import run_parameters, study_simulator

    tell = say or (lambda _: None)
    ctx = (
        results.context
        if options is None
        else dataclasses.replace(results.context, options=options)
    )
    posterior = results.posterior
    if posterior is None:
        raise ConfigError(
            f"{ctx.out} holds no finished calibration",
            hint=f"run `bayescal run {ctx.study.path}` first",
        )
    outputs = (*other.outputs.calibrate, *other.outputs.held_out)
    missing = [o for o in outputs if other.outputs.noise_sd(o) is None]
    if missing:
        raise ConfigError(
            f"--as {other.path}: no stated accuracy of {', '.join(missing)}",
            hint=f"set [outputs.errors.{missing[0]}] sd = ... in {Path(other.path or '').name}: "
            "the band of an output the calibration did not learn holds the sensor's accuracy",
        )
    names = list(posterior.names)
    wanted = run_parameters(other)
    shared = [n for n in wanted if n in names]
    if not shared:
        raise ConfigError(
            f"--as {other.path}: its parameters {', '.join(wanted)} share none with the "
            f"calibration's {', '.join(names)}"
        )
    fixed = dict(fixed or {})
    unknown = sorted(set(fixed) - set(wanted))
    if unknown:
        raise ConfigError(
            f"--set {unknown[0]}: not a calibrated parameter of {Path(other.path or '').name}",
            hint=f"its parameters: {', '.join(wanted)}",
        )
    nominal = nominal_parameters(other)
    draws, _ = posterior_draws(posterior, ctx.study.predict.runs, {})
    columns = [
        np.full(draws.shape[0], fixed[n] if n in fixed else nominal[n])
        if n in fixed or n not in names
        else draws[:, names.index(n)]
        for n in wanted
    ]
    theta = np.column_stack(columns)
    layout = ctx.measured.layout
    anchor = ctx.measured.times[int(layout.train_starts[0])]
    record = load_new_record(other, data or Path(other.data.file), anchor, start=start, end=end)
    other_ctx = dataclasses.replace(
        ctx, study=other, simulator=study_simulator(other), measured=record
    )
    notes = [
        f"the parameters {', '.join(shared)} from the posterior"
        + (
            f"; {', '.join(n for n in wanted if n not in names)} at nominal"
            if len(shared) < len(wanted)
            else ""
        )
        + f"; the bands hold the stated accuracy of {', '.join(outputs)}, no model error"
    ]
    name = Path(other.path or "").name
    tell(f"predict as {name}: {theta.shape[0]} posterior draws on {record.source.name}")
    runs, _ = runs_at(other_ctx, theta)
    measured = {**record.outputs, **record.held_out}
    band = held_out_band(
        record.layout,
        {o: runs[o] for o in outputs},
        {o: held_out_sd(other_ctx, o) for o in outputs},
        {o: measured[o] for o in outputs},
        ctx.study.predict.level,
    )
    return _prediction(other_ctx, band, None, None, "simulator", fixed, (), tuple(notes), ctx.study)


#: The columns of predictions.csv per output, after ``{output}_``.
CSV_SERIES = (
    "measured",
    "nominal",
    "calibrated",
    "calibrated_lower",
    "calibrated_lower50",
    "calibrated_upper50",
    "calibrated_upper",
    "corrected",
    "corrected_lower",
    "corrected_lower50",
    "corrected_upper50",
    "corrected_upper",
)


def summary_lines(pred: NewPrediction) -> list[str]:
    """What the prediction shows, one line each: the record, the method, the verdicts."""
    ds, m = pred.dataset, pred.metrics
    layout = pred.record.layout
    times = pd.DatetimeIndex(pred.record.times[layout.test_begin :]).tz_localize("UTC")
    zone = pred.record.zone
    level = float(ds.attrs.get("level", 0.95))
    how = (
        "the simulator re-run at posterior draws"
        if pred.method == "simulator"
        else "the emulator at posterior draws"
    )
    lines = [
        f"prediction of {pred.record.source.name} by the calibration {ds.attrs['study']!r}",
        f"  {layout.test_starts.size} period(s), {times[0].tz_convert(zone):%Y-%m-%d %H:%M} to "
        f"{times[-1].tz_convert(zone):%Y-%m-%d %H:%M} local time, after the study's warm-up",
        f"  model: {how}" + (f"; fixed: {ds.attrs['fixed']}" if ds.attrs.get("fixed") else ""),
        f"  bands ({100 * level:g} % and 50 %) of a measurement: parameters + noise"
        + " + the in-likelihood discrepancy kriged at the new conditions, where the study has one"
        + (" + the emulator's own variance" if pred.method == "emulator" else ""),
    ]
    lines += [f"  note: {n}" for n in pred.notes]
    warnings: list[str] = []
    rows_out: list[str] = []
    for output in dict.fromkeys(m["output"]) if len(m) else ():
        rows = m[m["output"] == output].set_index("model")
        if "calibrated" not in rows.index:
            continue
        cal = rows.loc["calibrated"]
        line = f"  {output}: RMSE {float(cal['rmse']):.4g}"
        if "nominal" in rows.index:
            nom = float(rows.loc["nominal", "rmse"])
            change = float(cal["rmse"]) / nom - 1.0 if nom > 0 else float("nan")
            verdict = (
                "better than"
                if change < -NO_BETTER
                else "worse than"
                if change > NO_BETTER
                else "as good as"
            )
            line += f" against {nom:.4g} at the nominal values ({100 * change:+.0f} %, {verdict}"
            line += " the catalogue)"
            if verdict == "worse than":
                warnings.append(
                    f"WARNING: {output} is predicted {100 * change:.0f} % worse than with the "
                    f"catalogue values: {ABSORBS}"
                )
        cover95, cover50 = float(cal["coverage95"]), float(cal["coverage50"])
        line += f"; bands cover {cover95:.3f} / {cover50:.3f}"
        if "n_eff95" in cal and np.isfinite(float(cal["n_eff95"])):
            low, high = honest_range(level, float(cal["n_eff95"]))
            holds = "within" if low <= cover95 <= high else "OUTSIDE"
            line += f" ({100 * level:g} % band {holds} {low:.2f}-{high:.2f}, what an honest band"
            line += f" covers on about {float(cal['n_eff95']):.0f} independent samples)"
            if holds == "OUTSIDE":
                side = "too narrow" if cover95 < low else "too wide"
                warnings.append(
                    f"WARNING: the {100 * level:g} % band of {output} covers {cover95:.3f}, "
                    f"outside {low:.2f}-{high:.2f}: {side} for these errors"
                )
        rows_out.append(line)
    lines += warnings + rows_out
    lines += [f"  note: {n}" for n in band_notes(m, level=level)]
    return lines


def write_new_prediction(pred: NewPrediction, folder: Path) -> dict[str, Path]:
    """Write predictions.nc, metrics.csv, predictions.csv, summary.md and one figure per
    output into ``folder`` (atomically, file by file)."""
    from bayescal.atomic import atomic_write_text
    from bayescal.report.figures import plot_fit
    from bayescal.store.predictions import METRICS_FILE, SERIES_FILE, save_predictions

    folder.mkdir(parents=True, exist_ok=True)
    ds = pred.dataset
    save_predictions(folder, ds, pred.metrics)
    files = {"netcdf": folder / SERIES_FILE, "metrics": folder / METRICS_FILE}
    keep = np.asarray(ds["window"].values == NEW_WINDOW)
    frame = pd.DataFrame({"time_utc": pd.DatetimeIndex(ds["time"].values[keep])})
    outputs = ds.attrs["outputs"].split(",")
    for o in outputs:
        for kind in CSV_SERIES:
            if f"{o}_{kind}" in ds:
                frame[f"{o}_{kind}"] = ds[f"{o}_{kind}"].values[keep]
    files["csv"] = atomic_write_text(folder / "predictions.csv", frame.to_csv(index=False))
    for o in outputs:
        if f"{o}_calibrated" not in ds:
            continue
        png = plot_fit(
            folder / f"{o}.png",
            ds["time"].values,
            ds["window"].values,
            o,
            ds[f"{o}_measured"].values,
            ds[f"{o}_calibrated"].values,
            ds[f"{o}_calibrated_lower"].values,
            ds[f"{o}_calibrated_upper"].values,
            nominal=ds[f"{o}_nominal"].values,
            windows=(NEW_WINDOW,),
            band50=(ds[f"{o}_calibrated_lower50"].values, ds[f"{o}_calibrated_upper50"].values),
        )
        files[f"figure {o}"] = png
    lines = summary_lines(pred)
    table = pred.metrics.to_string(index=False, float_format="{:.4g}".format)
    text = "\n".join(["# " + lines[0], "", *lines[1:], "", "## Metrics", "", "```", table, "```"])
    files["summary"] = atomic_write_text(folder / "summary.md", text + "\n")
    return files
