"""``bayescal compare STUDY...``: rank variants of a study on its training periods alone.

Each study folder is one *variant* of the same calibration problem (another
parameter set, other priors, another error model, the in-likelihood
discrepancy on or off, another standardisation). :func:`compare`

1. checks that every variant predicts the same measurements: at least one
   calibrated output in common and, sample for sample, the same measured values
   of the shared outputs at the same instants in the same training periods (else
   it refuses in one line); variants that calibrate different outputs (the inside
   heat flux alone, or the flux and a temperature inside the wall) are scored on
   the outputs they all calibrate (:func:`scored_on`; ``on`` narrows them), each
   period left out whole;
2. runs each study up to its ``calibrate`` stage, or reuses the stages
   already in its output folder (:func:`bayescal.pipeline.run`);
3. scores every training period left out in turn
   (:mod:`bayescal.calibration.cv`: PSIS with Pareto-smoothed weights, in the
   measurements' own units; outputs with relative errors add the log-Jacobian
   of their log map, :func:`relative_jacobian`), and refits the calibration without the period
   for those whose Pareto ``k`` exceeds 0.7, worst first, at most
   ``max_refits`` per variant; the scores are kept in each study's output
   folder (:mod:`bayescal.store.crossval`) and reused by a later comparison;
4. ranks the variants by ELPD, with the difference to the best and its
   standard error from the paired periods, beside the left-out bands with
   their standard errors (the period as the unit), notes where a band misses
   its rate by more than two of them or a period is predicted confidently
   wrong or a variant's calibration failed its MCMC diagnostics (marked in
   every table, never ranked silently), and writes into ``output``:
   ``compare.csv`` (the ranking), ``compare-periods.csv`` (every period of
   every variant), ``compare.png`` (:func:`bayescal.report.compare.plot_comparison`)
   and ``compare.md`` (a summary page);
5. with ``held_out`` (the default), scores the held-out sensors every variant holds
   out (:mod:`bayescal.pipeline.heldscore`: each variant's simulator at posterior
   draws and the catalogue model's nominal run, with the sensors' stated accuracy,
   on the training periods) into ``compare-held-out.csv`` and the page, and says
   loudly where the catalogue values predict one as well as the calibration.

With ``catalogue`` (the default) the *catalogue model* is ranked beside them
(:mod:`bayescal.pipeline.catalogue`): every calibrated parameter at its nominal
value, the error model fitted on the same emulator, one row per distinct error
model; where it is at least as good as the best calibrated variant of its error
model (ahead, or less than one SE of the paired difference behind), the
comparison says loudly that calibration does not improve on the catalogue
values (``Comparison.warnings``, first in ``compare.md``). One study is then
enough to compare.

Only the training periods' measurements are read: the test window is left for
the final metrics of the variant chosen.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from bayescal.atomic import atomic_write_text
from bayescal.calibration.cv import CONFIDENTLY_WRONG, PeriodScores, paired_difference
from bayescal.config import Study, load_study
from bayescal.config.outputs import OutputError
from bayescal.errors import BayescalError, ConfigError
from bayescal.pipeline import catalogue as cat
from bayescal.pipeline import heldscore as ho
from bayescal.pipeline.budget import estimate_time, format_seconds
from bayescal.pipeline.run import Results, run
from bayescal.pipeline.scores import relative_jacobian, score_calibration
from bayescal.pipeline.stages import Context, Options, prepare
from bayescal.report.compare import comparison_markdown, plot_comparison

__all__ = [
    "DEFAULT_MAX_REFITS",
    "FILES",
    "Comparison",
    "Variant",
    "compare",
    "relative_jacobian",
    "same_training_data",
    "scored_on",
]

Say = Callable[[str], None]
#: Exact refits per variant when none is asked for: each costs about one calibration.
DEFAULT_MAX_REFITS = 5
#: What :func:`compare` writes into its output folder.
FILES = {
    "table": "compare.csv",
    "periods": "compare-periods.csv",
    "figure": "compare.png",
    "summary": "compare.md",
    "held_out": "compare-held-out.csv",
}


@dataclass(frozen=True)
class Variant:
    """One study of a comparison and its leave-one-period-out scores.

    Attributes
    ----------
    label
        The name it goes by in the tables (its folder's name, or its path).
    study
        The study.
    scores
        Its per-period scores (physical units).
    settings
        ``parameters``, ``priors``, ``error_model``, ``standardise``: what
        tells the variants apart, in words.
    diagnostics
        The MCMC diagnostics its calibration failed (R-hat, ESS, stuck chains,
        divergences; empty where every one passed): its scores rest on those
        chains, so the tables mark it.
    catalogue_of
        For the catalogue model's row, the variant whose error model it has.
    scored_on
        The calibrated outputs its scores are the density of (:func:`scored_on`).
    """

    label: str
    study: Study
    scores: PeriodScores
    settings: dict[str, str] = field(default_factory=dict)
    diagnostics: tuple[str, ...] = ()
    catalogue_of: str = ""
    scored_on: tuple[str, ...] = ()

    @property
    def model(self) -> str:
        """``"catalogue"`` (the nominal values, :mod:`bayescal.pipeline.catalogue`) or
        ``"calibrated"``."""
        return "catalogue" if self.catalogue_of else "calibrated"


@dataclass(frozen=True)
class Comparison:
    """The ranking (best first), the per-period table, notes, the files written and the
    loud warnings (a catalogue row at least as good as the calibrated variants)."""

    variants: tuple[Variant, ...]
    table: pd.DataFrame
    periods: pd.DataFrame
    notes: tuple[str, ...]
    files: dict[str, Path]
    warnings: tuple[str, ...] = ()
    held_out: pd.DataFrame = field(default_factory=pd.DataFrame)


def _labels(studies: Sequence[Study]) -> list[str]:
    names = [s.root.name for s in studies]
    if len(set(names)) == len(names):
        return names
    return [str(s.root) for s in studies]


def _settings(study: Study) -> dict[str, str]:
    priors: list[str] = []
    for name, p in study.parameters.items():
        prior = p.prior
        if prior.distribution != "uniform":
            priors.append(f"{name} {prior.distribution}({prior.a:g}, {prior.b:g})")
    errors: list[str] = []
    for name in study.outputs.calibrate:
        spec = study.outputs.errors.get(name, OutputError())
        text = f"{name} {spec.model}"
        if spec.discrepancy:
            kind = spec.discrepancy
            text += "+discrepancy" + ("" if kind in (True, "conditions") else f" ({kind})")
        if spec.relative:
            text += " relative"
        if spec.sd is not None:
            text += f" sd {spec.sd}"
        errors.append(text)
    return {
        "parameters": " ".join(study.parameters),
        "priors": "; ".join(priors) or "uniform",
        "error_model": "; ".join(errors),
        "standardise": study.emulator.standardise,
    }


def _when(times: np.ndarray, index: int) -> str:
    return str(np.datetime_as_string(times[index], unit="m")).replace("T", " ")


def same_training_data(
    a: tuple[str, Context],
    b: tuple[str, Context],
    outputs: Sequence[str] | None = None,
    held_out: Sequence[str] = (),
) -> None:
    """Refuse in one line unless ``b`` predicts exactly the training measurements of ``a``
    (of the calibrated outputs they share, among ``outputs`` where given: those scored;
    and of the held-out sensors ``held_out`` both hold out, :mod:`bayescal.pipeline.heldscore`).

    Raises
    ------
    ConfigError
        Naming the first difference: no calibrated output in common, number or
        length of the training periods, their instants, or a measured value of
        a shared output.
    """
    (la, ca), (lb, cb) = a, b
    why = _first_difference(la, ca, lb, cb, outputs, held_out)
    if why is not None:
        raise ConfigError(
            f"cannot compare {la} and {lb}: {why}",
            hint="the variants of a comparison need the same data file, columns and training "
            "periods, and at least one calibrated output in common"
            + ("; or leave the held-out sensors out with --no-held-out" if held_out else ""),
        )


def _first_difference(
    la: str,
    ca: Context,
    lb: str,
    cb: Context,
    outputs: Sequence[str] | None = None,
    held_out: Sequence[str] = (),
) -> str | None:
    oa, ob = ca.study.outputs.calibrate, cb.study.outputs.calibrate
    shared = [name for name in oa if name in ob and (outputs is None or name in outputs)]
    if not shared:
        return f"{la} calibrates {list(oa)}, {lb} {list(ob)}: no output in common to score"
    ya, yb = ca.measured.layout, cb.measured.layout
    if (ya.m_star, ya.period) != (yb.m_star, yb.period):
        return (
            f"{la} has {ya.m_star} training periods of {ya.period} samples, "
            f"{lb} {yb.m_star} of {yb.period}"
        )
    idx_a = (ya.train_starts[:, None] + np.arange(ya.period)).ravel()
    idx_b = (yb.train_starts[:, None] + np.arange(yb.period)).ravel()
    ta, tb = ca.measured.times[idx_a], cb.measured.times[idx_b]
    if not np.array_equal(ta, tb):
        k = int(np.flatnonzero(ta != tb)[0])
        return (
            f"their training periods differ in time ({_when(ta, k)} UTC in {la}, "
            f"{_when(tb, k)} UTC in {lb})"
        )
    series = [(f"the measured {n}", ca.measured.outputs[n], cb.measured.outputs[n]) for n in shared]
    series += [
        (f"the held-out sensor {n}", ca.measured.held_out[n], cb.measured.held_out[n])
        for n in held_out
    ]
    for what, a, b in series:
        va = np.asarray(a, dtype=float)[idx_a]
        vb = np.asarray(b, dtype=float)[idx_b]
        same = (va == vb) | (np.isnan(va) & np.isnan(vb))
        if not np.all(same):
            k = int(np.flatnonzero(~same)[0])
            return (
                f"{what} differs in the training periods (first at "
                f"{_when(ta, k)} UTC: {va[k]:.6g} in {la}, {vb[k]:.6g} in {lb})"
            )
    return None


def scored_on(
    labels: Sequence[str], studies: Sequence[Study], on: Sequence[str] = ()
) -> tuple[tuple[str, ...], list[str]]:
    """The calibrated outputs every variant is scored on, and a note where that is not
    every output of every variant.

    The outputs all the variants calibrate (in the first variant's order), or
    those of them named in ``on``. A variant that calibrates more outputs is
    scored on these alone: each training period is left out whole (every output's
    samples), and the score is the density of the shared outputs' samples under
    the calibration on the other periods, so what the other outputs teach the
    calibration counts, and their own fit does not.

    Raises
    ------
    ConfigError
        No output calibrated by every variant, or an output of ``on`` that is not.
    """
    sets = [tuple(s.outputs.calibrate) for s in studies]
    shared = tuple(n for n in sets[0] if all(n in other for other in sets))
    if not shared:
        listed = "; ".join(f"{a} {list(b)}" for a, b in zip(labels, sets, strict=True))
        raise ConfigError(
            f"cannot compare: no output is calibrated by every variant, no output in common "
            f"to score ({listed})",
            hint="the variants of a comparison need at least one calibrated output in common",
        )
    if on:
        missing = [n for n in on if n not in shared]
        if missing:
            raise ConfigError(
                f"cannot score on {', '.join(missing)}: the outputs every variant calibrates "
                f"are {', '.join(shared)}",
                hint="--on takes outputs that every study's [outputs] calibrate lists",
            )
        shared = tuple(n for n in shared if n in on)
    if all(set(outs) == set(shared) for outs in sets):
        return shared, []
    more = [
        f"{label} also {', '.join(n for n in outs if n not in shared)}"
        for label, outs in zip(labels, sets, strict=True)
        if set(outs) != set(shared)
    ]
    return shared, [
        f"scored on {', '.join(shared)} alone ({'; '.join(more)}): each training period is "
        "left out whole and only these outputs' samples are scored, so the other outputs "
        "count through what they teach the calibration, not through their own fit"
    ]


def _calibrated(label: str, study: Study, options: Options, say: Say) -> Results:
    try:
        res = run(study, until="calibrate", options=options, say=lambda t: say(f"{label}: {t}"))
    except BayescalError as exc:
        raise type(exc)(f"{label}: running up to calibrate failed: {exc.one_line()}") from None
    return res


def _score(
    label: str,
    res: Results,
    options: Options,
    max_refits: int,
    draws_per_chain: int,
    say: Say,
    outputs: tuple[str, ...],
) -> PeriodScores:
    em, post = res.emulator, res.posterior
    if em is None or post is None:  # pragma: no cover - run(until="calibrate") gives both
        raise ConfigError(f"{label}: the calibrate stage did not finish")
    return score_calibration(
        label, res.context, em, post, options, max_refits, draws_per_chain, say, outputs=outputs
    )


def _tables(variants: Sequence[Variant], times: list[str]) -> tuple[pd.DataFrame, pd.DataFrame]:
    ranked = sorted(variants, key=lambda v: -v.scores.elpd)
    best = ranked[0].scores.pointwise
    rows = []
    for rank, v in enumerate(ranked, start=1):
        s = v.scores
        diff, se_diff = paired_difference(best, s.pointwise)
        rows.append(
            {
                "rank": rank,
                "variant": v.label,
                "model": v.model,
                "elpd": s.elpd,
                "se": s.se,
                "elpd_diff": diff,
                "se_diff": se_diff,
                "p_loo": s.p_loo,
                "periods": s.n_periods,
                "k_high": int(np.sum(s.high_k)),
                "refits": int(np.sum(s.refitted)),
                "psis_only": int(np.sum(s.psis_only)),
                "loo_band95": s.band_coverage(0.95),
                "loo_band95_se": s.band_coverage_se(0.95),
                "loo_band50": s.band_coverage(0.50),
                "loo_band50_se": s.band_coverage_se(0.50),
                "loo_band95_worst": _worst(s.band_shares(0.95)),
                "scored_on": " ".join(v.scored_on),
                "diagnostics": "failed" if v.diagnostics else "passed",
                "diagnostic_warnings": len(v.diagnostics),
                **v.settings,
                "catalogue_of": v.catalogue_of,
                "study": str(v.study.path),
            }
        )
    period_rows = [
        {
            "variant": v.label,
            "period": i,
            "start": times[i],
            "elpd_i": float(v.scores.pointwise[i]),
            "psis": float(v.scores.psis[i]),
            "refit": float(v.scores.refit[i]),
            "pareto_k": float(v.scores.pareto_k[i]),
            "lppd_i": float(v.scores.lppd[i]),
            "method": "refit" if v.scores.refitted[i] else "psis",
            "band95_i": _share(v.scores, 0.95, i),
            "band50_i": _share(v.scores, 0.50, i),
        }
        for v in ranked
        for i in range(v.scores.n_periods)
    ]
    return pd.DataFrame(rows), pd.DataFrame(period_rows)


def _share(scores: PeriodScores, level: float, period: int) -> float:
    shares = scores.band_shares(level)
    return float(shares[period]) if shares.size else math.nan


def _worst(shares: np.ndarray) -> float:
    return float(np.min(shares)) if shares.size else math.nan


def _band_notes(label: str, s: PeriodScores) -> list[str]:
    """What the left-out bands say beside the ELPD: a band off its rate by more than
    BAND_CHECK_Z standard errors, and the periods predicted confidently wrong."""
    notes = []
    for level in (0.95, 0.5):
        check = s.band_check(level)
        if check in ("too wide", "too narrow"):
            cov, se = s.band_coverage(level), s.band_coverage_se(level)
            what = (
                "wider than its rate: the bands of new periods would be conservative"
                if check == "too wide"
                else "narrower than its rate: the bands of new periods would be overconfident"
            )
            off = f"{abs(cov - level) / se:.1f} SE" if se > 1e-12 else "the same in every period"
            notes.append(
                f"{label}: left-out {level * 100:g} % band {cov:.3f} ± {se:.3f}, {what} "
                f"({off} from {level:g})"
            )
    shares = s.band_shares(0.95)
    wrong = np.flatnonzero(shares < CONFIDENTLY_WRONG)
    if wrong.size:
        cases = ", ".join(f"{i} ({shares[i]:.0%})" for i in wrong)
        notes.append(
            f"{label}: the left-out 95 % band held less than half of the samples of "
            f"period(s) {cases}: confidently wrong there"
        )
    return notes


def _diagnostics_note(v: Variant) -> list[str]:
    """One loud line for a variant whose calibration failed its MCMC diagnostics."""
    if not v.diagnostics:
        return []
    more = f" and {len(v.diagnostics) - 1} more" if len(v.diagnostics) > 1 else ""
    return [
        f"{v.label}: its calibration FAILED its MCMC diagnostics ({v.diagnostics[0]}{more}): "
        "its scores and rank rest on chains that have not converged; run longer chains "
        "([calibration] burn, samples, max_samples) before choosing it"
    ]


def _notes(variants: Sequence[Variant], max_refits: int) -> list[str]:
    notes = []
    for v in variants:
        s = v.scores
        notes += _diagnostics_note(v)
        notes += _band_notes(v.label, s)
        shaky = np.flatnonzero(s.psis_only)
        if s.refitted.any():
            done = ", ".join(str(i) for i in np.flatnonzero(s.refitted))
            notes.append(f"{v.label}: exact refits without period(s) {done}")
        if shaky.size:
            notes.append(
                f"{v.label}: {shaky.size} period(s) ({', '.join(map(str, shaky))}) have Pareto "
                f"k > 0.7 and no refit (--max-refits {max_refits} reached): their PSIS "
                "estimates are unreliable"
            )
        notes += [f"{v.label}: {w}" for w in s.refit_warnings]
    return notes


def compare(
    paths: Sequence[str | Path],
    *,
    output: str | Path = "compare",
    options: Options | None = None,
    max_refits: int = DEFAULT_MAX_REFITS,
    draws_per_chain: int = 250,
    say: Say | None = None,
    catalogue: bool = True,
    on: Sequence[str] = (),
    held_out: bool = True,
) -> Comparison:
    """Rank the variants ``paths`` by leave-one-period-out ELPD and write the comparison.

    Parameters
    ----------
    paths
        Study files or folders, two or more (one is enough with ``catalogue``:
        the study against its catalogue model).
    output
        Folder for ``compare.csv``, ``compare-periods.csv``, ``compare.png``
        and ``compare.md`` (created if missing).
    options
        Backends and progress bars (as :func:`bayescal.pipeline.run`); the
        refits' chains run on ``options.chains_backend``.
    max_refits
        Exact refits per variant at most (periods with Pareto ``k`` > 0.7,
        worst first).
    draws_per_chain
        Posterior draws per chain the scores use (thinned evenly).
    say
        Receives one-line progress notes.
    catalogue
        Also rank the catalogue model (every parameter at its nominal value, the
        error model fitted; :mod:`bayescal.pipeline.catalogue`), one row per
        distinct error model among the variants, and say loudly
        (``Comparison.warnings``) where it is at least as good as the best
        calibrated variant of its error model.
    on
        Score only these calibrated outputs (each calibrated by every variant);
        empty: the outputs every variant calibrates (:func:`scored_on`).
        Variants that calibrate different outputs are compared on those they share.
    held_out
        Also score the held-out sensors every variant holds out, on the training
        periods (:mod:`bayescal.pipeline.heldscore`; ``[predict] runs`` simulator runs
        at posterior draws per variant, through the run cache).

    Raises
    ------
    ConfigError
        Fewer than two studies (none with ``catalogue``), the same study twice,
        a study not found, variants that do not share their training
        measurements or no calibrated output, or an output of ``on`` that is not
        calibrated by every variant.
    BayescalError
        A study's stages up to ``calibrate`` failed (its label first).
    """
    note = say or (lambda _: None)
    opts = options or Options()
    if len(paths) < (1 if catalogue else 2):
        least = "one study" if catalogue else "two studies"
        raise ConfigError(
            f"compare needs at least {least} to rank, got {len(paths)}",
            hint="give the study folders of the variants: bayescal compare A B ... "
            "(one study is ranked against its catalogue model unless --no-catalogue)",
        )
    if max_refits < 0 or draws_per_chain < 1:
        raise ConfigError("max_refits must be >= 0 and draws_per_chain >= 1")
    studies = [load_study(p) for p in paths]
    twice = [str(p) for p, n in Counter(s.path.resolve() for s in studies).items() if n > 1]
    if twice:
        raise ConfigError(f"the study {twice[0]} is given more than once")
    folder = Path(output)
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{folder} exists and is not a folder", hint="give --output a folder")
    labels = _labels(studies)
    contexts = [(label, prepare(s, opts)) for label, s in zip(labels, studies, strict=True)]
    shared, on_notes = scored_on(labels, studies, on)
    sensors, held_notes = ho.shared_held_out(labels, studies) if held_out else ((), [])
    for other in contexts[1:]:
        same_training_data(contexts[0], other, shared, sensors)
    on_notes += held_notes
    for line in on_notes:
        note(line)
    sources = cat.catalogue_labels(labels, [_settings(s)["error_model"] for s in studies])
    if not catalogue:
        sources = {}
    note(_cost(contexts, max_refits, sources))
    if sensors:
        note(
            f"held-out sensors {', '.join(sensors)}: the simulator at up to "
            f"{max(c.study.predict.runs for _, c in contexts)} posterior draws per variant "
            "(from the run cache where the predict stage has run) and the nominal run"
        )
    variants = []
    held: list[tuple[str, str, bool, dict[str, ho.HeldOutScore]]] = []
    for k, (label, study) in enumerate(zip(labels, studies, strict=True), start=1):
        note(f"variant {k} of {len(studies)}: {label}")
        res = _calibrated(label, study, opts, note)
        scores = _score(label, res, opts, max_refits, draws_per_chain, note, shared)
        note(
            f"{label}: ELPD {scores.elpd:.1f} ± {scores.se:.1f} over {scores.n_periods} periods "
            f"({int(np.sum(scores.high_k))} with Pareto k > 0.7, {int(np.sum(scores.refitted))} "
            "refitted)"
        )
        failed = res.posterior.warnings if res.posterior is not None else ()
        variants.append(
            Variant(label, study, scores, _settings(study), tuple(failed), scored_on=shared)
        )
        if sensors and res.posterior is not None:
            note(f"{label}: predicting the held-out sensors at posterior draws")
            held += _held_out(label, res, sensors, bool(failed), sources.get(k - 1), held)
        if k - 1 in sources:
            variants.append(
                _catalogue(
                    sources[k - 1],
                    variants[-1],
                    res,
                    (opts, max_refits, draws_per_chain),
                    note,
                    shared,
                )
            )
    first = contexts[0][1].measured
    times = [_when(first.times, int(s)) for s in first.layout.train_starts]
    table, periods = _tables(variants, times)
    loud, margins = cat.catalogue_warnings(
        [
            cat.Scored(v.label, v.scores.pointwise, v.settings["error_model"], v.catalogue_of)
            for v in variants
        ]
    )
    notes = on_notes + margins + _notes(variants, max_refits)
    loud += ho.held_out_warnings(held)
    held_table = ho.held_out_table(held)
    pits = {v.label: v.scores.pit for v in variants}
    files = _write(folder, table, periods, notes, pits, loud, held_table)
    order = {label: k for k, label in enumerate(table["variant"])}
    ranked = tuple(sorted(variants, key=lambda v: order[v.label]))
    return Comparison(ranked, table, periods, tuple(notes), files, tuple(loud), held_table)


def _held_out(
    label: str,
    res: Results,
    sensors: Sequence[str],
    failed: bool,
    catalogue: str | None,
    done: Sequence[tuple[str, str, bool, dict[str, ho.HeldOutScore]]],
) -> list[tuple[str, str, bool, dict[str, ho.HeldOutScore]]]:
    """The variant's held-out scores, and its catalogue row's nominal run where it has one
    and no catalogue row is scored yet (one nominal run, with the stated accuracy, does
    not depend on the error model: the first variant's nominal values stand for the
    catalogue); a simulator failure names the variant."""
    assert res.posterior is not None  # the caller checks
    try:
        rows = [
            (label, "calibrated", failed, ho.variant_held_out(res.context, res.posterior, sensors))
        ]
        if catalogue is not None and not any(model == "catalogue" for _, model, _, _ in done):
            rows.append(
                (catalogue, "catalogue", False, ho.catalogue_held_out(res.context, sensors))
            )
    except BayescalError as exc:
        raise type(exc)(
            f"{label}: predicting the held-out sensors failed: {exc.one_line()}"
        ) from None
    return rows


def _catalogue(
    label: str,
    source: Variant,
    res: Results,
    scoring: tuple[Options, int, int],
    say: Say,
    outputs: tuple[str, ...],
) -> Variant:
    """The catalogue row of ``source``'s error model, on its emulator (``scoring``:
    options, most refits, draws per chain)."""
    if res.emulator is None:  # pragma: no cover - run(until="calibrate") gives it
        raise ConfigError(f"{source.label}: the emulator stage did not finish")
    ctx, em = res.context, res.emulator
    options, max_refits, draws_per_chain = scoring
    say(f"{label}: the nominal values with the error model of {source.label}")
    scores, failed = cat.score_catalogue(
        label, ctx, em, options, max_refits, draws_per_chain, say, outputs
    )
    say(
        f"{label}: ELPD {scores.elpd:.1f} ± {scores.se:.1f} over {scores.n_periods} periods "
        f"({int(np.sum(scores.high_k))} with Pareto k > 0.7, {int(np.sum(scores.refitted))} "
        "refitted)"
    )
    settings = cat.catalogue_settings(ctx, em, source.settings)
    return Variant(
        label,
        source.study,
        scores,
        settings,
        failed,
        catalogue_of=source.label,
        scored_on=outputs,
    )


def _cost(
    contexts: Sequence[tuple[str, Context]], max_refits: int, catalogues: Collection[int] = ()
) -> str:
    """What the comparison may cost, from each variant's sizes (:func:`estimate_time`):
    its emulator and calibration where its output folder does not hold them yet, and
    up to ``max_refits`` refits, each about one calibration; a catalogue model on the
    emulator of the variants ``catalogues`` costs about one calibration and its refits."""
    total = 0.0
    parts = []
    for k, (label, ctx) in enumerate(contexts):
        estimate = estimate_time(ctx.study, ctx.measured)
        stages = {part.what: part.seconds for part in estimate.parts}
        calibration = stages.get("calibration", 0.0)
        first = stages.get("emulator", 0.0) + calibration
        total += first + max_refits * calibration
        if k in catalogues:
            total += (1 + max_refits) * calibration
        parts.append(
            f"{label} {format_seconds(first)} + up to {max_refits} refits of "
            f"{format_seconds(calibration)}"
        )
    extra = (
        f" and {len(catalogues)} catalogue model(s) (the error model at the nominal values: "
        "about one calibration each, and its refits)"
        if catalogues
        else ""
    )
    return (
        f"compare: {len(contexts)} variants{extra}, up to about {format_seconds(total)} of MCMC "
        f"and emulator training besides the simulator runs ({'; '.join(parts)}; stages "
        "already in a study's output folder are reused, refits only where a period's "
        "Pareto k exceeds 0.7): an order of magnitude from the studies' sizes"
    )


def _write(
    folder: Path,
    table: pd.DataFrame,
    periods: pd.DataFrame,
    notes: list[str],
    pits: dict[str, np.ndarray],
    warnings: list[str] | None = None,
    held_out: pd.DataFrame | None = None,
) -> dict[str, Path]:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        files = {
            "table": atomic_write_text(folder / FILES["table"], table.to_csv(index=False)),
            "periods": atomic_write_text(folder / FILES["periods"], periods.to_csv(index=False)),
            "figure": plot_comparison(folder / FILES["figure"], table, periods, pits),
        }
        if held_out is not None and len(held_out):
            path = folder / FILES["held_out"]
            files["held_out"] = atomic_write_text(path, held_out.to_csv(index=False))
        text = comparison_markdown(table, periods, notes, FILES["figure"], warnings or [], held_out)
        files["summary"] = atomic_write_text(folder / FILES["summary"], text)
    except OSError as exc:
        raise ConfigError(f"cannot write into {folder}: {exc.strerror or exc}") from None
    return files
