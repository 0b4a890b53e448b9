"""What the data fix and what they leave open: identifiability of theta*.

Three views of a posterior against its prior:

* **contraction** per parameter, ``1 - var_posterior / var_prior`` (1: fixed by
  the data, 0: the data said nothing);
* the **posterior correlation matrix** of theta*;
* the **principal directions** of the posterior relative to the prior. Each
  parameter ``theta_k`` is put on a scale where its prior has unit standard
  deviation: ``log theta_k`` for positive parameters (so a direction is a
  product of powers: a resistance ``d / k`` is a direction in ``log k``), the
  parameter itself otherwise. In these coordinates the prior is (about)
  isotropic, so the eigenvectors of the posterior covariance are the
  combinations the data inform most and least; the square root of each
  eigenvalue is the posterior SD along that combination as a fraction of the
  prior SD. A direction with a fraction near 1 is **unidentified**: "the data
  fix k_brick^-0.7 x k_eps^-0.7 (the total resistance); the split is left open".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bayescal.calibration.posterior import Posterior
from bayescal.mcmc.diagnostics import ESS_MIN, RHAT_MAX

__all__ = ["Direction", "Identifiability", "identifiability", "moves_hint"]

FloatArray = NDArray[np.float64]
#: Posterior SD along a direction, as a fraction of the prior's, above which it is unidentified.
UNIDENTIFIED = 0.7
#: Prior draws used to measure the prior's spread on the working scale.
PRIOR_DRAWS = 20_000
#: Posterior correlation from which slow mixing is blamed on one-at-a-time moves.
CORRELATED = 0.7


@dataclass(frozen=True)
class Direction:
    """One principal direction of the posterior relative to the prior.

    Attributes
    ----------
    exponents
        Powers of the parameters on the working scale (log-scale parameters:
        ``prod theta_k^e_k``; others: ``sum e_k theta_k``), largest magnitude 1,
        ``(t,)``.
    ratio
        Posterior SD along the direction over the prior SD. [-]
    """

    exponents: FloatArray
    ratio: float

    def text(self, names: tuple[str, ...], log_scale: tuple[bool, ...]) -> str:
        """The combination in words, e.g. ``k_brick^0.98 x k_eps^-1.00``."""
        order = np.argsort(-np.abs(self.exponents))
        terms = []
        for k in order:
            e = float(self.exponents[k])
            if abs(e) < 0.15:
                continue
            terms.append(f"{names[k]}^{e:.2f}" if log_scale[k] else f"{e:+.2f} {names[k]}")
        joined = " x ".join(terms) if all(log_scale[k] for k in order) else " ".join(terms)
        return joined or "(none)"


@dataclass(frozen=True)
class Identifiability:
    """Contraction, correlation and principal directions of a posterior (module docstring)."""

    names: tuple[str, ...]
    log_scale: tuple[bool, ...]
    contraction: FloatArray
    correlation: FloatArray
    directions: tuple[Direction, ...]

    def lines(self) -> list[str]:
        """Plain sentences for ``bayescal show`` and the report."""
        out = []
        for d in self.directions:
            what = d.text(self.names, self.log_scale)
            pct = 100.0 * d.ratio
            if d.ratio >= UNIDENTIFIED:
                out.append(f"unidentified: {what} (posterior SD {pct:.0f} % of the prior's)")
            else:
                out.append(f"the data fix {what} (posterior SD {pct:.2g} % of the prior's)")
        return out


def _working_scale(posterior: Posterior, seed: int) -> tuple[FloatArray, FloatArray, list[bool]]:
    """Posterior draws and prior SDs on the working scale (log where positive)."""
    rng = np.random.default_rng(seed)
    draws = posterior.draws.reshape(-1, len(posterior.names))
    cols, sds, logs = [], [], []
    for k, prior in enumerate(posterior.priors.values()):
        prior_draws = prior.from_unit(prior.sample_unit(rng, PRIOR_DRAWS))
        use_log = prior.lower > 0.0
        scale = np.log if use_log else np.asarray
        cols.append(scale(draws[:, k]))
        sds.append(float(np.std(scale(prior_draws))))
        logs.append(use_log)
    return np.column_stack(cols), np.array(sds), logs


def identifiability(posterior: Posterior, seed: int = 0) -> Identifiability:
    """The three views of the module docstring for ``posterior``.

    Parameters
    ----------
    posterior
        The calibration posterior (its priors give the prior spread). Parameters whose
        draws are all one value (held, not calibrated) are left out.
    seed
        Seed of the prior draws that measure the prior's spread.
    """
    draws, prior_sd, logs = _working_scale(posterior, seed)
    # coordinates held at a value (``[design] reuse_screening``'s screened-out inputs) are
    # not calibrated: the data neither fix them nor correlate them with the others
    moving = np.array([n not in posterior.held_names for n in posterior.names])
    names = tuple(n for n, m in zip(posterior.names, moving, strict=True) if m)
    draws, prior_sd = draws[:, moving], prior_sd[moving]
    logs = [log for log, m in zip(logs, moving, strict=True) if m]
    z = draws / prior_sd
    cov = np.atleast_2d(np.cov(z, rowvar=False))
    sd = np.sqrt(np.diag(cov))
    safe = np.where(sd > 0.0, sd, 1.0)
    correlation = cov / np.outer(safe, safe)
    contraction = 1.0 - np.diag(cov)
    values, vectors = np.linalg.eigh(cov)
    directions = []
    for value, vector in zip(values, vectors.T, strict=True):
        exponents = vector / prior_sd  # back to powers of log theta (or multiples of theta)
        exponents = exponents / exponents[np.argmax(np.abs(exponents))]  # largest: +1
        directions.append(Direction(exponents, float(np.sqrt(max(value, 0.0)))))
    return Identifiability(names, tuple(logs), contraction, correlation, tuple(directions))


def moves_hint(posterior: Posterior) -> str | None:
    """Advice to move the coordinates jointly, where one-at-a-time moves mixed badly.

    ``None`` unless some coordinate missed R-hat <= 1.01 or ESS >= 400 and two
    sampled coordinates (theta* and the noise terms, on the log scale where
    positive) are correlated beyond ``CORRELATED`` in the posterior: random-walk
    steps one coordinate at a time crawl along such ridges, and
    ``[calibration] moves = "joint"`` moves them together (better on every shipped
    example; a 16-coordinate block needs a long burn-in: a suggestion to check).
    """
    d = posterior.diagnostics
    slow = (d.rhat > RHAT_MAX) | (d.ess_bulk < ESS_MIN) | (d.ess_tail < ESS_MIN)
    if not np.any(slow):
        return None
    draws = posterior.all_draws().reshape(-1, len(posterior.all_names))
    positive = np.all(draws > 0.0, axis=0)
    z = np.where(positive, np.log(np.where(positive, draws, 1.0)), draws)
    moving = np.ptp(z, axis=0) > 0.0  # a held coordinate is constant (std may round above 0)
    if np.count_nonzero(moving) < 2:
        return None
    names = [n for n, m in zip(posterior.all_names, moving, strict=True) if m]
    corr = np.corrcoef(z[:, moving], rowvar=False)
    np.fill_diagonal(corr, 0.0)
    i, j = sorted(np.unravel_index(int(np.argmax(np.abs(corr))), corr.shape))
    if abs(corr[i, j]) < CORRELATED:
        return None
    return (
        f"{names[i]} and {names[j]} are correlated in the posterior ({corr[i, j]:+.2f}): "
        'one-at-a-time moves crawl along such ridges; try [calibration] moves = "joint", '
        "which moves them together (Twin House, boxes, office: 3-10x the ESS per second; "
        "a block of 16 needs a burn-in of ~2000 sweeps; compare the diagnostics, "
        "docs/method.md 4)"
    )
