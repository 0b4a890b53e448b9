"""The calibration target of eq. 16 and how to sample it, without diagnostics.

With the emulator's hyperparameters fixed at their MAP, the stacked weights
``v_j = [w_j; w*_j]`` are ``N(0, Omega_j)`` (eqs. 12, 14, 17). The sampled
vector is ``[u_1 .. u_t, lambda, lambda*]`` where ``u`` is ``theta*`` on the
normalised scale [0, 1] of the prior bounds; the log posterior adds the prior
terms of :mod:`bayescal.calibration.priors`.

For people who script bayescal (``calibrate`` does all of this and adds
diagnostics)::

    target = build_target(emulator, assembled.w_star, assembled.lam_star_prior, priors)
    chains = sample(target, n_draws=2000, n_burn=1000, seed=1, backend="vectorised")
    chains.draws            # (chains, draws, t + 2): [u, lambda, lambda*]

Everything :func:`build_target` needs is in the emulator artefact and the
priors, so a calibration can be rebuilt from the saved files alone.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.calibration.batch import BatchSession
from bayescal.calibration.grid import StackedGrid
from bayescal.calibration.kron import CalibrationAlgebra, Kind, make_algebra
from bayescal.calibration.priors import CalibrationPriors
from bayescal.design import Prior
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import FloatArray
from bayescal.errors import ConfigError
from bayescal.mcmc.chains import ChainBackend, Chains, dispersed_starts, run_chains
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs

__all__ = [
    "LAMBDA_NAMES",
    "BatchedPosterior",
    "CalibrationPosterior",
    "build_target",
    "default_sampler",
    "default_starts",
    "emulator_algebra",
    "sample",
]

LAMBDA_NAMES = ("lambda", "lambda_star")
BoolArray = NDArray[np.bool_]


class CalibrationPosterior:
    """Log posterior of eq. 16 at ``[u_1 .. u_t, lambda, lambda*]``, up to a constant.

    Picklable (for chains in worker processes). Non-positive-definite
    covariances count as zero density. Offers its lockstep form
    (:meth:`lockstep`) for chains run together.

    Parameters
    ----------
    algebra
        Likelihood back end (Kronecker or dense) built with the MAP kernels.
    priors
        One prior per parameter, in the order of ``u``.
    lam_prior, lam_star_prior
        ``(shape, rate)`` of the Gamma priors of ``lambda`` and ``lambda*``.
    """

    def __init__(
        self,
        algebra: CalibrationAlgebra,
        priors: Sequence[Prior],
        lam_prior: tuple[float, float],
        lam_star_prior: tuple[float, float],
    ) -> None:
        self.algebra = algebra
        self.prior_terms = CalibrationPriors(tuple(priors), lam_prior, lam_star_prior)
        self.t = self.prior_terms.t

    @property
    def priors(self) -> tuple[Prior, ...]:
        """The priors of theta*, in the order of ``u``."""
        return self.prior_terms.theta

    @property
    def lam_prior(self) -> tuple[float, float]:
        """``(shape, rate)`` of the Gamma prior of ``lambda``."""
        return self.prior_terms.lam

    @property
    def lam_star_prior(self) -> tuple[float, float]:
        """``(shape, rate)`` of the Gamma prior of ``lambda*``."""
        return self.prior_terms.lam_star

    def grid(self) -> StackedGrid:
        """The fixed arrays of eq. 16 (the JAX route needs the Kronecker back end)."""
        grid = self.algebra.stacked_grid()
        if grid is None:
            raise ConfigError(
                "this calibration target has no stacked grid (dense algebra)",
                hint="use algebra 'kronecker'",
            )
        return grid

    def log_prior(self, v: ArrayLike) -> float:
        """Log prior density of ``[u, lambda, lambda*]`` (up to a constant)."""
        return self.prior_terms.scalar(v)

    def __call__(self, v: ArrayLike) -> float:
        """Log posterior (eq. 16) at ``v = [u_1 .. u_t, lambda, lambda*]``."""
        arr = np.asarray(v, dtype=float)
        prior = self.log_prior(arr)
        if prior == -math.inf:
            return prior
        try:
            lik = self.algebra.logpdf(arr[: self.t], float(arr[self.t]), float(arr[self.t + 1]))
        except np.linalg.LinAlgError:
            return -math.inf
        return prior + lik

    def lockstep(self) -> BatchedPosterior:
        """The same log posterior for ``B`` chains in lockstep (batched likelihood)."""
        return BatchedPosterior(self.algebra, self.prior_terms)


class BatchedPosterior:
    """Batched log posterior of eq. 16 at rows ``[u_1 .. u_t, lambda, lambda*]``.

    Equal to :class:`~bayescal.calibration.posterior.CalibrationPosterior` on
    each row, up to rounding. The likelihood goes through
    ``algebra.logpdf_batch``. Rows outside the prior support, and rows whose
    covariance is not positive definite, get ``-inf``. As a
    :class:`~bayescal.mcmc.samplers.lockstep.LockstepTarget` it keeps a
    :class:`BatchSession` of the chains' current points where the back end
    offers one (``algebra.batch_session``), else it evaluates every row.

    Parameters
    ----------
    algebra
        The likelihood back end.
    priors
        The priors of ``[u, lambda, lambda*]``.
    """

    def __init__(self, algebra: CalibrationAlgebra, priors: CalibrationPriors) -> None:
        self.algebra = algebra
        self.priors = priors
        self.t = priors.t
        self._session: BatchSession | None = None
        self._pending_terms: FloatArray | None = None
        self._prior_terms = np.zeros((0, self.t + 2))

    def start(self, points: FloatArray) -> FloatArray:
        """Log posterior at the starting points; they become the current points."""
        arr = np.array(points, dtype=float)
        t = self.t
        prior = self.priors.batch(arr)
        self._session = None
        if np.all(prior > -math.inf):
            self._session = self.algebra.batch_session(arr[:, :t], arr[:, t], arr[:, t + 1])
        if self._session is None:
            return self(arr)
        self._prior_terms = np.column_stack([self.priors.term(arr[:, k], k) for k in range(t + 2)])
        out: FloatArray = prior + np.where(self._session.ok, self._session.values, -math.inf)
        return out

    def propose(self, points: FloatArray, coordinate: int) -> FloatArray:
        """Log posterior with ``coordinate`` of the current points replaced."""
        session, t = self._session, self.t
        if session is None:
            return self(points)
        terms = self._prior_terms.copy()
        terms[:, coordinate] = self.priors.term(points[:, coordinate], coordinate)
        prior = terms.sum(axis=1)
        if coordinate < t:
            values, ok = session.propose_theta(points[:, :t])
        else:
            # Rows outside the prior are evaluated at their current precision (-inf anyway).
            column = points[:, coordinate]
            current = session.lam if coordinate == t else session.lam_star
            moved = np.where(column > 0.0, column, current)
            move = session.propose_lam if coordinate == t else session.propose_lam_star
            values, ok = move(moved)
        self._pending_terms = terms
        out: FloatArray = prior + np.where(ok, values, -math.inf)
        return out

    def commit(self, accept: BoolArray) -> None:
        """Take over the accepted rows of the last proposal."""
        terms = self._pending_terms
        if self._session is None or terms is None:
            return
        self._pending_terms = None
        self._session.commit(accept)
        self._prior_terms[accept] = terms[accept]

    def log_prior(self, points: FloatArray) -> FloatArray:
        """Log prior density per row ``(B,)`` (up to a constant)."""
        return self.priors.batch(points)

    def __call__(self, points: FloatArray) -> FloatArray:
        """Log posterior per row of ``points`` ``(B, t + 2)``."""
        arr = np.asarray(points, dtype=float)
        prior = self.log_prior(arr)
        inside = prior > -math.inf
        lik = np.full(arr.shape[0], -math.inf)
        if inside.any():
            rows = arr if inside.all() else arr[inside]
            lik[inside] = self._likelihood(rows)
        return prior + lik

    def _likelihood(self, rows: FloatArray) -> FloatArray:
        t = self.t
        return self.algebra.logpdf_batch(rows[:, :t], rows[:, t], rows[:, t + 1], errors="-inf")


def build_target(
    emulator: Emulator,
    w_star: ArrayLike,
    lam_star_prior: tuple[float, float],
    priors: Sequence[Prior],
    *,
    algebra: Kind = "kronecker",
) -> CalibrationPosterior:
    """The calibration log posterior from the emulator and the observed weights.

    Parameters
    ----------
    emulator
        The trained emulator (kernels at the MAP, design, conditions, weights,
        the ``lambda`` prior).
    w_star
        Observed weights ``W*`` of the training periods ``(m*, p)`` (eq. 13). [-]
    lam_star_prior
        ``(shape, rate)`` of the Gamma prior of ``lambda*`` (eq. 7 for ``Y*``).
    priors
        The theta* priors on the design's bounds, in the emulator's parameter order.
    algebra
        ``"kronecker"`` (fast, default) or ``"dense"`` (reference).
    """
    if len(priors) != len(emulator.parameter_names):
        raise ConfigError(
            f"got {len(priors)} priors for the emulator's {len(emulator.parameter_names)} "
            f"parameters {list(emulator.parameter_names)}"
        )
    alg = emulator_algebra(emulator, w_star, algebra)
    return CalibrationPosterior(alg, priors, emulator.lam_prior, lam_star_prior)


def emulator_algebra(
    emulator: Emulator, w_star: ArrayLike, kind: Kind = "kronecker"
) -> CalibrationAlgebra:
    """The back end of eq. 12 from a trained emulator and observed weights ``(m*, p)``."""
    return make_algebra(
        kind,
        emulator.theta,
        emulator.x,
        emulator.kernels,
        emulator.basis.ktk,
        emulator.w,
        w_star,
    )


def default_sampler(target: CalibrationPosterior, n_burn: int) -> MetropolisWithinGibbs:
    """Metropolis-within-Gibbs as ``calibrate`` configures it for ``target``."""
    t = target.t
    lower = [0.0] * (t + 2)
    upper = [1.0] * t + [math.inf, math.inf]
    # Logit-scale widths for theta*, ~2.4 prior log-sd for the sharply known precisions.
    scales = [0.5] * t + [
        2.4 / math.sqrt(target.lam_prior[0]),
        2.4 / math.sqrt(target.lam_star_prior[0]),
    ]
    # Short batches and a generous cap: the widths of sharply identified
    # parameters must shrink by ~e^3 within a burn-in of a few hundred sweeps.
    return MetropolisWithinGibbs(
        n_burn=n_burn, lower=lower, upper=upper, scales=scales, batch_size=25, max_adapt=0.25
    )


def default_starts(target: CalibrationPosterior, n_chains: int, seed: int) -> FloatArray:
    """Dispersed starts: theta* by strata in [0.05, 0.95], precisions from their priors.

    The generator is ``default_rng([seed, 2])``; theta* comes from
    :func:`bayescal.mcmc.chains.dispersed_starts`, then ``lambda`` and
    ``lambda*`` are drawn from their Gamma priors.
    """
    rng = np.random.default_rng([seed, 2])
    t = target.t
    u = dispersed_starts(np.zeros(t), np.ones(t), n_chains, rng)
    lam = rng.gamma(target.lam_prior[0], 1.0 / target.lam_prior[1], n_chains)
    lam_star = rng.gamma(target.lam_star_prior[0], 1.0 / target.lam_star_prior[1], n_chains)
    return np.column_stack([u, lam, lam_star])


def sample(
    target: CalibrationPosterior,
    n_draws: int,
    *,
    n_burn: int = 1000,
    n_chains: int = 4,
    seed: int = 0,
    backend: ChainBackend = "processes",
    names: Sequence[str] | None = None,
    callback: Callable[[int], None] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
    starts: ArrayLike | None = None,
    sampler: Any = None,
) -> Chains:
    """Metropolis-within-Gibbs sweeps of ``target``, no diagnostics.

    Parameters
    ----------
    target
        From :func:`build_target`.
    n_draws, n_burn, n_chains, seed
        Kept draws and burn-in sweeps per chain, chains, root seed.
    backend
        ``"processes"``, ``"serial"`` or ``"vectorised"`` (lockstep, batched
        likelihood); see :func:`bayescal.mcmc.chains.run_chains`.
    names
        Coordinate names (default: ``x0, x1, ...``).
    callback, checkpoint_dir, checkpoint_seconds
        Progress and snapshots, as :func:`~bayescal.mcmc.chains.run_chains`.
    starts
        Starting points ``(n_chains, t + 2)``; default :func:`default_starts`.
    sampler
        Another sampler (default :func:`default_sampler`).

    Returns
    -------
    Chains
        Draws of ``[u, lambda, lambda*]``, ``(chains, draws, t + 2)``.
    """
    x0 = default_starts(target, n_chains, seed) if starts is None else starts
    return run_chains(
        default_sampler(target, n_burn) if sampler is None else sampler,
        target,
        x0,
        n_draws,
        seed=seed,
        names=names,
        backend=backend,
        callback=callback,
        checkpoint_dir=checkpoint_dir,
        checkpoint_seconds=checkpoint_seconds,
    )
