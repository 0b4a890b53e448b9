"""Metropolis-within-Gibbs chains in lockstep: one batched log-density call per update.

:class:`~bayescal.mcmc.samplers.mwg.MetropolisWithinGibbs` runs one
chain at a time and calls the log-density once per coordinate update; at the
paper's size (R = 30 runs x m* = 25 periods) one calibration evaluation costs
about as much as the Python around it. Here all ``B`` chains of a run advance
together: for each coordinate update the ``B`` proposals go to the target in
one call of a *batched* log-density ``f(X (B, d)) -> (B,)``.

Each chain keeps the semantics of the serial sampler exactly: the same
schedule of batches, adaptation and snapshots
(:class:`~bayescal.mcmc.samplers.schedule.Schedule`, shared with the serial
sampler), the same bounded-coordinate maps, and its own generator consumed in
the same order (per batch of iterations, ``standard_normal((size, n_active))``
then ``random((size, n_active))``). Given a batched log-density that returns,
row by row, the values the scalar one returns, chain ``k`` of a lockstep run
is bit-identical to the serial run of chain ``k``. When the two differ by
rounding only (the calibration likelihood: ~1e-15 relative), the draws are
still identical unless an acceptance test falls within that rounding of its
threshold, and the stored log-densities agree to rounding.

Targets. A plain batched log-density is called on all chains' points at
every update. A target may instead follow the lockstep protocol
(:class:`LockstepTarget`): ``start(X)`` at the starting points,
``propose(X, i)`` when ``X`` differs from the current points in coordinate
``i`` only, and ``commit(accept)`` with the chains that took their proposal;
it can then keep each chain's current pieces and recompute only what
coordinate ``i`` changes, as the scalar likelihood's memos do for one chain.
A scalar target offers its lockstep form through a ``lockstep()`` method
(:class:`LockstepCapable`; the calibration posterior of eq. 16 does);
:func:`as_lockstep` picks the best form of any target.

A chain whose proposal overflows the sampling map (``OverflowError``, a
rejection in the serial sampler) is evaluated at its current point and
rejected.

Checkpoints (``checkpoint=``) hold all chains in one snapshot: a killed
lockstep run resumes with the draws of an uninterrupted one.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.errors import ConfigError
from bayescal.mcmc.checkpoint import ChainCheckpoint
from bayescal.mcmc.samplers import joint as jm
from bayescal.mcmc.samplers.base import (
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
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs, joint_covariance
from bayescal.mcmc.samplers.schedule import Schedule, fingerprint

__all__ = [
    "BatchLogDensity",
    "LockstepCapable",
    "LockstepTarget",
    "RowLoop",
    "Stateless",
    "as_lockstep",
    "run_lockstep",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
BatchLogDensity = Callable[[FloatArray], FloatArray]
"""A batched log-density: points ``(B, d)`` on the original scale -> ``(B,)``."""

_INF = math.inf


@runtime_checkable
class LockstepTarget(Protocol):
    """A batched target that follows the chains' current points (module docstring).

    None of the methods may keep the array it is given.
    """

    def start(self, points: FloatArray) -> FloatArray:
        """Log-densities ``(B,)`` at the starting points ``(B, d)``, made current."""
        ...

    def propose(self, points: FloatArray, coordinate: int | tuple[int, ...]) -> FloatArray:
        """Log-densities ``(B,)`` at the current points with ``coordinate`` replaced
        (a tuple: the coordinates of a joint move)."""
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

    def propose(self, points: FloatArray, coordinate: int | tuple[int, ...]) -> FloatArray:
        """Log-densities at the proposals (``coordinate`` is not used)."""
        return np.asarray(self.log_density(points), dtype=float)

    def commit(self, accept: BoolArray) -> None:
        """Nothing to keep."""


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


@runtime_checkable
class LockstepCapable(Protocol):
    """A scalar log-density that offers its own lockstep form."""

    def lockstep(self) -> LockstepTarget:
        """A :class:`LockstepTarget` equal to this log-density row by row."""
        ...


def as_lockstep(log_density: Any) -> LockstepTarget:
    """The lockstep form of a log-density.

    A :class:`LockstepTarget` as it is; a :class:`LockstepCapable` target's
    own ``lockstep()``; an object with a ``batch`` method (points ``(B, d)``
    -> ``(B,)``) through that method; a plain batched callable is not told
    from a scalar one, so anything else is looped over rows (:class:`RowLoop`).
    """
    if isinstance(log_density, LockstepTarget):
        return log_density
    if isinstance(log_density, LockstepCapable):
        return log_density.lockstep()
    batch = getattr(log_density, "batch", None)
    if callable(batch):
        return Stateless(batch)
    return Stateless(RowLoop(log_density))


def run_lockstep(
    sampler: MetropolisWithinGibbs,
    log_density: LockstepTarget | BatchLogDensity,
    starts: ArrayLike,
    n_draws: int,
    rngs: Sequence[np.random.Generator],
    callback: Callback | None = None,
    checkpoint: ChainCheckpoint | None = None,
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
    checkpoint
        Where to keep one snapshot of all chains between batches; a matching
        snapshot found there at the start is resumed (same draws as an
        uninterrupted run).

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
    joint = sampler.joint_indices(x.shape[1], active)
    maps = [box.scalar_map(i) for i in range(x.shape[1])]
    loop = _Lockstep(
        target, maps, active, box, joint, sampler.n_burn, sampler.joint_after_burn, sampler.screen
    )
    chains = _Chains(sampler, loop, list(rngs), callback)

    def start() -> None:
        chains.s = _initial_states(sampler, target, x, box, joint)

    schedule = Schedule(sampler.n_burn, n_draws, sampler.thin, sampler.batch_size)
    fp = fingerprint(sampler, x, rng_states)
    draws, lps = schedule.run(chains, start, checkpoint, fp, x.shape)
    return _results(sampler, chains.s, draws, lps, active, joint, n_draws, rng_states)


@dataclass
class _States:
    """All chains' states between blocks (mutated by the loop); rows are chains."""

    x: FloatArray  # (B, d) original scale
    z: FloatArray  # (B, d) sampling scale
    log_jac: FloatArray  # (B, d)
    lp: FloatArray  # (B,)
    scale: FloatArray  # (B, d)
    accepted: NDArray[np.int64]  # (B, d)
    joint: list[jm.JointState] | None = None  # one per chain


@dataclass
class _Chains:
    """All chains as the :class:`~bayescal.mcmc.samplers.schedule.ChainSet` of the schedule."""

    sampler: MetropolisWithinGibbs
    loop: _Lockstep
    rngs: list[np.random.Generator]
    callback: Callback | None
    s: _States = field(init=False)
    joint_only: bool = False  # whether the last block moved the joint block only jointly
    joint_moves: int = 0  # the joint moves of the last block

    def block(
        self, size: int, n_done: int, keep_every: int, keep_start: int
    ) -> list[tuple[FloatArray, FloatArray]]:
        self.joint_only, self.joint_moves = jm.batch_moves(
            n_done, size, self.sampler.n_burn, self.sampler.joint_after_burn
        )
        return self.loop.block(
            self.s, self.rngs, size, n_done, self.callback, keep_every, keep_start
        )

    def reset_counts(self) -> None:
        self.s.accepted[:] = 0
        for js in self.s.joint or ():
            js.accepted = js.screened = 0

    def adapt(self, size: int, n_batch: int) -> None:
        """Per chain and coordinate, the serial sampler's rule (same float operations)."""
        factor_up, factor_down = self.sampler.adaptation(n_batch)
        # coordinates that moved only jointly in this batch keep their widths
        kept = set(self.loop.joint) if self.joint_only else set()
        active = [i for i in self.loop.active if i not in kept]
        up = self.s.accepted[:, active] > self.sampler.target * size
        self.s.scale[:, active] *= np.where(up, factor_up, factor_down)
        if self.s.joint is not None:
            step = adaptation_step(n_batch, self.sampler.max_adapt)
            for k, js in enumerate(self.s.joint):
                js.adapt(self.joint_moves, step, self.s.scale[k, self.loop.joint])

    def state(self) -> tuple[dict[str, Any], dict[str, Any]]:
        s = self.s
        arrays: dict[str, Any] = {"x": s.x, "z": s.z, "log_jac": s.log_jac, "scale": s.scale}
        arrays |= {"accepted": s.accepted, "lp": s.lp}
        for k, js in enumerate(s.joint or ()):
            arrays |= js.arrays(f"joint{k}_")
        return arrays, {"rng": [rng.bit_generator.state for rng in self.rngs]}

    def restore(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
        for rng, state in zip(self.rngs, meta["rng"], strict=True):
            rng.bit_generator.state = state
        x = np.array(arrays["x"], dtype=float)
        self.loop.target.start(x.copy())  # the target's current points, for propose()
        self.s = _States(
            x=x,
            z=np.array(arrays["z"], dtype=float),
            log_jac=np.array(arrays["log_jac"], dtype=float),
            lp=np.array(arrays["lp"], dtype=float),
            scale=np.array(arrays["scale"], dtype=float),
            accepted=np.array(arrays["accepted"], dtype=np.int64),
        )
        if self.loop.joint:
            self.s.joint = [
                jm.JointState.from_arrays(arrays, f"joint{k}_") for k in range(x.shape[0])
            ]


def _initial_states(
    sampler: MetropolisWithinGibbs,
    target: LockstepTarget,
    x: FloatArray,
    box: Box,
    joint: list[int],
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
    log_jac = np.array([box.log_jacobians(row) for row in z], dtype=float).reshape(x.shape)
    scale = np.tile(initial_scales(sampler.scales, box), (x.shape[0], 1))
    accepted = np.zeros(x.shape, dtype=np.int64)
    states = _States(x.copy(), z, log_jac, lp, scale, accepted)
    if joint:
        states.joint = [jm.JointState.start(row[joint]) for row in scale]
    return states


def _results(
    sampler: MetropolisWithinGibbs,
    s: _States,
    draws: FloatArray,
    lps: FloatArray,
    active: list[int],
    joint: list[int],
    n_draws: int,
    rng_states: list[Any],
) -> list[SamplerResult]:
    """One :class:`SamplerResult` per chain from the ``(n_draws, B, ...)`` arrays."""
    results = []
    d = s.x.shape[1]
    for k in range(s.x.shape[0]):
        acceptance = np.full(d, np.nan)
        acceptance[active] = s.accepted[k, active] / (n_draws * sampler.thin)
        if sampler.joint_after_burn and s.joint:
            moves = n_draws * sampler.thin * sampler.joint_after_burn
            acceptance[joint] = s.joint[k].accepted / moves
        scales = np.zeros(d)
        scales[active] = s.scale[k, active]
        results.append(
            SamplerResult(
                draws=draws[:, k].copy(),
                log_density=lps[:, k].copy(),
                acceptance=acceptance,
                scales=scales,
                rng_state=rng_states[k],
                n_burn=sampler.n_burn,
                thin=sampler.thin,
                proposal_cov=joint_covariance(s.joint[k] if s.joint else None, joint, d),
                screened=(
                    jm.screened_share(s.joint[k], n_draws, sampler.thin, sampler.joint_after_burn)
                    if sampler.screen and s.joint
                    else None
                ),
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
    joint: list[int]
    n_burn: int
    joint_after_burn: int = 0
    screen: bool = False

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
        if self.joint:
            n_j = len(self.joint)
            n_moves = max(1, self.joint_after_burn)
            eps_j = np.stack([rng.standard_normal((size, n_moves, n_j)) for rng in rngs], axis=2)
            log_u_j = np.stack([np.log1p(-rng.random((size, n_moves))) for rng in rngs], axis=2)
            assert s.joint is not None
            precisions: list[FloatArray | None] = [None] * len(rngs)
            if self.screen:
                log_u_screen = np.stack(
                    [np.log1p(-rng.random((size, n_moves))) for rng in rngs], axis=2
                )
                precisions = [jm.screen_precision(js) for js in s.joint]
        n_chains = len(rngs)
        kept: list[tuple[FloatArray, FloatArray]] = []
        inside = set(self.joint)
        for row in range(size):
            only = jm.joint_only(n_done + row, self.n_burn, self.joint_after_burn)
            for k, i in enumerate(self.active):
                if not (only and i in inside):
                    self._update(s, i, eps[row, k], log_u[row, k])
            if self.joint:
                assert s.joint is not None
                ready = [jm.screen_in_use(js, p) for p, js in zip(precisions, s.joint, strict=True)]
                for move in range(self.joint_after_burn if only else 1):
                    screens = [
                        None if p is None else (p, float(log_u_screen[row, move, b]))
                        for b, p in enumerate(ready)
                    ]
                    self._joint_update(s, eps_j[row, move], log_u_j[row, move], screens)
                if jm.collecting(n_done + row, self.n_burn):
                    for b, js in enumerate(s.joint or ()):
                        if jm.restarting(n_done + row, self.n_burn):
                            js.restart()
                        js.collect(s.z[b, self.joint])
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

    def _joint_update(
        self,
        s: _States,
        eps: FloatArray,
        log_u: FloatArray,
        screens: Sequence[tuple[FloatArray, float] | None],
    ) -> None:
        """One Metropolis update of the joint block in every chain (as the serial sampler).

        A chain whose proposal the stand-in turns down (``screens``, delayed acceptance)
        is scored at its current point and rejected: the draws are the serial ones, the
        saved evaluations are the serial sampler's only."""
        joint, states = self.joint, s.joint
        assert states is not None
        n_chains = s.x.shape[0]
        values = s.x[:, joint].copy()
        jacobians: list[list[float]] = []
        z_new = np.empty((n_chains, len(joint)))
        ok = np.ones(n_chains, dtype=bool)
        screened = np.zeros(n_chains)
        for b, js in enumerate(states):
            z_new[b] = jm.propose(s.z[b, joint], js.chol, eps[b])
            mapped = jm.map_values(self.maps, joint, z_new[b])
            screen = screens[b]
            if mapped is not None and screen is not None:
                screened[b] = jm.screen_log_ratio(z_new[b], s.z[b, joint], js.mean, screen[0])
                if not screen[1] < screened[b]:
                    js.screened += 1
                    mapped = None
            if mapped is None:
                ok[b] = False
                jacobians.append([])
                continue
            values[b] = mapped[0]
            jacobians.append(mapped[1])
        old = s.x[:, joint].copy()
        s.x[:, joint] = values
        lp_new = np.asarray(self.target.propose(s.x, tuple(joint)), dtype=float)
        if not np.all(lp_new < _INF):
            bad = int(np.flatnonzero(~(lp_new < _INF))[0])
            check_log_density(float(lp_new[bad]), s.x[bad])
        accept = np.zeros(n_chains, dtype=bool)
        for b in range(n_chains):
            if ok[b]:
                lj_old = s.log_jac[b, joint].tolist()
                ratio = jm.log_ratio(float(lp_new[b]), jacobians[b], float(s.lp[b]), lj_old)
                accept[b] = bool(log_u[b] < ratio - float(screened[b]))
        self.target.commit(accept)
        for b in np.flatnonzero(accept).tolist():
            s.lp[b] = lp_new[b]
            s.z[b, joint] = z_new[b]
            s.log_jac[b, joint] = jacobians[b]
            states[b].accepted += 1
        s.x[:, joint] = np.where(accept[:, None], values, old)
