"""What the report of a study shows: its settings, warnings and the Delta correlations.

:func:`write_study_report` takes a study's results as plain objects (no
pipeline object: the pipeline calls it) and decides the report's content:
the warnings at the top (a parameter leaning on a prior bound, a calibrated
prediction worse than the nominal out of sample, failed diagnostics, failed
simulator runs) and the out-of-sample comparison with the nominal parameters, the
settings table, and the correlation of the discrepancy with each boundary
condition; :func:`bayescal.report.html.write_report` writes the page.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from bayescal.calibration.modelerror import discrepancy_ratios
from bayescal.calibration.posterior import Posterior
from bayescal.config import Study
from bayescal.design import Design
from bayescal.discrepancy import Discrepancy
from bayescal.emulator.gp import Emulator, LooResult
from bayescal.periods import PeriodLayout
from bayescal.report.answer import DISCREPANCY_KINDS
from bayescal.report.html import ReportInputs, write_report
from bayescal.report.trust import catalogue_verdicts, held_out_outputs, trust_warnings
from bayescal.runner import RunFailure

__all__ = ["delta_correlation", "report_settings", "write_study_report"]

SAMPLER_NAMES = {"mwg": "Metropolis-within-Gibbs", "nuts": "NUTS"}


def delta_correlation(predictions: xr.Dataset) -> pd.DataFrame:
    """Pearson correlation of Delta with each boundary condition over the training samples.

    Parameters
    ----------
    predictions
        The predictions dataset with ``{output}_delta`` and ``bc_{name}`` series
        (:func:`bayescal.pipeline.predict.predictions_dataset`).

    Returns
    -------
    pandas.DataFrame
        Rows: outputs; columns: boundary conditions; NaN where a series is constant. [-]
    """
    ds = predictions
    train = ds["window"].values == "train"
    outputs = ds.attrs["outputs"].split(",")
    boundary = [b for b in ds.attrs["boundary"].split(",") if b]
    table = {}
    for o in outputs:
        if f"{o}_delta" not in ds:  # a held-out output has no Delta
            continue
        d = ds[f"{o}_delta"].values[train]
        row = {}
        for b in boundary:
            v = ds[f"bc_{b}"].values[train]
            ok = np.isfinite(d) & np.isfinite(v)
            sd = np.std(d[ok]) * np.std(v[ok]) if ok.sum() > 2 else 0.0
            row[b] = float(np.corrcoef(d[ok], v[ok])[0, 1]) if sd > 0 else float("nan")
        table[o] = row
    return pd.DataFrame(table).T


def _calibration_longer(study: Study) -> str:
    """``", extended up to N until converged"`` where ``max_samples`` lets the chains grow."""
    cal = study.calibration
    if not cal.extends:
        return ""
    return f", extended up to {cal.most_samples} until converged"


def _emulator_training(study: Study) -> str:
    """How the emulator's hyperparameters were found, as ``[emulator] training`` says."""
    em = study.emulator
    if em.training == "map":
        return (
            "map: multi-start L-BFGS-B search of the hyperparameters' MAP with the exact "
            f"gradient, {em.samples} draws of its Laplace approximation"
        )
    return (
        f"mcmc: Metropolis-within-Gibbs, 2 chains x ({em.burn} + {em.samples}), "
        "best draw refined by L-BFGS-B"
    )


def _kind(discrepancy: object) -> str:
    """``True`` is the discrepancy over the conditions."""
    return "conditions" if discrepancy is True else str(discrepancy)


def _in_likelihood(study: Study) -> str:
    """The outputs with an in-likelihood discrepancy and its kind, else ``"none"``."""
    used = [
        f"{name} ({DISCREPANCY_KINDS[_kind(spec.discrepancy)]})"
        for name, spec in study.outputs.errors.items()
        if spec.discrepancy
    ]
    return ", ".join(used) or "none"


def report_settings(
    study: Study, layout: PeriodLayout, emulator: Emulator | None = None
) -> dict[str, object]:
    """The key settings of a study, as the report's settings table shows them.

    Parameters
    ----------
    study
        The validated study.
    layout
        The periods of its measured data.
    emulator
        The trained emulator (adds the number of basis vectors and the inputs).
    """
    s = study
    out: dict[str, object] = {
        "simulator": s.simulator.type,
        "runs (design)": s.design.runs,
        "training periods m*": layout.m_star,
        "samples per period": layout.period,
        "test samples": layout.test,
        "emulator training ([emulator] training)": _emulator_training(study),
        "calibration MCMC": f"{SAMPLER_NAMES[s.calibration.sampler]}, "
        f"{s.calibration.chains} chains x ({s.calibration.burn} + {s.calibration.samples}"
        f"{_calibration_longer(s)})",
        "algebra": s.emulator.algebra,
        "in-likelihood discrepancy ([outputs.errors.NAME] discrepancy)": _in_likelihood(study),
        "difference process Δ ([discrepancy] enabled)": (
            "enabled" if s.discrepancy.enabled else "not used"
        ),
        "seed": s.study.seed,
    }
    if s.discrepancy.enabled:
        burn, kept, most = s.discrepancy_lengths()
        longer = "" if most == kept else f", extended up to {most} until converged"
        out["discrepancy MCMC"] = (
            f"lockstep whitened Metropolis-within-Gibbs with Delta updates, "
            f"{s.calibration.chains} chains x ({burn} + {kept}{longer})"
        )
    if emulator is not None:
        out["basis vectors p"] = emulator.basis.p
        out["variable inputs x"] = ", ".join(emulator.inputs.labels)
    return out


def write_study_report(
    study: Study,
    layout: PeriodLayout,
    folder: Path,
    *,
    design: Design,
    failures: Sequence[RunFailure],
    emulator: Emulator,
    loo: LooResult,
    posterior: Posterior,
    discrepancy: Discrepancy | None,
    predictions: xr.Dataset,
    metrics: pd.DataFrame,
    nominal_derived: Mapping[str, float] | None = None,
) -> Path:
    """Write the HTML report of a study's results into ``folder``.

    Parameters
    ----------
    study
        The validated study (name, description, settings).
    layout
        The periods of its measured data.
    folder
        Output folder of the report (``out/report``).
    design
        The full design (all rows, failed ones included).
    failures
        The simulator runs that failed (may be empty).
    emulator, loo
        The trained emulator and its leave-one-run-out cross-validation.
    posterior
        The calibration posterior.
    discrepancy
        The difference process, if it was estimated.
    predictions, metrics
        The predictions dataset and the metrics table.
    nominal_derived
        The derived quantities at the nominal parameters (catalogue values
        shown beside the posterior's), where computed.

    Returns
    -------
    pathlib.Path
        ``folder / "report.html"``.
    """
    held = held_out_outputs(dict(predictions.attrs))
    disc = None if discrepancy is None else discrepancy.posterior
    sizes = discrepancy_ratios(emulator, posterior)
    warnings = [*trust_warnings(posterior, disc, metrics, held, sizes), *posterior.warnings]
    if failures:
        warnings.append(f"{len(failures)} simulator run(s) failed and were dropped")
    if route_warning := predictions.attrs.get("route_warning"):  # method = "auto"
        warnings.append(str(route_warning))
    inputs = ReportInputs(
        study_name=study.study.name,
        description=study.study.description,
        config_hash=study.config_hash(),
        design=design,
        failures=tuple(failures),
        emulator=emulator,
        loo=loo,
        posterior=posterior,
        discrepancy_posterior=None if discrepancy is None else discrepancy.posterior,
        predictions=predictions,
        metrics=metrics,
        delta_correlation=None if discrepancy is None else delta_correlation(predictions),
        delta_explained=None if discrepancy is None else dict(discrepancy.explained),
        warnings=tuple(warnings),
        catalogue=tuple(v.line() for v in catalogue_verdicts(metrics, held)),
        settings=report_settings(study, layout, emulator),
        nominal={
            **{name: p.nominal for name, p in study.parameters.items()},
            **(nominal_derived or {}),
        },
    )
    return write_report(inputs, folder)
