"""Morris elementary effects: trajectories, mu*, sigma, and the parameters to calibrate.

The method (Morris 1991; Campolongo, Cariboni & Saltelli 2007), with SALib
doing the sampling and the analysis:

* Each parameter's prior range is mapped to ``[0, 1]`` (the physical value
  is ``lower + u (upper - lower)``, as in the Latin hypercube of
  :mod:`bayescal.design`). A *trajectory* starts at a random point of a grid
  of ``p`` levels and moves one parameter at a time by
  ``delta = p / (2 (p - 1))``: ``k + 1`` runs for ``k`` parameters, ``r``
  trajectories in all, ``r (k + 1)`` runs.
* The elementary effect of parameter ``i`` on an output's scalar ``y`` in a
  trajectory is ``(y(u + delta e_i) - y(u)) / delta``: the change of ``y``
  per whole prior range. Over the ``r`` trajectories, ``mu*`` is the mean of
  their absolute values (the influence), ``mu`` their mean (its sign) and
  ``sigma`` their standard deviation (non-linearity and interactions); the
  95 % confidence interval of ``mu*`` comes from ``bootstrap`` resamples of
  the trajectories.
* A trajectory with a failed run gives no effect for its parameters; such
  trajectories are left out (the count is reported), as SALib needs complete
  trajectories.

Proposal
--------
:func:`~bayescal.screening.proposal.propose` (re-exported here): for each
output, a parameter's *score* is its ``mu*`` over the largest ``mu*`` of that
output (1 for the most influential); its score is its best over the outputs,
so a parameter that matters for one output only is kept. Parameters whose
score reaches ``threshold`` are proposed, most influential first, at most
``max_parameters`` of them. This is a screening rule, not a test: look at the
``mu*``-``sigma`` plot before dropping a parameter whose interval reaches the
threshold.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bayescal.errors import ConfigError
from bayescal.optional import require
from bayescal.screening.proposal import Proposal, propose

__all__ = [
    "MorrisDesign",
    "MorrisIndices",
    "Proposal",
    "morris_design",
    "morris_indices",
    "propose",
]


def salib_problem(names: Sequence[str]) -> dict[str, object]:
    """SALib's problem of ``names`` on the unit cube (Morris and Sobol sample it)."""
    return {"num_vars": len(names), "names": list(names), "bounds": [[0.0, 1.0]] * len(names)}


@dataclass(frozen=True, eq=False)
class MorrisDesign:
    """Morris trajectories on the unit cube of the parameters' prior ranges.

    Attributes
    ----------
    names
        Parameter names, in column order.
    unit
        Normalised points, shape ``(r (k + 1), k)``, in ``[0, 1]``; rows
        ``j (k + 1) ... j (k + 1) + k`` form trajectory ``j``.
    trajectories
        Number of trajectories ``r``.
    levels
        Grid levels ``p``.
    seed
        Seed of the trajectories.
    """

    names: tuple[str, ...]
    unit: np.ndarray
    trajectories: int
    levels: int
    seed: int

    @property
    def runs(self) -> int:
        """Number of points ``r (k + 1)``."""
        return int(self.unit.shape[0])

    @property
    def trajectory(self) -> np.ndarray:
        """Trajectory of each row, shape ``(runs,)``."""
        return np.arange(self.runs) // (len(self.names) + 1)


def morris_design(names: Sequence[str], trajectories: int, levels: int, seed: int) -> MorrisDesign:
    """Draw ``trajectories`` Morris trajectories over ``len(names)`` parameters.

    Parameters
    ----------
    names
        Parameter names (at least two).
    trajectories
        Number of trajectories ``r`` (at least 2).
    levels
        Grid levels ``p`` (even, at least 2).
    seed
        Seed of SALib's generator.

    Raises
    ------
    ConfigError
        If SALib is missing or the arguments are out of range.
    """
    require("Morris screening", "SALib")
    from SALib.sample import morris as morris_sample

    if len(names) < 2:
        raise ConfigError(f"screening needs at least two parameters, got {list(names)}")
    if trajectories < 2 or levels < 2 or levels % 2:
        raise ConfigError(
            f"Morris needs >= 2 trajectories and an even number of levels >= 2, got "
            f"trajectories={trajectories}, levels={levels}"
        )
    unit = morris_sample.sample(
        salib_problem(names), int(trajectories), num_levels=int(levels), seed=int(seed)
    )
    unit = np.clip(np.asarray(unit, dtype=float), 0.0, 1.0)
    unit.flags.writeable = False
    return MorrisDesign(tuple(names), unit, int(trajectories), int(levels), int(seed))


@dataclass(frozen=True, eq=False)
class MorrisIndices:
    """Morris indices of every parameter for one output.

    Attributes
    ----------
    output
        The output (and statistic) they belong to.
    names
        Parameter names.
    mu_star, mu, sigma
        Mean absolute, mean and standard deviation of the elementary
        effects, in the output's unit per whole prior range; shape ``(k,)``.
    mu_star_conf
        Half-width of the 95 % bootstrap confidence interval of ``mu*``.
    trajectories
        Trajectories used (complete ones).
    """

    output: str
    names: tuple[str, ...]
    mu_star: np.ndarray
    mu: np.ndarray
    sigma: np.ndarray
    mu_star_conf: np.ndarray
    trajectories: int

    @property
    def measure(self) -> str:
        """The index the proposal ranks by: ``"mu*"``."""
        return "mu*"

    @property
    def normalised(self) -> np.ndarray:
        """``mu*`` over the largest ``mu*`` of this output (0 if all are 0)."""
        top = float(np.max(self.mu_star)) if self.mu_star.size else 0.0
        return self.mu_star / top if top > 0 else np.zeros_like(self.mu_star)

    @property
    def ranks(self) -> np.ndarray:
        """Rank of each parameter by ``mu*`` (1 = most influential)."""
        order = np.argsort(-self.mu_star, kind="stable")
        ranks = np.empty(order.size, dtype=int)
        ranks[order] = np.arange(1, order.size + 1)
        return ranks


def morris_indices(
    design: MorrisDesign, values: np.ndarray, output: str, *, bootstrap: int = 1000, seed: int = 0
) -> MorrisIndices:
    """Morris indices of one scalar output over a design.

    Parameters
    ----------
    design
        The trajectories.
    values
        The scalar at each row of the design, shape ``(runs,)``; NaN where
        the run failed (its trajectory is left out).
    output
        Name of the output, for the result.
    bootstrap
        Resamples of the confidence intervals.
    seed
        Seed of the bootstrap.

    Raises
    ------
    ConfigError
        If fewer than two trajectories are complete.
    """
    require("Morris screening", "SALib")
    from SALib.analyze import morris as morris_analyze

    y = np.asarray(values, dtype=float)
    if y.shape != (design.runs,):
        raise ValueError(f"values must have shape ({design.runs},), got {y.shape}")
    bad = np.unique(design.trajectory[~np.isfinite(y)])
    keep = ~np.isin(design.trajectory, bad)
    used = design.trajectories - bad.size
    if used < 2:
        raise ConfigError(
            f"only {used} of {design.trajectories} Morris trajectories have every run; at "
            "least 2 are needed",
            hint="see the failed runs in the output folder's simulations/failures",
        )
    found = morris_analyze.analyze(
        salib_problem(design.names),
        np.asarray(design.unit)[keep],
        y[keep],
        num_resamples=int(bootstrap),
        conf_level=0.95,
        num_levels=design.levels,
        seed=int(seed),
    )

    def column(key: str) -> np.ndarray:
        return np.asarray(np.ma.filled(found[key], np.nan), dtype=float)

    return MorrisIndices(
        output=output,
        names=design.names,
        mu_star=column("mu_star"),
        mu=column("mu"),
        sigma=column("sigma"),
        mu_star_conf=column("mu_star_conf"),
        trajectories=int(used),
    )
