"""Priors of theta* for the discrepancy phase, from the calibration posterior.

The paper (section "Difference process") advises to take as priors "those
inferred previously at least for the better identified parameters", and less
informative ones, Beta(1, 2), for parameters "whose probability mass is close
to the boundaries of their intervals". :func:`default_priors` makes that rule
concrete on the normalised scale ``u in [0, 1]`` of the prior bounds.

Piled up at a bound
-------------------
Let ``q_lo`` and ``q_hi`` be the 2.5 % and 97.5 % quantiles of the posterior
draws of ``u`` and ``sd`` their standard deviation. The posterior is **piled up
at the lower bound** when ``q_lo < 0.25 sd`` and ``1 - q_hi >= 0.25 sd``, and
at the upper bound in the mirror case. The ratio ``q_lo / sd`` is about 0.05
for a half-normal, 0.03 for an exponential and 0.05 for a Beta(1, 2) density
(mode at the bound; 0.09 for the uniform), 0.11 for a normal whose mode lies
one SD inside the bound and truncated there, 0.18 at 1.5 SDs, 0.35 at two and
1.07 at three (Monte Carlo, 10^6 draws); 0.25 therefore means "the mode lies
within about 1.7 posterior SDs of the bound". A posterior that meets the test
at both ends (flat, spread over the interval: not identified) counts as
spread, not piled up.

Priors
------
* piled up at the lower bound: Beta(1, 2) on the bounds, the paper's choice
  (density ``2 (1 - u)``: it keeps the lean towards the bound but is far
  weaker than the pile-up, so the data decide again); mirrored, Beta(2, 1), at
  the upper bound. ``pile_up="away"`` swaps the two (weight away from the
  pile-up) for those who prefer to challenge the bound rather than soften it.
* otherwise: the Beta distribution on the bounds with the posterior's mean
  and variance (method of moments), each shape raised to at least 1 so the
  density stays finite at the bounds (a posterior spread over the whole
  interval gives Beta(1, 1), the uniform prior).

These priors re-use the data of the calibration phase (the paper's
sequential scheme): the discrepancy-phase posterior of a well-identified
parameter is therefore narrower than a single use of the data would justify.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from bayescal.calibration.posterior import Posterior
from bayescal.design import BetaPrior, Prior, UniformPrior
from bayescal.errors import ConfigError

__all__ = ["PILE_UP_RATIO", "default_priors", "moment_beta", "piled_up"]

#: Distance of the outer 2.5 % quantile from a bound, in posterior SDs, below
#: which the posterior counts as piled up there.
PILE_UP_RATIO = 0.25

Side = Literal["lower", "upper"]


def piled_up(u: ArrayLike, ratio: float = PILE_UP_RATIO) -> Side | None:
    """Which bound the normalised draws ``u`` pile up at, if any (see the module doc).

    Parameters
    ----------
    u
        Posterior draws of one parameter on the normalised scale, any shape. [-]
    ratio
        Threshold of ``quantile distance / sd``. [-]
    """
    arr = np.asarray(u, dtype=float).reshape(-1)
    sd = float(np.std(arr))
    if not sd > 0.0:
        return None
    q_lo, q_hi = np.percentile(arr, [2.5, 97.5])
    low = q_lo < ratio * sd
    high = 1.0 - q_hi < ratio * sd
    if low and not high:
        return "lower"
    if high and not low:
        return "upper"
    return None


def moment_beta(u: ArrayLike) -> tuple[float, float]:
    """Beta shapes ``(a, b)`` with the mean and variance of ``u``, each at least 1.

    Parameters
    ----------
    u
        Draws on the normalised scale [0, 1]. [-]
    """
    arr = np.asarray(u, dtype=float).reshape(-1)
    mean, var = float(np.mean(arr)), float(np.var(arr))
    spread = mean * (1.0 - mean)
    if not (var > 0.0 and spread > var):
        return 1.0, 1.0
    common = spread / var - 1.0
    return max(1.0, mean * common), max(1.0, (1.0 - mean) * common)


def default_priors(
    posterior: Posterior, *, pile_up: Literal["toward", "away"] = "toward"
) -> dict[str, Prior]:
    """Priors of theta* for the discrepancy phase from the calibration posterior.

    Parameters
    ----------
    posterior
        The calibration phase's posterior (its priors give the bounds).
    pile_up
        ``"toward"`` (the paper: Beta(1, 2) for a pile-up at the lower bound) or
        ``"away"`` (Beta(2, 1) there, weight away from the pile-up).

    Returns
    -------
    dict
        Parameter name -> prior on the same bounds, in the posterior's order.
    """
    if pile_up not in ("toward", "away"):
        raise ConfigError(f"pile_up must be 'toward' or 'away', got {pile_up!r}")
    out: dict[str, Prior] = {}
    for i, (name, prior) in enumerate(posterior.priors.items()):
        u = posterior.unit_draws[..., i]
        side = piled_up(u)
        if side is None:
            a, b = moment_beta(u)
        else:
            at_lower = (side == "lower") == (pile_up == "toward")
            a, b = (1.0, 2.0) if at_lower else (2.0, 1.0)
        if a == 1.0 and b == 1.0:
            out[name] = UniformPrior(
                prior.lower, prior.upper, unit=prior.unit, description=prior.description
            )
        else:
            out[name] = BetaPrior(
                prior.lower, prior.upper, a, b, unit=prior.unit, description=prior.description
            )
    return out
