"""Block random-walk Metropolis with Haario-adaptive covariance during burn-in.

All free coordinates move together: ``z' = z + L e`` with ``e ~ N(0, I)`` and
``L L^T = exp(2 g) (2.38^2 / d) C`` on the sampling scale. During burn-in,
after every batch of ``batch_size`` iterations:

* ``C`` becomes the empirical covariance of the burn-in states so far plus
  ``jitter * mean(diag)`` on the diagonal (Haario, Saksman & Tamminen 2001),
  once ``n_initial`` iterations have passed and every free coordinate has
  moved; before that it is the diagonal of the initial scales squared;
* the global log-scale ``g`` moves by ``min(max_adapt, n**-0.5)`` towards the
  ``target`` acceptance rate (0.234, Roberts, Gelman & Gilks 1997; 0.44 when
  one coordinate is free), as in Andrieu & Thoms (2008), algorithm 4.

After burn-in ``L`` is frozen. Useful for a few strongly correlated
parameters, where one-coordinate-at-a-time updates crawl.

References: H. Haario, E. Saksman, J. Tamminen (2001), "An adaptive Metropolis
algorithm", Bernoulli 7(2), 223-242; C. Andrieu, J. Thoms (2008), "A tutorial
on adaptive MCMC", Stat. Comput. 18, 343-373.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.errors import ConfigError
from bayescal.mcmc.samplers.base import (
    BoundsMethod,
    Box,
    Callback,
    LogDensity,
    SamplerResult,
    adaptation_step,
    check_log_density,
    check_run_args,
    fixed_mask,
    initial_scales,
)

_INF = math.inf


@dataclass
class _Chain:
    """Mutable state of one run on the free coordinates' sampling scale."""

    z: NDArray[np.float64]
    x: NDArray[np.float64]
    log_jac: float
    lp: float
    chol: NDArray[np.float64]
    accepted: int = 0


@dataclass
class _Moments:
    """Running mean and scatter matrix (Welford) of the burn-in states."""

    n: int
    mean: NDArray[np.float64]
    scatter: NDArray[np.float64]

    def add(self, z: NDArray[np.float64]) -> None:
        self.n += 1
        delta = z - self.mean
        self.mean += delta / self.n
        self.scatter += np.outer(delta, z - self.mean)

    def cov(self) -> NDArray[np.float64]:
        return self.scatter / max(self.n - 1, 1)


@dataclass(frozen=True)
class AdaptiveMetropolis:
    """Block random-walk Metropolis, covariance adapted during burn-in only.

    Parameters
    ----------
    n_burn
        Burn-in iterations, adapted and discarded.
    thin
        Iterations per kept draw.
    lower, upper
        Bounds per coordinate on the original scale (``None``/``inf`` for none).
    bounds
        ``"transform"`` (default) or ``"reflect"`` (see
        :mod:`bayescal.mcmc.samplers.base`).
    fixed
        Boolean mask (d,) or indices of coordinates that keep their start value.
    scales
        Initial proposal standard deviations on the sampling scale (scalar or
        (d,)); same defaults as :class:`MetropolisWithinGibbs`.
    target
        Acceptance rate the global scale aims at; default 0.234 (0.44 if one
        coordinate is free).
    batch_size
        Iterations between adaptations.
    max_adapt
        Cap of the per-batch change of the global log-scale.
    n_initial
        Burn-in iterations before the empirical covariance is used; default
        ``max(200, 20 d)``.
    jitter
        Relative ridge added to the empirical covariance.
    """

    n_burn: int = 2000
    thin: int = 1
    lower: Sequence[float] | None = None
    upper: Sequence[float] | None = None
    bounds: BoundsMethod = "transform"
    fixed: Sequence[bool] | Sequence[int] | None = None
    scales: float | Sequence[float] | None = None
    target: float | None = None
    batch_size: int = 50
    max_adapt: float = 0.1
    n_initial: int | None = None
    jitter: float = 1e-8

    def __post_init__(self) -> None:
        check_run_args(1, self.n_burn, self.thin)
        if self.target is not None and not 0.0 < self.target < 1.0:
            raise ConfigError(f"target acceptance must lie in (0, 1), got {self.target!r}")
        if int(self.batch_size) != self.batch_size or self.batch_size < 1:
            raise ConfigError(f"batch_size must be a positive integer, got {self.batch_size!r}")
        if not self.max_adapt > 0.0:
            raise ConfigError(f"max_adapt must be positive, got {self.max_adapt!r}")

    def run(
        self,
        log_density: LogDensity,
        x0: ArrayLike,
        n_draws: int,
        rng: np.random.Generator,
        callback: Callback | None = None,
    ) -> SamplerResult:
        """Run one chain; arguments and result as :meth:`MetropolisWithinGibbs.run`."""
        check_run_args(n_draws, self.n_burn, self.thin)
        n_draws = int(n_draws)
        rng_state = copy.deepcopy(rng.bit_generator.state)
        x = np.array(x0, dtype=float).reshape(-1)
        d = x.size
        box = Box.build(d, self.lower, self.upper, self.bounds)
        box.check_start(x)
        free = np.flatnonzero(~fixed_mask(self.fixed, d))
        scales = initial_scales(self.scales, box)[free]
        chain = self._start(log_density, x, box, free, scales)
        target = self.target if self.target is not None else (0.44 if free.size == 1 else 0.234)
        moments = _Moments(0, np.zeros(free.size), np.zeros((free.size, free.size)))
        n_initial = self.n_initial if self.n_initial is not None else max(200, 20 * d)
        log_g, cov = 0.0, np.diag(scales**2)
        step = _Stepper(
            log_density, box, free, np.flatnonzero(~np.isin(np.arange(d), free)), callback
        )

        n_done, n_batch = 0, 0
        while n_done < self.n_burn:
            size = min(self.batch_size, self.n_burn - n_done)
            chain.accepted = 0
            step.iterate(chain, rng, size, n_done, moments=moments)
            n_done += size
            n_batch += 1
            delta = adaptation_step(n_batch, self.max_adapt)
            log_g += delta if chain.accepted > target * size else -delta
            if n_done >= n_initial and np.all(np.diag(moments.cov()) > 0):
                cov = moments.cov()
            chain.chol = self._cholesky(cov, log_g, free.size)

        chain.accepted = 0
        draws, lps = step.iterate(chain, rng, n_draws * self.thin, n_done, keep=self.thin)
        acceptance = np.full(d, np.nan)
        acceptance[free] = chain.accepted / (n_draws * self.thin)
        proposal = np.zeros((d, d))
        proposal[np.ix_(free, free)] = chain.chol @ chain.chol.T
        return SamplerResult(
            draws=draws,
            log_density=lps,
            acceptance=acceptance,
            scales=np.sqrt(np.diag(proposal)),
            rng_state=rng_state,
            n_burn=self.n_burn,
            thin=self.thin,
            proposal_cov=proposal,
        )

    def _start(
        self,
        log_density: LogDensity,
        x: NDArray[np.float64],
        box: Box,
        free: NDArray[np.intp],
        scales: NDArray[np.float64],
    ) -> _Chain:
        lp = check_log_density(log_density(x), x)
        if lp == -_INF:
            raise ConfigError(
                f"log-density is -inf at the starting point {np.array2string(x, precision=6)}",
                hint="start inside the support of the prior and likelihood",
            )
        z = box.to_sampling(x)
        log_jac = box.to_original(z)[1] if box.transforms else 0.0
        chol = self._cholesky(np.diag(scales**2), 0.0, free.size, scaled=False)
        return _Chain(z, x, log_jac, lp, chol)

    def _cholesky(
        self, cov: NDArray[np.float64], log_g: float, n_free: int, scaled: bool = True
    ) -> NDArray[np.float64]:
        factor = math.exp(2.0 * log_g) * (2.38**2 / n_free if scaled else 1.0)
        ridge = self.jitter * float(np.mean(np.diag(cov)))
        chol = np.linalg.cholesky(factor * (cov + ridge * np.eye(n_free)))
        return np.asarray(chol, dtype=np.float64)


@dataclass(frozen=True)
class _Stepper:
    """One Metropolis step after another with the current Cholesky factor."""

    log_density: LogDensity
    box: Box
    free: NDArray[np.intp]
    fixed: NDArray[np.intp]
    callback: Callback | None

    def iterate(
        self,
        c: _Chain,
        rng: np.random.Generator,
        size: int,
        n_done: int,
        moments: _Moments | None = None,
        keep: int = 0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Run ``size`` iterations; record burn-in moments, or keep every ``keep``-th."""
        eps = rng.standard_normal((size, self.free.size)) @ c.chol.T
        log_u = np.log1p(-rng.random(size))
        n_keep = size // keep if keep else 0
        draws = np.empty((n_keep, c.x.size))
        lps = np.empty(n_keep)
        for it in range(size):
            self._step(c, eps[it], float(log_u[it]))
            if moments is not None:
                moments.add(c.z[self.free])
            if keep and (it + 1) % keep == 0:
                draws[(it + 1) // keep - 1] = c.x
                lps[(it + 1) // keep - 1] = c.lp
            if self.callback is not None:
                self.callback(n_done + it + 1)
        return draws, lps

    def _step(self, c: _Chain, e: NDArray[np.float64], log_u: float) -> None:
        z_new = c.z.copy()
        z_new[self.free] += e
        try:
            x_new, log_jac = self.box.to_original(z_new)
        except OverflowError:
            return
        x_new[self.fixed] = c.x[self.fixed]
        if not self.box.transforms:
            z_new = x_new
        lp_new = self.log_density(x_new)
        if not lp_new < _INF:
            check_log_density(lp_new, x_new)
        if log_u < lp_new + log_jac - c.lp - c.log_jac:
            c.z, c.x, c.lp, c.log_jac = z_new, x_new, lp_new, log_jac
            c.accepted += 1
