"""The catalogue model as a variant of ``bayescal compare``: does calibration help?

The *catalogue* model of a study holds every calibrated parameter at its
``nominal`` value of the study file and fits only the error model the study
states: the simulator precision ``lambda``, each output's ``lambda*``, the
AR(1) coefficients and the in-likelihood discrepancy's variances, sampled as
in the calibration (the same chains, burn-in and length). It is the study's
own calibration target (eq. 16) with theta* held at the nominal values
(:func:`bayescal.calibration.target.hold_theta`), on the **same emulator**: the
calibrated variants and the catalogue then differ in one thing only, whether
theta* was learnt from the training periods, and both carry the emulator's
uncertainty at the parameters they predict with. (The simulator's own nominal
run would avoid the emulator's error at the nominal values but put the
catalogue on another footing than the variants it is ranked with.)

It is scored exactly as a variant (:func:`bayescal.pipeline.scores.score_calibration`):
leave-one-period-out ELPD by PSIS with refits where the Pareto ``k`` exceeds
0.7, and the left-out bands. One catalogue row is added per distinct error
model among the variants, on the emulator of the first variant with that error
model. :func:`catalogue_warnings` says loudly where a catalogue row ranks
above the best calibrated variant of its error model or within one standard
error of the paired difference below it: :data:`DOES_NOT_IMPROVE`, with
:data:`bayescal.report.trust.ABSORBS`, the wording of the report's out-of-sample
check (:func:`bayescal.report.trust.catalogue_verdicts`).

Its scores are kept in the study's output folder (:data:`FILE`, the fit's
diagnostics in :data:`FIT_FILE`) and reused by a later comparison.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bayescal.atomic import atomic_write_json, read_json
from bayescal.calibration.cv import PeriodScores, paired_difference
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.pipeline.scores import Say, progress_bar, score_calibration, scores_key
from bayescal.pipeline.stages import Context, EmulatorResult, Options
from bayescal.report.trust import ABSORBS

__all__ = [
    "CATALOGUE",
    "DOES_NOT_IMPROVE",
    "FILE",
    "FIT_FILE",
    "Scored",
    "catalogue_labels",
    "catalogue_posterior",
    "catalogue_settings",
    "catalogue_warnings",
    "nominal_values",
    "score_catalogue",
]

#: The label of the catalogue row (of one per error model: ``catalogue (VARIANT)``).
CATALOGUE = "catalogue"
#: The catalogue model's scores, in the output folder of the study whose emulator it uses.
FILE = "leave-period-out-catalogue.npz"
#: The diagnostics of the catalogue model's chains, with the key of its scores.
FIT_FILE = "leave-period-out-catalogue.json"
#: What a catalogue row at least as good as the calibrated variants means.
DOES_NOT_IMPROVE = "calibration does not improve on the catalogue values on the left-out periods"


def nominal_values(ctx: Context, em: EmulatorResult) -> dict[str, float]:
    """Calibrated parameter -> its nominal (catalogue) value, in the emulator's order."""
    return {
        name: float(ctx.study.parameters[name].nominal) for name in em.assembled.parameter_names
    }


def catalogue_posterior(ctx: Context, em: EmulatorResult, label: str = CATALOGUE) -> Posterior:
    """The study's error model fitted with theta* held at the nominal values.

    The chains of ``[calibration]`` (number, burn-in, length, moves, longer
    while a diagnostic fails up to ``max_samples``), Metropolis-within-Gibbs
    whatever the study's sampler, seeded apart from the calibration's.
    """
    section = ctx.study.calibration
    total = section.chains * (section.burn + section.samples)
    tick, close = progress_bar(ctx.options, f"{label}: error model at the nominal values", total)
    try:
        return calibrate(
            em.emulator,
            em.assembled,
            n_chains=section.chains,
            n_burn=section.burn,
            n_draws=section.samples,
            seed=ctx.seed("catalogue"),
            backend=ctx.options.chains_backend,  # type: ignore[arg-type]
            algebra=ctx.study.emulator.algebra,
            sampler="mwg",
            callback=tick,
            observations=em.assembled.observations,
            moves=section.moves,
            max_draws=section.most_samples,
            held=nominal_values(ctx, em),
        )
    finally:
        close()


def _saved_warnings(ctx: Context, key: str) -> tuple[str, ...] | None:
    try:
        found = read_json(ctx.out / FIT_FILE)
    except (OSError, ValueError):
        return None
    if not isinstance(found, dict) or found.get("key") != key:
        return None
    return tuple(str(w) for w in found.get("warnings", []))


def score_catalogue(
    label: str,
    ctx: Context,
    em: EmulatorResult,
    options: Options,
    max_refits: int,
    draws_per_chain: int,
    say: Say,
    outputs: tuple[str, ...] | None = None,
) -> tuple[PeriodScores, tuple[str, ...]]:
    """The catalogue model's leave-one-period-out scores and its chains' diagnostic warnings.

    The fit runs only where the output folder does not hold its scores and
    diagnostics for the same key (the calibrate stage's key, the draws and
    ``"catalogue"``). ``outputs``: the calibrated outputs scored (``None``: all),
    as :func:`~bayescal.pipeline.scores.score_calibration`.
    """
    key = scores_key(ctx, em, draws_per_chain, CATALOGUE)
    warnings = _saved_warnings(ctx, key)

    def fit() -> Posterior:
        nonlocal warnings
        say(f"{label}: fitting the error model with every parameter at its nominal value")
        post = catalogue_posterior(ctx, em, label)
        warnings = post.warnings
        ctx.out.mkdir(parents=True, exist_ok=True)
        atomic_write_json(ctx.out / FIT_FILE, {"key": key, "warnings": list(warnings)})
        return post

    priors = em.assembled.priors
    nominal = nominal_values(ctx, em)
    held = np.array([float(priors[name].to_unit(value)) for name, value in nominal.items()])
    scores = score_calibration(
        label,
        ctx,
        em,
        fit() if warnings is None else fit,
        options,
        max_refits,
        draws_per_chain,
        say,
        file=FILE,
        what=(CATALOGUE,),
        held=held,
        outputs=outputs,
    )
    return scores, tuple(warnings or ())


def catalogue_labels(labels: Sequence[str], error_models: Sequence[str]) -> dict[int, str]:
    """Variant index -> the label of its catalogue row: the first variant of each
    distinct error model (``catalogue``, or ``catalogue (VARIANT)`` for several)."""
    first: dict[str, int] = {}
    for k, model in enumerate(error_models):
        first.setdefault(model, k)
    out = {}
    for k in first.values():
        name = CATALOGUE if len(first) == 1 else f"{CATALOGUE} ({labels[k]})"
        while name in labels:
            name += " (nominal)"
        out[k] = name
    return out


def catalogue_settings(
    ctx: Context, em: EmulatorResult, settings: dict[str, str]
) -> dict[str, str]:
    """The settings columns of a catalogue row: its source variant's, with theta* held."""
    values = " ".join(f"{n}={v:g}" for n, v in nominal_values(ctx, em).items())
    return {**settings, "parameters": f"nominal: {values}", "priors": "held at nominal"}


@dataclass(frozen=True)
class Scored:
    """What :func:`catalogue_warnings` needs of a row: its label, its per-period
    ELPD, its error model and, for a catalogue row, the variant it was built from."""

    label: str
    pointwise: np.ndarray
    error_model: str
    catalogue_of: str = ""


def catalogue_warnings(rows: Sequence[Scored]) -> tuple[list[str], list[str]]:
    """Loud warnings and plain notes: each catalogue row against the best calibrated
    variant with its error model (the paired ELPD difference and its SE).

    A warning where the catalogue ranks above that variant or less than one SE
    below it: the calibrated parameters do not predict a left-out period better
    than the catalogue values. Otherwise a note of the margin.
    """
    loud, notes = [], []
    for cat in (r for r in rows if r.catalogue_of):
        rivals = [r for r in rows if not r.catalogue_of and r.error_model == cat.error_model]
        if not rivals:
            continue
        best = max(rivals, key=lambda r: float(np.sum(r.pointwise)))
        diff, se = paired_difference(best.pointwise, cat.pointwise)
        margin = f"ELPD of {best.label} minus {cat.label}: {diff:+.1f} ± {se:.1f} nats"
        if diff <= se:
            loud.append(f"{DOES_NOT_IMPROVE}: {ABSORBS} ({margin}, error model {cat.error_model})")
        else:
            notes.append(
                f"{best.label} improves on the catalogue values on the left-out periods "
                f"({margin}, {diff / se:.1f} SE)"
                if se > 0
                else f"{best.label} improves on the catalogue values ({margin})"
            )
    return loud, notes
