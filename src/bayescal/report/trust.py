"""Whether a calibration helped: the first screen of ``bayescal show`` and of the report.

Two checks, each a pure function of results already computed:

* :func:`catalogue_verdicts` -- does the calibrated prediction beat the nominal
  (catalogue) one **out of sample**? For a calibrated output, on the test window;
  for a held-out sensor (not read by the calibration), over its whole record
  (training periods and test window pooled: every sample is out of sample for
  it). The RMSEs of ``metrics.csv`` are compared: calibrated at most 95 % of
  the nominal is *better*, more than 105 % is *worse*, in between *no better*
  (:data:`NO_BETTER`). Worse is a warning: the parameters absorb model error.
* :func:`bayescal.calibration.bounds.bound_leans` -- a parameter whose posterior
  piles against a bound of its prior.
* :mod:`bayescal.calibration.modelerror` -- an in-likelihood discrepancy that
  the data show for certain (its SD's 95 % interval above a quarter of the noise
  SD): the model misses part of what was measured (:data:`MISSES`).

:func:`trust_warnings` gathers both into the sentences shown before anything else.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd

from bayescal.calibration.bounds import bound_warnings
from bayescal.calibration.modelerror import ModelErrorSize
from bayescal.calibration.posterior import Posterior
from bayescal.design import PosteriorPrior

__all__ = [
    "ABSORBS",
    "CONFLICT",
    "MISSES",
    "NO_BETTER",
    "CatalogueVerdict",
    "catalogue_verdicts",
    "held_out_outputs",
    "prior_conflicts",
    "trust_warnings",
]

#: Relative RMSE difference within which the calibrated prediction is "no better". [-]
NO_BETTER = 0.05
#: What a calibrated prediction worse than the catalogue's means.
ABSORBS = "the parameters absorb model error; treat them as fitting constants, not properties"

#: What a discrepancy the data show for certain means for the parameters.
MISSES = (
    "the model misses part of what was measured; the parameters may have absorbed some of "
    "it, and the physics behind the rest is in no parameter: quantities derived from them "
    "(a U-value, a heat capacity) describe the model, not the building. Check them with a "
    "sensor the calibration did not read, or a model with the missing physics"
)

Verdict = Literal["better", "no better", "worse", "unknown"]


@dataclass(frozen=True)
class CatalogueVerdict:
    """The calibrated prediction of one output against the nominal one, out of sample.

    Attributes
    ----------
    output
        The output (a measured column).
    held_out
        Whether the calibration did not read it (a held-out sensor).
    nominal, calibrated
        RMSE of the nominal and of the calibrated prediction on the samples
        compared, in the output's unit (NaN where there are none).
    """

    output: str
    held_out: bool
    nominal: float
    calibrated: float

    @property
    def where(self) -> str:
        """``"test window"`` or ``"held-out sensor, whole record"``."""
        return "held-out sensor, whole record" if self.held_out else "test window"

    @property
    def verdict(self) -> Verdict:
        """``better`` (RMSE at most 95 % of the nominal), ``worse`` (above 105 %),
        ``no better`` (in between), ``unknown`` (nothing to compare)."""
        if not (np.isfinite(self.nominal) and np.isfinite(self.calibrated)) or self.nominal <= 0:
            return "unknown"
        ratio = self.calibrated / self.nominal
        if ratio <= 1.0 - NO_BETTER:
            return "better"
        return "worse" if ratio > 1.0 + NO_BETTER else "no better"

    def line(self) -> str:
        """``heat_flux_in (test window): better: calibrated RMSE 1.2, nominal 2.3 (-48 %)``."""
        if self.verdict == "unknown":
            what = "no test window" if not self.held_out else "no samples"
            return f"{self.output} ({self.where}): not known ({what} to compare on)"
        change = 100.0 * (self.calibrated / self.nominal - 1.0)
        return (
            f"{self.output} ({self.where}): {self.verdict}: calibrated RMSE "
            f"{self.calibrated:.4g}, nominal (catalogue) {self.nominal:.4g} ({change:+.0f} %)"
        )

    def warning(self) -> str | None:
        """The loud sentence where the calibrated prediction is worse, else ``None``."""
        if self.verdict != "worse":
            return None
        return (
            f"{self.output}: the calibrated prediction is worse than the nominal (catalogue) "
            f"one out of sample ({self.where}: RMSE {self.calibrated:.4g} against "
            f"{self.nominal:.4g}): {ABSORBS}"
        )


def _rmse(rows: pd.DataFrame) -> float:
    """RMSE over the rows' samples pooled (``sqrt(sum n mse / sum n)``)."""
    if rows.empty:
        return float("nan")
    if len(rows) == 1:
        return float(rows["rmse"].iloc[0])
    n = rows["n"].to_numpy(dtype=float)
    mse = rows["mse"].to_numpy(dtype=float)
    return float(np.sqrt(np.sum(n * mse) / np.sum(n))) if np.sum(n) > 0 else float("nan")


def catalogue_verdicts(
    metrics: pd.DataFrame, held_out: Collection[str] = ()
) -> tuple[CatalogueVerdict, ...]:
    """Does the calibration beat the catalogue out of sample? One verdict per output.

    Parameters
    ----------
    metrics
        A ``metrics.csv`` table (columns ``output``, ``model``, ``window``,
        ``n``, ``mse``, ``rmse``), from
        :func:`bayescal.pipeline.predict.metrics_table`.
    held_out
        The outputs the calibration did not read: compared over every window
        (pooled); the others on the test window only.

    Returns
    -------
    tuple of CatalogueVerdict
        In the table's order of outputs.
    """
    out = []
    for output in dict.fromkeys(metrics["output"]):
        rows = metrics[metrics["output"] == output]
        is_held = output in held_out
        if not is_held:
            rows = rows[rows["window"] == "test"]
        out.append(
            CatalogueVerdict(
                str(output),
                is_held,
                _rmse(rows[rows["model"] == "nominal"]),
                _rmse(rows[rows["model"] == "calibrated"]),
            )
        )
    return tuple(out)


def held_out_outputs(attrs: dict[str, object]) -> tuple[str, ...]:
    """The held-out outputs a predictions dataset's ``attrs`` name."""
    return tuple(o for o in str(attrs.get("held_out", "")).split(",") if o)


#: Share of a prior from a previous posterior beyond the new posterior's centre below which
#: the two records count as disagreeing (:func:`prior_conflicts`).
CONFLICT = 0.05


def prior_conflicts(posterior: Posterior, phase: str = "") -> tuple[str, ...]:
    """Where the posterior's centre lies in the thin tail of a prior from a previous
    posterior (``[study] prior_from``): one sentence per such prior.

    The centre is the mean of the draws' ``logit(u)``; its squared Mahalanobis
    distance from the prior's logit-normal mean, under its covariance, is read
    against chi-square with as many degrees of freedom as the prior has
    parameters: below :data:`CONFLICT` of the prior's mass lies farther out.
    The new record then pulls the parameters where the previous one did not put
    them, and the product rests on the fitted density's tail, where it is least
    like the previous draws (``docs/case-studies.md``, Twin House).
    """
    from scipy import special, stats

    joints = {}
    for prior in posterior.priors.values():
        if isinstance(prior, PosteriorPrior):
            joints[prior.joint] = prior.joint
    found = []
    for joint in joints:
        columns = [posterior.names.index(n) for n in joint.names]
        u = posterior.unit_draws.reshape(-1, len(posterior.names))[:, columns]
        z = special.logit(np.clip(u, 1e-12, 1.0 - 1e-12)).mean(axis=0) - np.asarray(joint.mean)
        d2 = float(z @ np.linalg.solve(np.asarray(joint.cov, dtype=float), z))
        share = float(stats.chi2.sf(d2, len(joint.names)))
        if share < CONFLICT:
            found.append(
                f"{phase}the posterior of {', '.join(joint.names)} lies where the prior from "
                f"{joint.source or 'the previous posterior'} is thin ({100 * share:.2g} % of "
                "that prior lies farther from its centre): this record and the previous one "
                "disagree, and a sequential calibration then rests on the tail of the density "
                "fitted to the previous draws; `bayescal joint` calibrates both records "
                "without it"
            )
    return tuple(found)


def trust_warnings(
    posterior: Posterior | None,
    discrepancy: Posterior | None = None,
    metrics: pd.DataFrame | None = None,
    held_out: Collection[str] = (),
    model_error: Collection[ModelErrorSize] = (),
) -> tuple[str, ...]:
    """The warnings that say the calibration did not help, for the first screen.

    Parameters
    ----------
    posterior
        The calibration's posterior: its parameters leaning on a prior bound
        (:func:`bayescal.calibration.bounds.bound_warnings`), and its centre in the
        thin tail of a prior from a previous posterior (:func:`prior_conflicts`).
    discrepancy
        The difference-process phase's theta* posterior, if estimated (the same).
    metrics
        The metrics table, if predicted: outputs whose calibrated prediction is
        worse than the nominal out of sample (:func:`catalogue_verdicts`).
    held_out
        The held-out outputs of ``metrics``.
    model_error
        The in-likelihood discrepancies' sizes
        (:func:`bayescal.calibration.modelerror.discrepancy_ratios`): those the data
        show for certain (:attr:`~bayescal.calibration.modelerror.ModelErrorSize.shown`).
    """
    found: list[str] = []
    for phase, post in (("calibration: ", posterior), ("difference process: ", discrepancy)):
        if post is not None:
            found += bound_warnings(post.unit_draws, post.priors, phase=phase)
            found += prior_conflicts(post, phase=phase)
    if metrics is not None:
        for verdict in catalogue_verdicts(metrics, held_out):
            if (text := verdict.warning()) is not None:
                found.append(text)
    for size in model_error:
        if size.shown:
            found.append(f"{size.line()}: {MISSES}")
    return tuple(found)
