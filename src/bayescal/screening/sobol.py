"""Sobol indices from the runs of a Latin hypercube, through a quick GP (SALib).

The method (``[screening] method = "sobol"``):

* The runs are a Latin hypercube over the parameters' prior ranges, mapped to
  ``[0, 1]^k`` as for Morris and the design (the physical value is
  ``lower + u (upper - lower)``); each run gives one scalar per output.
* A GP with ARD length scales (:mod:`~bayescal.screening.surrogate`) is
  fitted to ``u -> scalar`` by maximum marginal likelihood, and its accuracy
  is measured by leave-one-out: ``Q2 = 1 - PRESS / sum (y - mean y)^2``.
  Below :data:`Q2_WARN` the ranking is not to be trusted (more runs, or
  Morris).
* The first-order and total Sobol indices ``S1`` and ``ST`` (Saltelli et al.
  2010, SALib's estimators) are computed on the GP mean at the ``N (k + 2)``
  points of a Saltelli sample (scrambled Sobol' sequence, ``N = base``)
  **uniform over the prior ranges**, like Morris's trajectories: the indices
  share out the variance over the ranges, not over the prior densities.
  ``S1_conf`` and ``ST_conf`` are SALib's 95 % bootstrap half-widths of that
  estimate (the Saltelli sample's error).
* The GP's own uncertainty: the same analysis on ``paths`` joint posterior
  draws of the GP at the Saltelli points gives a 95 % interval of each index
  (2.5 and 97.5 % of the paths' indices). It holds the emulator's error given
  its fitted hyperparameters, not the hyperparameters' uncertainty.
  :attr:`SobolIndices.st_lower` and ``st_upper`` widen it by the Saltelli
  half-width: the interval shown and kept.

Failed runs (NaN) are left out; the GP needs ``k + 2`` complete runs.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bayescal.errors import ConfigError
from bayescal.optional import require
from bayescal.screening.morris import salib_problem
from bayescal.screening.surrogate import ScalarGP, fit_scalar_gp

__all__ = ["Q2_WARN", "SobolIndices", "sobol_indices"]

#: Below this leave-one-out Q2 the GP is too rough for the ranking to be trusted.
Q2_WARN = 0.8


@dataclass(frozen=True, eq=False)
class SobolIndices:
    """Sobol indices of every parameter for one output, through the GP.

    Attributes
    ----------
    output
        The output (and statistic) they belong to.
    names
        Parameter names.
    s1, st
        First-order and total indices on the GP mean, shape ``(k,)``. [-]
    s1_conf, st_conf
        SALib's 95 % bootstrap half-widths of ``s1`` and ``st`` (the Saltelli
        sample's error).
    s1_paths, st_paths
        The indices of each GP posterior path, shape ``(paths, k)``.
    runs
        Runs the GP was fitted to (complete ones).
    q2
        Leave-one-out Q2 of the GP (NaN for a constant scalar).
    loo_rmse
        Leave-one-out root mean squared error, in the scalar's unit.
    sd
        Standard deviation of the scalar over the runs.
    lengths
        The GP's length scales on ``[0, 1]`` (a long one: a parameter with little
        effect).
    base
        Saltelli base sample ``N``.
    """

    output: str
    names: tuple[str, ...]
    s1: np.ndarray
    st: np.ndarray
    s1_conf: np.ndarray
    st_conf: np.ndarray
    s1_paths: np.ndarray
    st_paths: np.ndarray
    runs: int
    q2: float
    loo_rmse: float
    sd: float
    lengths: np.ndarray
    base: int

    @property
    def measure(self) -> str:
        """The index the proposal ranks by: ``"ST"``."""
        return "ST"

    @property
    def paths(self) -> int:
        """Number of GP posterior paths analysed."""
        return int(self.st_paths.shape[0])

    def _band(self, paths: np.ndarray, point: np.ndarray, conf: np.ndarray) -> np.ndarray:
        if paths.shape[0] < 2:
            return np.vstack([point - conf, point + conf])
        low, high = np.quantile(paths, [0.025, 0.975], axis=0)
        return np.vstack([np.minimum(low, point) - conf, np.maximum(high, point) + conf])

    @property
    def st_lower(self) -> np.ndarray:
        """Lower end of the 95 % interval of ``st``: the GP paths' 2.5 % widened by ``st_conf``."""
        return self._band(self.st_paths, self.st, self.st_conf)[0]

    @property
    def st_upper(self) -> np.ndarray:
        """Upper end of the 95 % interval of ``st`` (see :attr:`st_lower`)."""
        return self._band(self.st_paths, self.st, self.st_conf)[1]

    @property
    def s1_lower(self) -> np.ndarray:
        """Lower end of the 95 % interval of ``s1`` (as for ``st``)."""
        return self._band(self.s1_paths, self.s1, self.s1_conf)[0]

    @property
    def s1_upper(self) -> np.ndarray:
        """Upper end of the 95 % interval of ``s1``."""
        return self._band(self.s1_paths, self.s1, self.s1_conf)[1]

    @property
    def reliable(self) -> bool:
        """Whether the GP's leave-one-out Q2 reaches :data:`Q2_WARN` (a constant scalar is
        reliably insensitive)."""
        return bool(math.isnan(self.q2) and self.sd == 0) or self.q2 >= Q2_WARN

    @property
    def normalised(self) -> np.ndarray:
        """``ST`` over the largest ``ST`` of this output (0 if all are 0)."""
        st = np.maximum(self.st, 0.0)
        top = float(np.max(st)) if st.size else 0.0
        return st / top if top > 0 else np.zeros_like(st)

    @property
    def ranks(self) -> np.ndarray:
        """Rank of each parameter by ``ST`` (1 = most influential)."""
        order = np.argsort(-self.st, kind="stable")
        ranks = np.empty(order.size, dtype=int)
        ranks[order] = np.arange(1, order.size + 1)
        return ranks


def _analyse(names: Sequence[str], y: np.ndarray, resamples: int, seed: int) -> dict[str, object]:
    from SALib.analyze import sobol as sobol_analyze

    with warnings.catch_warnings():  # a flat path: SALib warns and returns zeros
        warnings.simplefilter("ignore")
        found: dict[str, object] = sobol_analyze.analyze(
            salib_problem(names),
            y,
            calc_second_order=False,
            num_resamples=int(resamples),
            conf_level=0.95,
            seed=int(seed),
        )
    return found


def _column(found: dict[str, object], key: str) -> np.ndarray:
    return np.nan_to_num(np.asarray(found[key], dtype=float), nan=0.0)


def sobol_indices(
    unit: np.ndarray,
    values: np.ndarray,
    names: Sequence[str],
    output: str,
    *,
    base: int = 1024,
    paths: int = 30,
    bootstrap: int = 1000,
    seed: int = 0,
    restarts: int = 4,
) -> SobolIndices:
    """Sobol indices of one scalar output from the runs at ``unit`` (see the module notes).

    Parameters
    ----------
    unit
        Normalised parameters of the runs, shape ``(n, k)``, in ``[0, 1]``.
    values
        The scalar at each run, shape ``(n,)``; NaN where the run failed.
    names
        Parameter names (at least two).
    output
        Name of the output, for the result.
    base
        Saltelli base sample ``N`` (a power of 2): ``N (k + 2)`` GP evaluations.
    paths
        GP posterior paths analysed for the GP's interval (0: none).
    bootstrap
        SALib's bootstrap resamples of the Saltelli half-widths.
    seed
        Seed of the GP's starts, the Saltelli sample, the paths and the bootstrap.
    restarts
        Random starts of the GP's likelihood maximisation besides the default one.

    Raises
    ------
    ConfigError
        If SALib is missing or fewer than ``k + 2`` runs are complete.
    """
    require("Sobol screening", "SALib")
    from SALib.sample import sobol as sobol_sample

    x = np.asarray(unit, dtype=float)
    y = np.asarray(values, dtype=float)
    k = len(names)
    if k < 2 or x.ndim != 2 or x.shape[1] != k or y.shape != (x.shape[0],):
        raise ValueError(f"need (n, {k}) points and n values for {k} >= 2 parameters")
    ok = np.isfinite(y)
    if int(ok.sum()) < k + 2:
        raise ConfigError(
            f"only {int(ok.sum())} of {y.size} screening runs succeeded; the Sobol GP of "
            f"{k} parameters needs at least {k + 2}",
            hint="see the failed runs in the output folder's simulations/failures",
        )
    x, y = x[ok], y[ok]
    sd = float(np.std(y))
    zeros = np.zeros(k)
    if not sd > 0:  # nothing varies: every index is 0
        empty = np.zeros((0, k))
        flat = np.full(k, np.inf)
        return SobolIndices(output, tuple(names), zeros, zeros, zeros, zeros, empty, empty,
                            int(y.size), math.nan, 0.0, 0.0, flat, int(base))  # fmt: skip
    gp: ScalarGP = fit_scalar_gp(x, y, restarts=restarts, seed=seed)
    points = sobol_sample.sample(
        salib_problem(names), int(base), calc_second_order=False, scramble=True, seed=int(seed)
    )
    mean, _ = gp.predict(points)
    found = _analyse(names, mean, bootstrap, seed + 1)
    s1_paths, st_paths = np.zeros((paths, k)), np.zeros((paths, k))
    if paths > 0:
        draws = gp.sample_paths(points, paths, np.random.default_rng(seed + 2))
        for p in range(paths):
            each = _analyse(names, draws[p], 2, seed + 3 + p)  # the point values only
            s1_paths[p], st_paths[p] = _column(each, "S1"), _column(each, "ST")
    return SobolIndices(
        output=output,
        names=tuple(names),
        s1=_column(found, "S1"),
        st=_column(found, "ST"),
        s1_conf=_column(found, "S1_conf"),
        st_conf=_column(found, "ST_conf"),
        s1_paths=s1_paths,
        st_paths=st_paths,
        runs=int(y.size),
        q2=gp.q2,
        loo_rmse=gp.loo_rmse,
        sd=sd,
        lengths=np.asarray(gp.lengths, dtype=float),
        base=int(base),
    )
