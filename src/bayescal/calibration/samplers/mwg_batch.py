"""Metropolis-within-Gibbs chains in lockstep: one batched log-density call per update.

:class:`~bayescal.calibration.samplers.mwg.MetropolisWithinGibbs` runs one
chain at a time and calls the log-density once per coordinate update; at the
paper's size (R = 30 runs x m* = 25 periods) one calibration evaluation costs
about as much as the Python around it. Here all ``B`` chains of a run advance
together: for each coordinate update the ``B`` proposals go to the target in
one call of a *batched* log-density ``f(X (B, d)) -> (B,)``.

Each chain keeps the semantics of the serial sampler exactly: the same
proposal scales, batches and adaptation rule (Roberts & Rosenthal 2009), the
same bounded-coordinate maps, and its own generator consumed in the same
order (per batch of iterations, ``standard_normal((size, n_active))`` then
``random((size, n_active))``). Given a batched log-density that returns, row
by row, the values the scalar one returns, chain ``k`` of a lockstep run is
bit-identical to the serial run of chain ``k``. When the two differ by
rounding only (the calibration likelihood: ~1e-15 relative), the draws are
still identical unless an acceptance test falls within that rounding of its
threshold, and the stored log-densities agree to rounding.

Targets. A plain batched log-density is called on all chains' points at
every update. A target may instead offer the lockstep protocol
(:class:`LockstepTarget`): ``start(X)`` at the starting points,
``propose(X, i)`` when ``X`` differs from the current points in coordinate
``i`` only, and ``commit(accept)`` with the chains that took their proposal;
it can then keep each chain's current pieces and recompute only what
coordinate ``i`` changes (:class:`BatchedPosterior` does, through
:class:`~bayescal.emulator.kron_batch.BatchSession`), as the scalar
likelihood's memos do for one chain.

A chain whose proposal overflows the sampling map (``OverflowError``, a
rejection in the serial sampler) is evaluated at its current point and
rejected.

Checkpoints (``checkpoint=``) are not offered for lockstep runs.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.calibration.samplers.base import (
    Box,
    Callback,
    LogDensity,
    SamplerResult,
    ScalarMap,
    adaptation_step,
    check_log_density,
    check_run_args,
    fixed_mask,
    initial_scales,
)
from bayescal.calibration.samplers.mwg import MetropolisWithinGibbs, _batch_sizes
from bayescal.errors import ConfigError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
BatchLogDensity = Callable[[FloatArray], FloatArray]
"""A batched log-density: points ``(B, d)`` on the original scale -> ``(B,)``."""


@runtime_checkable
class LockstepTarget(Protocol):
    """A batched target that follows the chains' current points (module docstring).

    None of the methods may keep the array it is given.
    """

    def start(self, points: FloatArray) -> FloatArray:
        """Log-densities ``(B,)`` at the starting points ``(B, d)``, made current."""
        ...

    def propose(self, points: FloatArray, coordinate: int) -> FloatArray:
        """Log-densities ``(B,)`` at the current points with ``coordinate`` replaced."""
        ...

    def commit(self, accept: BoolArray) -> None:
        """The rows of the last proposal where ``accept`` become current."""
        ...


@dataclass(frozen=True)
class Stateless:
    """The lockstep protocol for a plain batched log-density (every call evaluates all).

    Parameters
    ----------
    log_density
        Batched log-density ``(B, d) -> (B,)``.
    """

    log_density: BatchLogDensity

    def start(self, points: FloatArray) -> FloatArray:
        """Log-densities at the starting points."""
        return np.asarray(self.log_density(points), dtype=float)

    def propose(self, points: FloatArray, coordinate: int) -> FloatArray:
        """Log-densities at the proposals (``coordinate`` is not used)."""
        return np.asarray(self.log_density(points), dtype=float)

    def commit(self, accept: BoolArray) -> None:
        """Nothing to keep."""


_INF = math.inf


@dataclass(frozen=True)
class RowLoop:
    """A batched log-density from a scalar one: one call per row (no speed-up there).

    Parameters
    ----------
    log_density
        The scalar log-density ``x (d,) -> float``.
    """

    log_density: LogDensity

    def __call__(self, points: FloatArray) -> FloatArray:
        """Log-densities of the rows of ``points`` ``(B, d)``."""
        return np.array([self.log_density(row.copy()) for row in points], dtype=float)


def as_lockstep(log_density: Any) -> LockstepTarget:
    """The lockstep form of a log-density.

    A :class:`LockstepTarget` as it is; a
    :class:`~bayescal.calibration.posterior.CalibrationPosterior` wrapped in
    :class:`BatchedPosterior`; an object with a ``batch`` method (points
    ``(B, d)`` -> ``(B,)``) through that method; anything else looped over
    rows (:class:`RowLoop`).
    """
    if isinstance(log_density, LockstepTarget):
        return log_density
    from bayescal.calibration.posterior import CalibrationPosterior

    if isinstance(log_density, CalibrationPosterior):
        return BatchedPosterior(log_density)
    batch = getattr(log_density, "batch", None)
    if callable(batch):
        return Stateless(batch)
    return Stateless(RowLoop(log_density))


class BatchedPosterior:
    """Batched log posterior of eq. 16 at rows ``[u_1 .. u_t, lambda, lambda*]``.

    Built from the public attributes of a
    :class:`~bayescal.calibration.posterior.CalibrationPosterior` (``algebra``,
    ``priors``, ``t``, ``lam_prior``, ``lam_star_prior``); equal to calling it
    on each row, up to rounding. The likelihood goes through
    ``algebra.logpdf_batch`` where the back end has it (Kronecker), else a loop.
    Rows outside the prior support, and rows whose covariance is not positive
    definite, get ``-inf``. As a :class:`LockstepTarget` it keeps a
    :class:`~bayescal.emulator.kron_batch.BatchSession` of the chains' current
    points where the back end offers one (``algebra.batch_session``).

    Parameters
    ----------
    target
        The scalar posterior.
    """

    def __init__(self, target: Any) -> None:
        from bayescal.design import UniformPrior

        self.target = target
        self.t = int(target.t)
        gammas = (target.lam_prior, target.lam_star_prior)
        self.shape_m1 = np.array([float(g[0]) - 1.0 for g in gammas])
        self.rate = np.array([float(g[1]) for g in gammas])
        priors = list(target.priors)
        self.uniform = [k for k, p in enumerate(priors) if type(p) is UniformPrior]
        self.other = [(k, p) for k, p in enumerate(priors) if type(p) is not UniformPrior]
        self._session: Any = None
        self._precisions = np.zeros((0, 2))
        self._pending: tuple[int, FloatArray, FloatArray, BoolArray, FloatArray] | None = None
        self._prior_terms = np.zeros((0, self.t + 2))

    def prior_term(self, column: FloatArray, k: int) -> FloatArray:
        """Log prior of coordinate ``k`` at the values ``column`` ``(B,)``."""
        t = self.t
        if k >= t:
            shape_m1, rate = float(self.shape_m1[k - t]), float(self.rate[k - t])
            if column.min() > 0.0:
                out: FloatArray = shape_m1 * np.log(column) - rate * column
                return out
            return _log_gamma(column, shape_m1, rate)
        if k in self.uniform:
            if column.min() >= 0.0 and column.max() <= 1.0:
                return np.zeros(column.shape)
            return np.where((column >= 0.0) & (column <= 1.0), 0.0, -_INF)
        return np.asarray(self.target.priors[k].logpdf_unit(column), dtype=float)

    def start(self, points: FloatArray) -> FloatArray:
        """Log posterior at the starting points; they become the current points."""
        arr = np.array(points, dtype=float)
        t = self.t
        prior = self.log_prior(arr)
        make = getattr(self.target.algebra, "batch_session", None)
        self._session = None
        if make is not None and np.all(prior > -_INF):
            self._session = make(arr[:, :t], arr[:, t], arr[:, t + 1])
        if self._session is None:
            return self(arr)
        self._precisions = arr[:, t : t + 2].copy()
        self._prior_terms = np.column_stack([self.prior_term(arr[:, k], k) for k in range(t + 2)])
        out: FloatArray = prior + np.where(self._session.ok, self._session.values, -_INF)
        return out

    def propose(self, points: FloatArray, coordinate: int) -> FloatArray:
        """Log posterior with ``coordinate`` of the current points replaced."""
        session, t = self._session, self.t
        if session is None:
            return self(points)
        terms = self._prior_terms.copy()
        terms[:, coordinate] = self.prior_term(points[:, coordinate], coordinate)
        prior = terms.sum(axis=1)
        if coordinate < t:
            moved = points[:, :t]
            values, ok = session.propose_theta(moved)
        else:
            # Rows outside the prior are evaluated at their current precision (-inf anyway).
            column = points[:, coordinate]
            moved = np.where(column > 0.0, column, self._precisions[:, coordinate - t])
            move = session.propose_lam if coordinate == t else session.propose_lam_star
            values, ok = move(moved)
        self._pending = (coordinate, moved, values, ok, terms)
        out: FloatArray = prior + np.where(ok, values, -_INF)
        return out

    def commit(self, accept: BoolArray) -> None:
        """Take over the accepted rows of the last proposal."""
        if self._session is None or self._pending is None:
            return
        coordinate, moved, values, ok, terms = self._pending
        self._pending = None
        self._session.commit(accept, values, ok)
        self._prior_terms[accept] = terms[accept]
        if coordinate >= self.t:
            column = self._precisions[:, coordinate - self.t]
            column[accept] = moved[accept]

    def log_prior(self, points: FloatArray) -> FloatArray:
        """Log prior density per row ``(B,)`` (up to a constant)."""
        t = self.t
        prec = points[:, t : t + 2]
        if prec.min() > 0.0:
            total = (self.shape_m1 * np.log(prec) - self.rate * prec).sum(axis=1)
        else:
            total = _log_gamma(prec[:, 0], self.shape_m1[0], self.rate[0])
            total += _log_gamma(prec[:, 1], self.shape_m1[1], self.rate[1])
        if self.uniform:
            u = points[:, self.uniform]
            inside = ((u >= 0.0) & (u <= 1.0)).all(axis=1)
            if not inside.all():
                total[~inside] = -_INF
        for k, prior in self.other:
            total += np.asarray(prior.logpdf_unit(points[:, k]), dtype=float)
        return total

    def __call__(self, points: FloatArray) -> FloatArray:
        """Log posterior per row of ``points`` ``(B, t + 2)``."""
        arr = np.asarray(points, dtype=float)
        prior = self.log_prior(arr)
        inside = prior > -_INF
        lik = np.full(arr.shape[0], -_INF)
        if inside.any():
            rows = arr if inside.all() else arr[inside]
            lik[inside] = self._likelihood(rows)
        return prior + lik

    def _likelihood(self, rows: FloatArray) -> FloatArray:
        t = self.t
        algebra = self.target.algebra
        if hasattr(algebra, "logpdf_batch"):
            out: FloatArray = algebra.logpdf_batch(
                rows[:, :t], rows[:, t], rows[:, t + 1], errors="-inf"
            )
            return out
        values = np.empty(rows.shape[0])
        for n, row in enumerate(rows):
            try:
                values[n] = algebra.logpdf(row[:t], float(row[t]), float(row[t + 1]))
            except np.linalg.LinAlgError:
                values[n] = -_INF
        return values


def _log_gamma(value: FloatArray, shape_m1: float, rate: float) -> FloatArray:
    """``(shape - 1) log x - rate x`` for ``x > 0``, ``-inf`` elsewhere."""
    positive = value > 0.0
    safe = np.where(positive, value, 1.0)
    return np.where(positive, shape_m1 * np.log(safe) - rate * safe, -_INF)


@dataclass
class _States:
    """All chains' states between blocks (mutated by the loop); rows are chains."""

    x: FloatArray  # (B, d) original scale
    z: FloatArray  # (B, d) sampling scale
    log_jac: FloatArray  # (B, d)
    lp: FloatArray  # (B,)
    scale: FloatArray  # (B, d)
    accepted: NDArray[np.int64]  # (B, d)


def run_lockstep(
    sampler: MetropolisWithinGibbs,
    log_density: LockstepTarget | BatchLogDensity,
    starts: ArrayLike,
    n_draws: int,
    rngs: Sequence[np.random.Generator],
    callback: Callback | None = None,
) -> list[SamplerResult]:
    """Run one chain per generator in lockstep (see the module docstring).

    Parameters
    ----------
    sampler
        The settings (burn-in, thinning, bounds, scales, adaptation).
    log_density
        A :class:`LockstepTarget`, or a batched log-density ``(B, d) -> (B,)``
        on the original scale; it must not keep the array it is given (the
        sampler modifies it in place).
    starts
        Starting points ``(B, d)``, one per chain.
    n_draws
        Draws to keep per chain after burn-in.
    rngs
        One generator per chain (their states at the start are recorded).
    callback
        Called after each sweep with the iterations completed over all chains
        (the total is ``B * (n_burn + n_draws * thin)``).

    Returns
    -------
    list of SamplerResult
        One per chain, as :meth:`MetropolisWithinGibbs.run` returns.
    """
    check_run_args(n_draws, sampler.n_burn, sampler.thin)
    n_draws = int(n_draws)
    x = np.array(starts, dtype=float)
    if x.ndim != 2 or x.shape[0] != len(rngs) or x.shape[0] < 1:
        raise ConfigError(
            f"starts must have shape (n_chains, d) with n_chains = {len(rngs)}, got {x.shape}"
        )
    rng_states = [copy.deepcopy(rng.bit_generator.state) for rng in rngs]
    target = log_density if isinstance(log_density, LockstepTarget) else Stateless(log_density)
    box = Box.build(x.shape[1], sampler.lower, sampler.upper, sampler.bounds)
    for row in x:
        box.check_start(row)
    active = np.flatnonzero(~fixed_mask(sampler.fixed, x.shape[1])).tolist()
    state = _initial_states(sampler, target, x, box)
    loop = _Lockstep(target, [box.scalar_map(i) for i in range(x.shape[1])], active, box)
    burn = _batch_sizes(sampler.n_burn, sampler.batch_size)
    batches = burn + _batch_sizes(n_draws * sampler.thin, sampler.batch_size)
    draws = np.empty((x.shape[0], n_draws, x.shape[1]))
    lps = np.empty((x.shape[0], n_draws))
    n_done, n_kept = 0, 0
    for index, size in enumerate(batches):
        if index < len(burn):
            state.accepted[:] = 0
            loop.block(state, rngs, size, n_done, callback)
            _adapt(sampler, state, size, active, index + 1)
            if index == len(burn) - 1:
                state.accepted[:] = 0
        else:
            if index == 0:
                state.accepted[:] = 0
            kept = loop.block(
                state, rngs, size, n_done, callback, sampler.thin, keep_start=sampler.n_burn
            )
            for xs, lp in kept:
                draws[:, n_kept], lps[:, n_kept] = xs, lp
                n_kept += 1
        n_done += size
    return _results(sampler, state, draws, lps, active, n_draws, rng_states)


def _initial_states(
    sampler: MetropolisWithinGibbs, target: LockstepTarget, x: FloatArray, box: Box
) -> _States:
    lp = np.asarray(target.start(x.copy()), dtype=float).reshape(-1)
    for k, value in enumerate(lp.tolist()):
        check_log_density(value, x[k])
        if value == -_INF:
            raise ConfigError(
                f"log-density is -inf at the starting point of chain {k}, "
                f"{np.array2string(x[k], precision=6)}",
                hint="start inside the support of the prior and likelihood",
            )
    z = np.array([box.to_sampling(row) for row in x])
    log_jac = np.zeros_like(x)
    if box.transforms:
        for i in range(x.shape[1]):
            f = box.scalar_map(i)
            if f is not None:
                log_jac[:, i] = [f(float(v))[1] for v in z[:, i]]
    scale = np.tile(initial_scales(sampler.scales, box), (x.shape[0], 1))
    accepted = np.zeros(x.shape, dtype=np.int64)
    return _States(x, z, log_jac, lp, scale, accepted)


def _adapt(
    sampler: MetropolisWithinGibbs, s: _States, size: int, active: list[int], n_batch: int
) -> None:
    """Per chain and coordinate, the serial sampler's rule (same float operations)."""
    step = adaptation_step(n_batch, sampler.max_adapt)
    factor_up, factor_down = math.exp(step), math.exp(-step)
    up = s.accepted[:, active] > sampler.target * size
    s.scale[:, active] *= np.where(up, factor_up, factor_down)


def _results(
    sampler: MetropolisWithinGibbs,
    s: _States,
    draws: FloatArray,
    lps: FloatArray,
    active: list[int],
    n_draws: int,
    rng_states: list[Any],
) -> list[SamplerResult]:
    results = []
    d = s.x.shape[1]
    for k in range(s.x.shape[0]):
        acceptance = np.full(d, np.nan)
        acceptance[active] = s.accepted[k, active] / (n_draws * sampler.thin)
        scales = np.zeros(d)
        scales[active] = s.scale[k, active]
        results.append(
            SamplerResult(
                draws=draws[k].copy(),
                log_density=lps[k].copy(),
                acceptance=acceptance,
                scales=scales,
                rng_state=rng_states[k],
                n_burn=sampler.n_burn,
                thin=sampler.thin,
            )
        )
    return results


def _map_column(f: ScalarMap, z: FloatArray) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Apply one coordinate's scalar map to every chain's proposal.

    Returns original-scale values, log-Jacobians and a mask of the chains whose
    map overflowed (rejected, as in the serial sampler). The scalar map itself,
    not a numpy version, so that the values are those of the serial sampler.
    """
    values = z.tolist()
    try:
        pairs = [f(v) for v in values]
    except OverflowError:
        pairs = []
        for v in values:
            try:
                pairs.append(f(v))
            except OverflowError:
                pairs.append((math.nan, math.nan))
    arr = np.array(pairs, dtype=float)
    overflow: NDArray[np.bool_] = np.isnan(arr[:, 0])
    return arr[:, 0], arr[:, 1], overflow


@dataclass(frozen=True)
class _Lockstep:
    """The inner loop over sweeps and coordinates, all chains at once."""

    target: LockstepTarget
    maps: list[ScalarMap | None]
    active: list[int]
    box: Box

    def block(
        self,
        s: _States,
        rngs: Sequence[np.random.Generator],
        size: int,
        n_done: int,
        callback: Callback | None,
        keep_every: int = 0,
        keep_start: int = 0,
    ) -> list[tuple[FloatArray, FloatArray]]:
        """Run ``size`` sweeps after ``n_done``; keep ``(x copy, lp copy)`` every
        ``keep_every`` iterations counted from ``keep_start`` (0: keep none)."""
        n_act = len(self.active)
        # Each chain's generator, consumed exactly as the serial sampler does.
        eps = np.stack([rng.standard_normal((size, n_act)) for rng in rngs], axis=2)
        log_u = np.stack([np.log1p(-rng.random((size, n_act))) for rng in rngs], axis=2)
        n_chains = len(rngs)
        kept: list[tuple[FloatArray, FloatArray]] = []
        for row in range(size):
            for k, i in enumerate(self.active):
                self._update(s, i, eps[row, k], log_u[row, k])
            done = n_done + row + 1
            if keep_every and (done - keep_start) % keep_every == 0:
                kept.append((s.x.copy(), s.lp.copy()))
            if callback is not None:
                callback(n_chains * done)
        return kept

    def _update(self, s: _States, i: int, eps: FloatArray, log_u: FloatArray) -> None:
        """One Metropolis update of coordinate ``i`` in every chain."""
        z_new = s.z[:, i] + s.scale[:, i] * eps
        f = self.maps[i]
        old = s.x[:, i].copy()
        if f is None:
            x_new, lj_new = z_new, np.zeros_like(z_new)
            overflow = None
        else:
            x_new, lj_new, overflow = _map_column(f, z_new)
            if not self.box.transforms:
                z_new = x_new
            if overflow.any():
                x_new = np.where(overflow, old, x_new)
            else:
                overflow = None
        s.x[:, i] = x_new
        lp_new = np.asarray(self.target.propose(s.x, i), dtype=float)
        if not np.all(lp_new < _INF):
            bad = int(np.flatnonzero(~(lp_new < _INF))[0])
            check_log_density(float(lp_new[bad]), s.x[bad])
        # The serial sampler's test, with the same float operations in the same order.
        accept = log_u < lp_new + lj_new - s.lp - s.log_jac[:, i]
        if overflow is not None:
            accept &= ~overflow
        self.target.commit(accept)
        s.lp = np.where(accept, lp_new, s.lp)
        s.z[:, i] = np.where(accept, z_new, s.z[:, i])
        s.log_jac[:, i] = np.where(accept, lj_new, s.log_jac[:, i])
        s.accepted[:, i] += accept
        s.x[:, i] = np.where(accept, x_new, old)
