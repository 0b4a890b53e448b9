"""A quick Gaussian process of one scalar over ``[0, 1]^k``: the surrogate of Sobol screening.

The model of the standardised scalar ``z = (y - centre) / scale`` at the
normalised parameters ``u`` is

    z(u) = beta + f(u) + eps,   f ~ GP(0, s2 m52(u, u')),   eps ~ N(0, n2),

with the Matérn 5/2 correlation with one length scale ``l_i`` per parameter
(ARD): ``m52 = (1 + sqrt(5) r + 5 r^2 / 3) exp(-sqrt(5) r)``,
``r^2 = sum_i ((u_i - u'_i) / l_i)^2``. The constant ``beta`` is its
generalised least-squares estimate given the other hyperparameters (profiled
out), and ``l``, ``s2`` and the nugget ``n2`` maximise the marginal likelihood
(L-BFGS-B on their logarithms with the analytic gradient, from a few starts;
the best is kept). The hyperparameters are point estimates: what follows
(predictions, leave-one-out, sample paths) treats them as known.

* :meth:`ScalarGP.predict` -- the posterior mean and variance of ``beta + f``;
* :meth:`ScalarGP.loo` -- the closed-form leave-one-out predictions
  (Rasmussen & Williams 2006, eq. 5.12) and :attr:`ScalarGP.q2`, their
  ``1 - PRESS / sum (y - mean y)^2``;
* :meth:`ScalarGP.sample_paths` -- joint draws of ``beta + f`` given the runs
  at many points by pathwise conditioning (Wilson et al. 2020): a prior path
  from random Fourier features of the Matérn spectral density (a Student-t of
  5 degrees of freedom scaled by ``1 / l``), moved onto the data by the
  kriging update ``k(u, U) K^-1 (z - beta - f_prior(U) - eps)``. The cost is
  linear in the number of points, so tens of thousands of Saltelli points are
  cheap; the prior part's covariance is exact as the features grow (error
  ``O(features^-1/2)``).

This GP lives here, not in :mod:`bayescal.emulator` (a floor above), because
the screening needs one scalar per run, not a PCA basis of series.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, optimize

__all__ = ["ScalarGP", "fit_scalar_gp", "matern52"]

_SQRT5 = math.sqrt(5.0)
_JITTER = 1e-10
#: Bounds of log length scale, log signal variance and log nugget (standardised scale).
_LOG_LENGTH = (math.log(0.01), math.log(100.0))
_LOG_SIGNAL = (math.log(1e-3), math.log(1e4))
_LOG_NUGGET = (math.log(1e-8), math.log(1.0))


def _sq_dist(a: np.ndarray, b: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    sa, sb = a / lengths, b / lengths
    d2 = (sa * sa).sum(1)[:, None] + (sb * sb).sum(1)[None, :] - 2.0 * sa @ sb.T
    return np.asarray(np.maximum(d2, 0.0))


def matern52(a: np.ndarray, b: np.ndarray, lengths: np.ndarray, variance: float) -> np.ndarray:
    """The Matérn 5/2 ARD covariance between the rows of ``a`` and of ``b``."""
    r = np.sqrt(_sq_dist(np.atleast_2d(a), np.atleast_2d(b), np.asarray(lengths, dtype=float)))
    return np.asarray(variance * (1.0 + _SQRT5 * r + 5.0 / 3.0 * r * r) * np.exp(-_SQRT5 * r))


@dataclass(frozen=True, eq=False)
class ScalarGP:
    """A fitted GP of one scalar (see the module notes).

    Attributes
    ----------
    x
        Normalised inputs of the runs, shape ``(n, k)``.
    y
        The scalar at each run, shape ``(n,)``.
    centre, scale
        Mean and standard deviation of ``y`` (the standardisation).
    lengths
        ARD length scales on ``[0, 1]``, shape ``(k,)``.
    variance, nugget
        Signal and nugget variances of the standardised scalar.
    beta
        GLS constant of the standardised scalar.
    log_likelihood
        Log marginal likelihood at the fitted hyperparameters (standardised scale).
    """

    x: np.ndarray
    y: np.ndarray
    centre: float
    scale: float
    lengths: np.ndarray
    variance: float
    nugget: float
    beta: float
    log_likelihood: float
    _chol: tuple[np.ndarray, bool] = field(init=False, repr=False)
    _alpha: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cov = matern52(self.x, self.x, self.lengths, self.variance)
        cov[np.diag_indices_from(cov)] += self.nugget + _JITTER
        chol = linalg.cho_factor(cov, lower=True)
        z = (self.y - self.centre) / self.scale
        object.__setattr__(self, "_chol", chol)
        object.__setattr__(self, "_alpha", linalg.cho_solve(chol, z - self.beta))

    @property
    def runs(self) -> int:
        """Number of runs ``n``."""
        return int(self.y.size)

    def predict(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and variance of ``beta + f`` at ``points`` (the scalar's unit)."""
        cross = matern52(points, self.x, self.lengths, self.variance)
        mean = self.beta + cross @ self._alpha
        solved = linalg.cho_solve(self._chol, cross.T)
        var = np.maximum(self.variance - np.einsum("ij,ji->i", cross, solved), 0.0)
        return self.centre + self.scale * mean, self.scale**2 * var

    def loo(self) -> tuple[np.ndarray, np.ndarray]:
        """Leave-one-out predictive means and variances of ``y`` at the runs (fixed
        hyperparameters and ``beta``; eq. 5.12 of Rasmussen & Williams 2006)."""
        inverse = linalg.cho_solve(self._chol, np.eye(self.runs))
        diag = np.diag(inverse)
        mean = self.y - self.scale * self._alpha / diag
        return mean, self.scale**2 / diag

    @property
    def q2(self) -> float:
        """``1 - sum (y - loo)^2 / sum (y - mean y)^2``: 1 is perfect, 0 no better than the mean."""
        mean, _ = self.loo()
        total = float(np.sum((self.y - self.y.mean()) ** 2))
        return 1.0 - float(np.sum((self.y - mean) ** 2)) / total if total > 0 else math.nan

    @property
    def loo_rmse(self) -> float:
        """Root mean squared leave-one-out error, in the scalar's unit."""
        mean, _ = self.loo()
        return float(np.sqrt(np.mean((self.y - mean) ** 2)))

    def sample_paths(
        self,
        points: np.ndarray,
        paths: int,
        rng: np.random.Generator,
        *,
        features: int = 2000,
        chunk: int = 4096,
    ) -> np.ndarray:
        """Joint posterior draws of ``beta + f`` at ``points``, shape ``(paths, m)``.

        Pathwise conditioning on random Fourier features (see the module notes);
        the paths share the ``features`` frequencies and differ in their weights
        (the features' error in the prior covariance is common to them).
        """
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        k = self.x.shape[1]
        out = np.empty((paths, pts.shape[0]))
        amp = math.sqrt(2.0 * self.variance / features)
        z = (self.y - self.centre) / self.scale
        chi = rng.chisquare(5.0, size=(features, 1))
        omega = rng.standard_normal((features, k)) / np.sqrt(chi / 5.0) / self.lengths
        phase = rng.uniform(0.0, 2.0 * math.pi, size=features)
        weights = amp * rng.standard_normal((features, paths))
        noise = rng.standard_normal((self.runs, paths)) * math.sqrt(self.nugget + _JITTER)
        prior_at_runs = _fourier(self.x, omega, phase, weights)
        update = linalg.cho_solve(self._chol, z[:, None] - self.beta - prior_at_runs - noise)
        for a in range(0, pts.shape[0], chunk):
            block = pts[a : a + chunk]
            cross = matern52(block, self.x, self.lengths, self.variance)
            prior = _fourier(block, omega, phase, weights)
            out[:, a : a + chunk] = (self.beta + prior + cross @ update).T
        return self.centre + self.scale * out


def _fourier(
    u: np.ndarray, omega: np.ndarray, phase: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Prior paths from random Fourier features: ``sum_j w_js cos(omega_j . u + phase_j)``,
    one column per column of ``weights``."""
    return np.asarray(np.cos(u @ omega.T + phase) @ weights)


def _objective(theta: np.ndarray, x: np.ndarray, z: np.ndarray) -> tuple[float, np.ndarray]:
    """Negative log marginal likelihood (beta profiled out) and its gradient in ``theta =
    [log l_1..k, log s2, log n2]``."""
    n, k = x.shape
    lengths, signal, nugget = np.exp(theta[:k]), math.exp(theta[k]), math.exp(theta[k + 1])
    r = np.sqrt(_sq_dist(x, x, lengths))
    decay = np.exp(-_SQRT5 * r)
    corr = (1.0 + _SQRT5 * r + 5.0 / 3.0 * r * r) * decay
    cov = signal * corr
    cov[np.diag_indices(n)] += nugget + _JITTER
    try:
        chol = linalg.cho_factor(cov, lower=True)
    except linalg.LinAlgError:
        return 1e25, np.zeros_like(theta)
    ones = np.ones(n)
    k1, kz = linalg.cho_solve(chol, ones), linalg.cho_solve(chol, z)
    beta = float(ones @ kz) / float(ones @ k1)
    alpha = kz - beta * k1
    logdet = 2.0 * float(np.sum(np.log(np.diag(chol[0]))))
    value = 0.5 * float((z - beta) @ alpha) + 0.5 * logdet + 0.5 * n * math.log(2 * math.pi)
    w = linalg.cho_solve(chol, np.eye(n)) - np.outer(alpha, alpha)
    grad = np.empty_like(theta)
    shape = signal * 5.0 / 3.0 * (1.0 + _SQRT5 * r) * decay * w  # dK/dr^2-type factor, times W
    for i in range(k):
        diff = (x[:, i, None] - x[None, :, i]) ** 2 / lengths[i] ** 2
        grad[i] = 0.5 * float(np.sum(shape * diff))
    grad[k] = 0.5 * float(np.sum(w * cov)) - 0.5 * (nugget + _JITTER) * float(np.trace(w))
    grad[k + 1] = 0.5 * nugget * float(np.trace(w))
    return value, grad


def fit_scalar_gp(x: np.ndarray, y: np.ndarray, *, restarts: int = 4, seed: int = 0) -> ScalarGP:
    """Fit the GP of ``y`` at ``x`` by maximum marginal likelihood (see the module notes).

    Parameters
    ----------
    x
        Normalised inputs, shape ``(n, k)``, in ``[0, 1]``.
    y
        Finite scalars, shape ``(n,)``, not all equal.
    restarts
        Random starts besides the default one (length scales 0.5).
    seed
        Seed of the random starts.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    n, k = x.shape
    if y.shape != (n,) or not np.all(np.isfinite(y)):
        raise ValueError(f"y must be {n} finite values, got shape {y.shape}")
    centre, scale = float(y.mean()), float(y.std())
    if not scale > 0:
        raise ValueError("y is constant: there is nothing to fit")
    z = (y - centre) / scale
    rng = np.random.default_rng(seed)
    starts = [np.r_[np.full(k, math.log(0.5)), 0.0, math.log(1e-4)]]
    for _ in range(restarts):
        starts.append(
            np.r_[
                rng.uniform(math.log(0.1), math.log(2.0), k),
                rng.uniform(math.log(0.3), math.log(3.0)),
                rng.uniform(math.log(1e-6), math.log(1e-2)),
            ]
        )
    bounds = [_LOG_LENGTH] * k + [_LOG_SIGNAL, _LOG_NUGGET]
    best: optimize.OptimizeResult | None = None
    for start in starts:
        found = optimize.minimize(
            _objective, start, args=(x, z), jac=True, method="L-BFGS-B", bounds=bounds
        )
        if best is None or found.fun < best.fun:
            best = found
    assert best is not None
    theta = np.asarray(best.x, dtype=float)
    lengths, signal, nugget = np.exp(theta[:k]), math.exp(theta[k]), math.exp(theta[k + 1])
    cov = matern52(x, x, lengths, signal)
    cov[np.diag_indices(n)] += nugget + _JITTER
    chol = linalg.cho_factor(cov, lower=True)
    ones = np.ones(n)
    beta = float(ones @ linalg.cho_solve(chol, z)) / float(ones @ linalg.cho_solve(chol, ones))
    return ScalarGP(
        x=x,
        y=y,
        centre=centre,
        scale=scale,
        lengths=lengths,
        variance=signal,
        nugget=nugget,
        beta=beta,
        log_likelihood=-float(best.fun),
    )
