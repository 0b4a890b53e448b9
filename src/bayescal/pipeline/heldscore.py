"""Held-out sensors in ``bayescal compare``: each variant's prediction of a sensor it never read.

A held-out sensor (``[outputs] held_out``) is predicted, never calibrated on: the
simulator at posterior draws plus the sensor's stated accuracy
(``[outputs.errors.NAME] sd``, :func:`bayescal.pipeline.stages.held_out_sd`), as the
study's own band of it (:func:`bayescal.pipeline.predict.held_out_band`). Every window of
it is out of sample, so :func:`bayescal.pipeline.compare.compare` scores it on the
training periods (the test window stays unread) for every variant that holds it out:

* per period ``i`` the log predictive density of its samples,
  ``log (1/S) sum_s prod_t N(y_t | f_s(t), sd^2)`` over the ``S`` draws' runs
  (:func:`score_held_out`), summed over the periods; variants are paired period by
  period (:func:`bayescal.calibration.cv.paired_difference`), as the left-out scores
  are;
* the RMSE of the mean prediction, and the share of the samples inside the central
  95 % and 50 % of the draws' mixture (its PIT), with their standard errors over the
  periods;
* the catalogue model (every parameter at its nominal value) is one draw, the nominal
  run, with the same stated accuracy.

The score uses the stated accuracy, not a fitted one, so it ranks how close each
variant's simulator runs lie to the sensor, in the sensor's units; where the catalogue
values predict a held-out sensor as well as the best calibrated variant or better
(ahead, or less than one SE of the paired difference behind), or a calibrated variant's
mean lies further off (RMSE above 105 % of the catalogue's, the rule of ``show``'s
verdict), :func:`held_out_warnings` says loudly that the parameters absorb model error.
The two can disagree: a posterior whose draws spread widely can cover a bias with its
spread and score a higher density than the catalogue's single run, its mean further off.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import special, stats

from bayescal.calibration.cv import paired_difference
from bayescal.calibration.posterior import Posterior
from bayescal.config import Study
from bayescal.periods import PeriodLayout
from bayescal.pipeline.stages import Context, held_out_sd, nominal_run, posterior_runs
from bayescal.report.trust import ABSORBS, NO_BETTER

__all__ = [
    "HeldOutScore",
    "catalogue_held_out",
    "held_out_table",
    "held_out_warnings",
    "score_held_out",
    "shared_held_out",
    "variant_held_out",
]


@dataclass(frozen=True)
class HeldOutScore:
    """One variant's prediction of one held-out sensor over the training periods.

    Attributes
    ----------
    pointwise
        Log predictive density of each period's samples, ``(m*,)``. [nats]
    rmse
        RMSE of the mean prediction over the periods' samples. [the sensor's unit]
    inside95, inside50
        Share of each period's samples inside the central 95 % / 50 % of the
        prediction, ``(m*,)``.
    draws
        Simulator runs the prediction is made of (1 for the catalogue model).
    sd
        The sensor's stated accuracy used. [the sensor's unit]
    """

    pointwise: np.ndarray
    rmse: float
    inside95: np.ndarray
    inside50: np.ndarray
    draws: int
    sd: float

    @property
    def lpd(self) -> float:
        """The log predictive density of every period's samples. [nats]"""
        return float(np.sum(self.pointwise))

    @property
    def se(self) -> float:
        """Its standard error from the periods: ``sqrt(m* var(pointwise))``."""
        return math.sqrt(self.pointwise.size * float(np.var(self.pointwise)))

    def band(self, level: float) -> tuple[float, float]:
        """Mean share of the samples inside the central ``level`` band (0.95 or 0.5) and
        its standard error over the periods."""
        shares = self.inside95 if level == 0.95 else self.inside50
        ok = shares[np.isfinite(shares)]
        if ok.size == 0:
            return math.nan, math.nan
        return float(np.mean(ok)), float(np.std(ok) / math.sqrt(ok.size))


def score_held_out(
    layout: PeriodLayout, measured: np.ndarray, runs: np.ndarray, sd: float
) -> HeldOutScore:
    """Score the runs ``(S, n_total)`` of a held-out sensor against its measurements
    ``(n_total,)`` on the training periods of ``layout``, with noise SD ``sd``.

    Missing measurements (NaN) are left out; a period without any scores 0 and no
    band share (NaN).
    """
    runs = np.atleast_2d(np.asarray(runs, dtype=float))
    y = np.asarray(measured, dtype=float)
    m = layout.m_star
    pointwise, in95, in50 = np.zeros(m), np.full(m, np.nan), np.full(m, np.nan)
    errors: list[np.ndarray] = []
    for i, start in enumerate(layout.train_starts):
        idx = np.arange(start, start + layout.period)
        yi, fi = y[idx], runs[:, idx]
        ok = np.isfinite(yi)
        if not ok.any():
            continue
        yi, fi = yi[ok], fi[:, ok]
        per_draw = np.sum(stats.norm.logpdf(yi[None], fi, sd), axis=1)
        pointwise[i] = float(special.logsumexp(per_draw) - math.log(per_draw.size))
        pit = stats.norm.cdf((yi[None] - fi) / sd).mean(axis=0)
        in95[i] = float(np.mean((pit >= 0.025) & (pit <= 0.975)))
        in50[i] = float(np.mean((pit >= 0.25) & (pit <= 0.75)))
        errors.append(yi - fi.mean(axis=0))
    flat = np.concatenate(errors) if errors else np.array([np.nan])
    rmse = float(np.sqrt(np.mean(flat**2)))
    return HeldOutScore(pointwise, rmse, in95, in50, int(runs.shape[0]), float(sd))


def shared_held_out(
    labels: Sequence[str], studies: Sequence[Study]
) -> tuple[tuple[str, ...], list[str]]:
    """The held-out sensors every variant holds out (in the first variant's order), and a
    note naming those only some hold out (a sensor one variant calibrates on is in sample
    there: not a fair test of the others)."""
    sets = [tuple(s.outputs.held_out) for s in studies]
    shared = tuple(n for n in sets[0] if all(n in other for other in sets))
    partial = sorted({n for outs in sets for n in outs} - set(shared))
    notes = []
    if partial:
        holders = {
            n: [label for label, outs in zip(labels, sets, strict=True) if n in outs]
            for n in partial
        }
        listed = "; ".join(f"{n} by {', '.join(who)}" for n, who in holders.items())
        notes.append(
            f"held-out sensors not scored, since not every variant holds them out ({listed}): "
            "a sensor one variant calibrates on is no test of it"
        )
    return shared, notes


def variant_held_out(
    ctx: Context, posterior: Posterior, names: Sequence[str]
) -> dict[str, HeldOutScore]:
    """A calibrated variant's scores: the simulator at ``[predict] runs`` posterior draws
    (thinned evenly, through the run cache: the predict stage's own runs where it has
    run), the sensors' stated accuracy."""
    if not names:
        return {}
    runs, _, _ = posterior_runs(ctx, posterior, ctx.study.predict.runs)
    layout = ctx.measured.layout
    return {
        n: score_held_out(layout, ctx.measured.held_out[n], runs[n], held_out_sd(ctx, n))
        for n in names
    }


def catalogue_held_out(ctx: Context, names: Sequence[str]) -> dict[str, HeldOutScore]:
    """The catalogue model's scores: one draw, the nominal run, the stated accuracy."""
    if not names:
        return {}
    nominal = nominal_run(ctx)
    layout = ctx.measured.layout
    return {
        n: score_held_out(layout, ctx.measured.held_out[n], nominal[n], held_out_sd(ctx, n))
        for n in names
    }


def held_out_table(
    scored: Sequence[tuple[str, str, bool, Mapping[str, HeldOutScore]]],
) -> pd.DataFrame:
    """One row per held-out sensor and variant, best first within each sensor.

    ``scored``: (label, model ``"calibrated"``/``"catalogue"``, whether its MCMC
    diagnostics failed, its scores per sensor).
    """
    rows = []
    names = list(dict.fromkeys(n for _, _, _, s in scored for n in s))
    for name in names:
        entries = [(label, model, failed, s[name]) for label, model, failed, s in scored]
        entries.sort(key=lambda e: -e[3].lpd)
        best = entries[0][3].pointwise
        for rank, (label, model, failed, score) in enumerate(entries, start=1):
            diff, se_diff = paired_difference(best, score.pointwise)
            b95, b95_se = score.band(0.95)
            b50, b50_se = score.band(0.5)
            rows.append(
                {
                    "output": name,
                    "rank": rank,
                    "variant": label,
                    "model": model,
                    "lpd": score.lpd,
                    "se": score.se,
                    "lpd_diff": diff,
                    "se_diff": se_diff,
                    "rmse": score.rmse,
                    "band95": b95,
                    "band95_se": b95_se,
                    "band50": b50,
                    "band50_se": b50_se,
                    "draws": score.draws,
                    "sd": score.sd,
                    # the catalogue's prediction is the nominal run: no chains to check
                    "diagnostics": "none" if model == "catalogue" else _passed(failed),
                }
            )
    columns = ["output", "rank", "variant", "model", "lpd", "se", "lpd_diff", "se_diff"]
    columns += ["rmse", "band95", "band95_se", "band50", "band50_se", "draws", "sd"]
    return pd.DataFrame(rows, columns=[*columns, "diagnostics"])


def _passed(failed: bool) -> str:
    return "failed" if failed else "passed"


def held_out_warnings(
    scored: Sequence[tuple[str, str, bool, Mapping[str, HeldOutScore]]],
) -> list[str]:
    """Loud lines where the catalogue model predicts a held-out sensor as well as the
    calibration, by either measure:

    * its log density at least that of the best calibrated variant (ahead, or less than
      one SE of the paired difference behind);
    * its RMSE below a calibrated variant's by more than :data:`NO_BETTER` (the calibrated
      RMSE above 105 % of the catalogue's: the rule of ``show``'s out-of-sample verdict,
      :mod:`bayescal.report.trust`). A posterior whose draws spread widely can score a
      higher density than the catalogue's single run while its mean lies further off.
    """
    out: list[str] = []
    calibrated = [(label, s) for label, model, _, s in scored if model == "calibrated"]
    catalogue = [(label, s) for label, model, _, s in scored if model == "catalogue"]
    if not calibrated or not catalogue:
        return out
    for name in calibrated[0][1]:
        best_label, best = max(calibrated, key=lambda e: e[1][name].lpd)
        for label, s in catalogue:
            diff, se = paired_difference(best[name].pointwise, s[name].pointwise)
            if diff < se:
                where = "ahead of" if diff < 0 else "less than one SE behind"
                out.append(
                    f"on the held-out sensor {name} (never calibrated on), the catalogue "
                    f"values ({label}) predict the training days {where} the best calibrated "
                    f"variant {best_label} ({-diff:+.1f} ± {se:.1f} nats): {ABSORBS}"
                )
            cat_rmse = s[name].rmse
            if not cat_rmse > 0.0:  # the nominal run on the measurements: no ratio to take
                continue
            worse = [
                f"{v} {sv[name].rmse:.3g} ({100.0 * (sv[name].rmse / cat_rmse - 1.0):+.0f} %)"
                for v, sv in calibrated
                if sv[name].rmse > (1.0 + NO_BETTER) * cat_rmse
            ]
            if worse:
                out.append(
                    f"on the held-out sensor {name} (never calibrated on), the calibrated "
                    f"prediction is further off than the catalogue values' ({label}) on the "
                    f"training days: RMSE {', '.join(worse)} against {cat_rmse:.3g}: {ABSORBS}"
                )
    return out
