"""Goodness-of-fit metrics of a simulated (or predicted) series against measurements.

Definitions (``e = simulated - measured``, over the ``n`` scored samples):

* MSE = mean(e²); RMSE = sqrt(MSE);
* mean absolute error = mean(|e|);
* maximum absolute error = max(|e|) (the paper's "MAE" column is this one);
* bias = mean(e);
* ASHRAE Guideline 14 CV(RMSE) = sqrt(sum(e²) / (n - p)) / mean(measured) and
  NMBE = sum(-e) / ((n - p) · mean(measured)), both in %, with ``p`` the number of
  parameters of the model (degrees of freedom; Guideline 14 uses p = 1 for
  calibrated simulation). NMBE is positive when the model under-predicts.
  Both are undefined (NaN) where the measured mean is zero; CV(RMSE) divides by
  the absolute mean, so it stays positive for series with a negative mean (a
  heat flux out of a room).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class Metrics:
    """Fit metrics; units are the output's (squared for MSE), CV(RMSE) and NMBE in %."""

    n: int
    mse: float
    rmse: float
    mean_abs_error: float
    max_abs_error: float
    bias: float
    cv_rmse: float
    nmbe: float

    def as_dict(self) -> dict[str, float]:
        """The metrics as a plain dictionary."""
        return asdict(self)


def fit_metrics(simulated: npt.ArrayLike, measured: npt.ArrayLike, *, p: int = 1) -> Metrics:
    """Metrics of ``simulated`` against ``measured`` over samples where both are finite.

    Parameters
    ----------
    simulated, measured
        Series of the same shape, in the output's unit.
    p
        Degrees of freedom removed in CV(RMSE) and NMBE (ASHRAE Guideline 14).
    """
    sim = np.asarray(simulated, dtype=float)
    obs = np.asarray(measured, dtype=float)
    if sim.shape != obs.shape:
        raise ValueError(f"simulated has shape {sim.shape}, measured {obs.shape}")
    ok = np.isfinite(sim) & np.isfinite(obs)
    e = sim[ok] - obs[ok]
    n = int(e.size)
    if n == 0:
        nan = float("nan")
        return Metrics(0, nan, nan, nan, nan, nan, nan, nan)
    mse = float(np.mean(e**2))
    mean_obs = float(np.mean(obs[ok]))
    dof = max(n - p, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cv = 100.0 * np.sqrt(np.sum(e**2) / dof) / abs(mean_obs) if mean_obs != 0 else float("nan")
        nmbe = 100.0 * float(np.sum(-e)) / (dof * mean_obs) if mean_obs != 0 else float("nan")
    return Metrics(
        n=n,
        mse=mse,
        rmse=float(np.sqrt(mse)),
        mean_abs_error=float(np.mean(np.abs(e))),
        max_abs_error=float(np.max(np.abs(e))),
        bias=float(np.mean(e)),
        cv_rmse=float(cv),
        nmbe=float(nmbe),
    )
