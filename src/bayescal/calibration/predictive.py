"""The predictive distribution of a measurement: a mixture over posterior draws.

For one sample of a measured series the calibration gives, for every retained
posterior draw ``s = 1..S``, a Gaussian: mean ``mu_s`` (the emulator's or the
simulator's prediction at theta*_s, plus Delta where the difference process is
used) and variance ``v_s`` (the emulator's interpolation variance, the
observation noise ``sd^2 / lambda*_s`` and Delta's variance). The predictive
distribution of the measurement is the equally weighted mixture

    F(y) = (1/S) sum_s Phi((y - mu_s) / sqrt(v_s)).

Its quantiles (the band edges) are found here by bisection on ``F`` itself, not
as percentiles of a few random realisations: the only Monte Carlo error left
is that of the ``S`` draws, and it is estimated with the band
(:func:`quantile_error`: ``sd_s(Phi_s(y_q)) / (sqrt(S_eff) f(y_q))``, the
delta method for a quantile of an average of CDFs). The probability integral
transform of a measurement, ``F(y_obs)``, is uniform on [0, 1] when the
predictive distribution is right (:func:`pit`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

__all__ = ["mixture_cdf", "mixture_quantiles", "pit", "quantile_error"]

FloatArray = NDArray[np.float64]
_SQRT2PI = float(np.sqrt(2.0 * np.pi))
_ITERATIONS = 60  # bisection halvings: the bracket shrinks by 2^-60, below float precision


def _as_pair(mean: ArrayLike, variance: ArrayLike) -> tuple[FloatArray, FloatArray]:
    mu = np.asarray(mean, dtype=float)
    var = np.asarray(variance, dtype=float)
    if mu.ndim != 2 or var.shape != mu.shape:
        raise ValueError(f"expected mean and variance (S, T) alike, got {mu.shape}, {var.shape}")
    if not np.all(var > 0.0):
        raise ValueError("predictive variances must be > 0")
    return mu, np.sqrt(var)


def mixture_cdf(mean: ArrayLike, variance: ArrayLike, y: ArrayLike) -> FloatArray:
    """``F(y)`` of the mixture at every sample ``(T,)``.

    Parameters
    ----------
    mean, variance
        Component means and variances ``(S, T)``.
    y
        Values ``(T,)``.
    """
    mu, sd = _as_pair(mean, variance)
    out: FloatArray = special.ndtr((np.asarray(y, dtype=float)[None, :] - mu) / sd).mean(axis=0)
    return out


def mixture_quantiles(mean: ArrayLike, variance: ArrayLike, probs: ArrayLike) -> FloatArray:
    """Quantiles of the mixture, ``(len(probs), T)``, by bisection on its CDF.

    Parameters
    ----------
    mean, variance
        Component means and variances ``(S, T)``.
    probs
        Probabilities in (0, 1).
    """
    mu, sd = _as_pair(mean, variance)
    p = np.asarray(probs, dtype=float).reshape(-1)
    if not np.all((p > 0.0) & (p < 1.0)):
        raise ValueError(f"probabilities must lie in (0, 1), got {p.tolist()}")
    # Every component's quantile brackets the mixture's: F is an average of the Phi_s.
    z = special.ndtri(p)[:, None, None]  # (P, 1, 1)
    comp = mu[None] + z * sd[None]  # (P, S, T)
    lo, hi = comp.min(axis=1), comp.max(axis=1)
    for _ in range(_ITERATIONS):
        mid = 0.5 * (lo + hi)
        below = special.ndtr((mid[:, None, :] - mu[None]) / sd[None]).mean(axis=1) < p[:, None]
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    out: FloatArray = 0.5 * (lo + hi)
    return out


def quantile_error(
    mean: ArrayLike, variance: ArrayLike, quantile: ArrayLike, n_effective: float | None = None
) -> FloatArray:
    """Monte Carlo standard error of a mixture quantile due to the finite draws ``(T,)``.

    ``sd_s(Phi_s(y_q)) / (sqrt(S_eff) f(y_q))`` with ``f`` the mixture density:
    the error of the average CDF at ``y_q`` carried to the quantile.

    Parameters
    ----------
    mean, variance
        Component means and variances ``(S, T)``.
    quantile
        The quantile ``y_q`` at every sample ``(T,)``.
    n_effective
        Effective number of independent draws (default ``S``; give the ESS when
        the draws are autocorrelated).
    """
    mu, sd = _as_pair(mean, variance)
    zq = (np.asarray(quantile, dtype=float)[None, :] - mu) / sd
    cdf = special.ndtr(zq)
    dens = (np.exp(-0.5 * zq * zq) / (_SQRT2PI * sd)).mean(axis=0)
    n = float(mu.shape[0] if n_effective is None else n_effective)
    out: FloatArray = cdf.std(axis=0) / (np.sqrt(n) * np.maximum(dens, np.finfo(float).tiny))
    return out


def pit(mean: ArrayLike, variance: ArrayLike, observed: ArrayLike) -> FloatArray:
    """Probability integral transform ``F(y_obs)`` of every observed sample ``(T,)``.

    NaN where the observation is missing.
    """
    obs = np.asarray(observed, dtype=float)
    out: FloatArray = np.full(obs.shape, np.nan)
    ok = np.isfinite(obs)
    if ok.any():
        mu, var = np.asarray(mean, dtype=float), np.asarray(variance, dtype=float)
        out[ok] = mixture_cdf(mu[:, ok], var[:, ok], obs[ok])
    return out
