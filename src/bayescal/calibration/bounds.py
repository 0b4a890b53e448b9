"""Posteriors that lean on a bound of their prior.

Every prior of theta* is bounded (``[lower, upper]``, uniform or a scaled
Beta). A parameter **leans on a bound** when at least :data:`LEAN_SHARE`
(5 %) of its posterior draws lie within :data:`EDGE` (1 %) of the prior range
of that bound: five times the share that a posterior as flat as a uniform prior
puts there, so the posterior's density at the bound is at least five times the
flat density over the range. A posterior spread uniformly over the prior puts
1 % of its draws there and is not flagged (with 400 effective draws, the
share's standard error is 0.5 %); one with its mass piled at a bound is; a
narrow posterior whose mass stays more than a few of its SDs inside the range
is not, however near the bound it is.

What it usually means: the data push the parameter beyond its physically
plausible range, because the parameter absorbs an error of the model (a missing
heat path, a wrong boundary condition) or because the prior is too narrow.
Either way the value is a fitting constant, not a property of the material.

The rule reads the draws only (no file, no terminal); :func:`bound_warnings`
words it for the pipeline, ``bayescal show`` and the report.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from bayescal.design import Prior

__all__ = ["EDGE", "LEAN_SHARE", "MEANING", "BoundLean", "bound_leans", "bound_warnings"]

#: Width of the band next to a bound, as a fraction of the prior range. [-]
EDGE = 0.01
#: Share of the draws in that band from which a parameter leans on the bound. [-]
LEAN_SHARE = 0.05
#: What a posterior leaning on a bound usually means (the warning's second half).
MEANING = (
    "model error absorbed by the parameter, or a prior too narrow: treat it as a fitting "
    "constant, not a property"
)


@dataclass(frozen=True)
class BoundLean:
    """One parameter leaning on one bound of its prior.

    Attributes
    ----------
    name
        The parameter.
    side
        ``"lower"`` or ``"upper"``.
    share
        Fraction of the posterior draws within :data:`EDGE` of the prior range
        of that bound. [-]
    """

    name: str
    side: Literal["lower", "upper"]
    share: float

    def sentence(self, prior: Prior) -> str:
        """``k_cb leans on the upper bound of its prior (0.2 W/(m·K)): 38 % of ...``."""
        bound = prior.upper if self.side == "upper" else prior.lower
        unit = f" {prior.unit}" if prior.unit else ""
        return (
            f"{self.name} leans on the {self.side} bound of its prior ({bound:g}{unit}): "
            f"{100 * self.share:.0f} % of the posterior draws lie within {100 * EDGE:g} % "
            f"of the prior range of it (a flat posterior puts {100 * EDGE:g} % there); "
            f"{MEANING}"
        )


def bound_leans(
    unit_draws: ArrayLike,
    names: Sequence[str],
    *,
    edge: float = EDGE,
    share: float = LEAN_SHARE,
) -> tuple[BoundLean, ...]:
    """The parameters whose posterior leans on a bound of their prior.

    Parameters
    ----------
    unit_draws
        Draws on the prior's normalised scale (0 at the lower bound, 1 at the
        upper), ``(..., t)``: any leading shape (chains, draws). [-]
    names
        The ``t`` parameter names.
    edge
        Width of the band next to each bound, a fraction of the range. [-]
    share
        Share of the draws in a band from which the parameter leans on that
        bound (the draws of a band count, whatever happens at the other). [-]

    Returns
    -------
    tuple of BoundLean
        In parameter order, lower bound before upper; empty where none leans. A
        parameter whose draws are all one value was held there (``[design]
        reuse_screening``'s screened-out inputs at a nominal value on a bound), not
        calibrated: it does not lean.
    """
    u = np.asarray(unit_draws, dtype=float)
    if u.ndim == 0 or u.shape[-1] != len(names):
        raise ValueError(f"draws of shape {u.shape} do not end in {len(names)} parameters")
    flat = u.reshape(-1, len(names))
    found = []
    for k, name in enumerate(names):
        column = flat[:, k][np.isfinite(flat[:, k])]
        if column.size < 2 or np.ptp(column) == 0.0:  # none, or held at one value: not free
            continue
        for side, near in (("lower", column <= edge), ("upper", column >= 1.0 - edge)):
            fraction = float(np.mean(near))
            if fraction >= share:
                found.append(BoundLean(name, side, fraction))  # type: ignore[arg-type]
    return tuple(found)


def bound_warnings(
    unit_draws: ArrayLike, priors: Mapping[str, Prior], *, phase: str = ""
) -> tuple[str, ...]:
    """One sentence per parameter and bound it leans on (:func:`bound_leans`).

    Parameters
    ----------
    unit_draws
        Normalised draws ``(..., t)``, the columns in the order of ``priors``
        (a :class:`~bayescal.calibration.posterior.Posterior`'s ``unit_draws``
        and ``priors``).
    priors
        Parameter name -> its prior (the bound's value and unit).
    phase
        Put before each sentence (``"difference process: "``).
    """
    leans = bound_leans(unit_draws, list(priors))
    return tuple(f"{phase}{lean.sentence(priors[lean.name])}" for lean in leans)
