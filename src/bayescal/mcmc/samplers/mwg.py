"""Adaptive Metropolis-within-Gibbs (Roberts & Rosenthal 2009, section 3).

One coordinate at a time, in a fixed order, is moved by a Gaussian random
walk on the sampling scale and accepted or rejected by Metropolis: one
log-density evaluation per coordinate update. During burn-in only, the
iterations are grouped in batches of ``batch_size`` (50); after batch ``n``
the log proposal width of each coordinate goes up by
``delta(n) = min(max_adapt, n**-0.5)`` if that coordinate's acceptance rate in
the batch exceeded ``target`` (0.44) and down by ``delta(n)`` otherwise. After
burn-in the widths are frozen, so the kept draws come from a fixed,
reversible Markov kernel.

References: G. O. Roberts and J. S. Rosenthal (2009), "Examples of adaptive
MCMC", J. Comput. Graph. Stat. 18(2), 349-367; J. S. Rosenthal (2007),
"AMCMC: An R interface for adaptive MCMC", Comput. Stat. Data Anal. 51.

With ``joint`` set, a few coordinates also move together once per sweep, by
a random walk whose covariance is learnt during burn-in
(:mod:`bayescal.mcmc.samplers.joint`): it follows the ridges of correlated
posteriors that one-coordinate steps crawl along. With ``joint_after_burn =
k > 0`` the block's coordinates stop moving one at a time halfway through
burn-in: each later sweep moves the block ``k`` times (the coordinates outside
it still move one at a time), and the second half of burn-in learns the
covariance and the scale ``g`` from these joint moves
(:func:`~bayescal.mcmc.samplers.joint.joint_only`). Where the block's
coordinates are correlated this mixes far better per evaluation: on the Twin
House calibration (seven coordinates, correlations up to 0.86) the smallest
bulk ESS per log-density evaluation after burn-in was 7-8x the Gibbs sweeps'
(docs/validation/benchmarks-log.md).

Bounded coordinates are sampled on a transformed scale or reflected at the
bounds (see :mod:`bayescal.mcmc.samplers.base`); ``fixed`` coordinates
keep their starting value.

Why no "only coordinate i moved" hook: each update already costs exactly one
evaluation, and in bayescal's models (eq. 9 per basis, eq. 14) a change of any
one coordinate changes the whole covariance, so a conditional log-density
would save nothing; independent blocks (the bases of eq. 9) are better
sampled as separate targets.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.errors import ConfigError
from bayescal.mcmc.checkpoint import ChainCheckpoint
from bayescal.mcmc.samplers import joint as jm
from bayescal.mcmc.samplers.base import (
    BoundsMethod,
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
from bayescal.mcmc.samplers.schedule import Schedule, fingerprint

_INF = math.inf


@dataclass
class _State:
    """The chain's state between blocks of iterations (mutated by the loop)."""

    x: NDArray[np.float64]
    z: list[float]
    log_jac: list[float]
    lp: float
    scale: list[float]
    accepted: list[int]
    joint: jm.JointState | None = None


@dataclass(frozen=True)
class MetropolisWithinGibbs:
    """Adaptive Metropolis-within-Gibbs with Gaussian random-walk proposals.

    Parameters
    ----------
    n_burn
        Burn-in iterations (full sweeps), adapted and discarded.
    thin
        Iterations per kept draw.
    lower, upper
        Bounds per coordinate on the original scale (``-inf``/``inf`` or
        ``None`` for none).
    bounds
        ``"transform"`` (default) or ``"reflect"``.
    fixed
        Boolean mask (d,) or indices of coordinates that keep their start value.
    scales
        Initial proposal standard deviations on the sampling scale, scalar or
        (d,). Default: 0.25 * (upper - lower) for a coordinate reflected in two
        bounds, 1 otherwise (1 is a wide step on the logit/log scale).
    target
        Acceptance rate the adaptation aims at.
    batch_size
        Iterations per adaptation batch.
    max_adapt
        Cap of the per-batch change of a log proposal width.
    joint
        Indices of coordinates that also move together once per sweep
        (:mod:`~bayescal.mcmc.samplers.joint`); at least two free coordinates,
        ``bounds="transform"`` only. Empty: none (the draws are then those of
        the plain sampler).
    joint_after_burn
        ``0`` (default): every sweep, burn-in or not, moves each free
        coordinate once and then the joint block once. ``k > 0``: from the
        second half of burn-in on, each sweep moves the coordinates outside the
        joint block once each and then the block ``k`` times, and no longer
        moves its coordinates one at a time (the covariance learnt from these
        moves in the second half of burn-in does the work; a fixed kernel after
        burn-in, as before). Needs ``joint``.
    screen
        Delayed acceptance of the joint moves: each proposal is first tested
        against a Student-t stand-in of the block learnt during burn-in, and the
        log-density is evaluated only for those that pass
        (:mod:`~bayescal.mcmc.samplers.joint`). Same target, fewer evaluations
        where that stand-in is close to the block's posterior on the sampling scale.
        Needs ``joint``; draws one more uniform per joint move.
    """

    n_burn: int = 2000
    thin: int = 1
    lower: Sequence[float] | None = None
    upper: Sequence[float] | None = None
    bounds: BoundsMethod = "transform"
    fixed: Sequence[bool] | Sequence[int] | None = None
    scales: float | Sequence[float] | None = None
    target: float = 0.44
    batch_size: int = 50
    max_adapt: float = 0.01
    joint: tuple[int, ...] = ()
    joint_after_burn: int = 0
    screen: bool = False

    def __post_init__(self) -> None:
        check_run_args(1, self.n_burn, self.thin)
        if not 0.0 < self.target < 1.0:
            raise ConfigError(f"target acceptance must lie in (0, 1), got {self.target!r}")
        if int(self.batch_size) != self.batch_size or self.batch_size < 1:
            raise ConfigError(f"batch_size must be a positive integer, got {self.batch_size!r}")
        if not self.max_adapt > 0.0:
            raise ConfigError(f"max_adapt must be positive, got {self.max_adapt!r}")
        object.__setattr__(self, "joint", tuple(int(i) for i in self.joint))
        if self.joint and self.bounds != "transform":
            raise ConfigError(
                "joint moves need bounds='transform' (a folded joint step is not symmetric)"
            )
        if int(self.joint_after_burn) != self.joint_after_burn or self.joint_after_burn < 0:
            raise ConfigError(
                f"joint_after_burn must be a non-negative integer, got {self.joint_after_burn!r}"
            )
        object.__setattr__(self, "joint_after_burn", int(self.joint_after_burn))
        if self.joint_after_burn and not self.joint:
            raise ConfigError("joint_after_burn needs a joint block (joint=...)")
        if self.screen and not self.joint:
            raise ConfigError("screen needs a joint block (joint=...)")

    def joint_indices(self, d: int, active: Sequence[int]) -> list[int]:
        """The joint block checked against ``d`` coordinates and the free ones."""
        joint = [int(i) for i in self.joint]
        if not joint:
            return []
        if len(set(joint)) != len(joint) or not set(joint) <= set(active) or len(joint) < 2:
            raise ConfigError(
                f"joint must name at least two distinct free coordinates of {d}, got {joint}"
            )
        return joint

    def run(
        self,
        log_density: LogDensity,
        x0: ArrayLike,
        n_draws: int,
        rng: np.random.Generator,
        callback: Callback | None = None,
        checkpoint: ChainCheckpoint | None = None,
    ) -> SamplerResult:
        """Run one chain.

        Parameters
        ----------
        log_density
            Log of the unnormalised target density on the original scale.
        x0
            Starting point (d,), inside the bounds, with finite log-density.
        n_draws
            Draws to keep after burn-in.
        rng
            The chain's random generator (its state at the start is recorded).
        callback
            Called with the number of completed iterations after each one; the
            total is ``n_burn + n_draws * thin``.
        checkpoint
            Where to keep snapshots between batches; a matching snapshot found
            there at the start is resumed (same draws as an uninterrupted run).

        Returns
        -------
        SamplerResult
        """
        check_run_args(n_draws, self.n_burn, self.thin)
        n_draws = int(n_draws)
        rng_state = copy.deepcopy(rng.bit_generator.state)
        x = np.array(x0, dtype=float).reshape(-1)
        box = Box.build(x.size, self.lower, self.upper, self.bounds)
        box.check_start(x)
        active = np.flatnonzero(~fixed_mask(self.fixed, x.size)).tolist()
        joint = self.joint_indices(x.size, active)
        maps = [box.scalar_map(i) for i in range(x.size)]
        loop = _Loop(
            log_density,
            maps,
            active,
            box.transforms,
            callback,
            joint,
            self.n_burn,
            self.joint_after_burn,
            self.screen,
        )
        chain = _Chain(self, loop, rng, active)
        fp = fingerprint(self, x, rng_state)

        def start() -> None:
            chain.s = self._initial_state(log_density, x, box)

        schedule = Schedule(self.n_burn, n_draws, self.thin, self.batch_size)
        draws, lps = schedule.run(chain, start, checkpoint, fp, (x.size,))
        state = chain.s
        acceptance = np.full(x.size, np.nan)
        acceptance[active] = np.asarray(state.accepted, dtype=float)[active] / (n_draws * self.thin)
        if self.joint_after_burn and state.joint is not None:
            acceptance[joint] = state.joint.accepted / (n_draws * self.thin * self.joint_after_burn)
        screened = None
        if self.screen and state.joint is not None:
            screened = jm.screened_share(state.joint, n_draws, self.thin, self.joint_after_burn)
        scales = np.zeros(x.size)
        scales[active] = np.asarray(state.scale)[active]
        return SamplerResult(
            draws=draws,
            log_density=lps,
            acceptance=acceptance,
            scales=scales,
            rng_state=rng_state,
            n_burn=self.n_burn,
            thin=self.thin,
            proposal_cov=joint_covariance(state.joint, joint, x.size),
            screened=screened,
        )

    def _initial_state(self, log_density: LogDensity, x: NDArray[np.float64], box: Box) -> _State:
        lp = check_log_density(log_density(x), x)
        if lp == -_INF:
            raise ConfigError(
                f"log-density is -inf at the starting point {np.array2string(x, precision=6)}",
                hint="start inside the support of the prior and likelihood",
            )
        z = box.to_sampling(x)
        log_jac = box.log_jacobians(z)
        scales = initial_scales(self.scales, box)
        joint = self.joint_indices(x.size, np.flatnonzero(~fixed_mask(self.fixed, x.size)).tolist())
        state = _State(x, z.tolist(), log_jac, lp, scales.tolist(), [])
        if joint:
            state.joint = jm.JointState.start(scales[joint])
        return state

    def adaptation(self, n_batch: int) -> tuple[float, float]:
        """Factors ``(up, down)`` of a proposal width after burn-in batch ``n_batch``."""
        step = adaptation_step(n_batch, self.max_adapt)
        return math.exp(step), math.exp(-step)


@dataclass
class _Chain:
    """One chain as the :class:`~bayescal.mcmc.samplers.schedule.ChainSet` of the schedule."""

    sampler: MetropolisWithinGibbs
    loop: _Loop
    rng: np.random.Generator
    active: list[int]
    s: _State = field(init=False)
    joint_only: bool = False  # whether the last block moved the joint block only jointly
    joint_moves: int = 0  # the joint moves of the last block

    def block(
        self, size: int, n_done: int, keep_every: int, keep_start: int
    ) -> list[tuple[NDArray[np.float64], float]]:
        self.joint_only, self.joint_moves = jm.batch_moves(
            n_done, size, self.sampler.n_burn, self.sampler.joint_after_burn
        )
        return self.loop.block(self.s, self.rng, size, n_done, keep_every, keep_start)

    def reset_counts(self) -> None:
        self.s.accepted = [0] * self.s.x.size
        if self.s.joint is not None:
            self.s.joint.accepted = self.s.joint.screened = 0

    def adapt(self, size: int, n_batch: int) -> None:
        factor_up, factor_down = self.sampler.adaptation(n_batch)
        scale, counts, target = self.s.scale, self.s.accepted, self.sampler.target
        # coordinates that moved only jointly in this batch keep their widths
        kept = set(self.loop.joint) if self.joint_only else set()
        for i in self.active:
            if i not in kept:
                scale[i] *= factor_up if counts[i] > target * size else factor_down
        if self.s.joint is not None:
            step = adaptation_step(n_batch, self.sampler.max_adapt)
            widths = np.array([scale[i] for i in self.loop.joint])
            self.s.joint.adapt(self.joint_moves, step, widths)

    def state(self) -> tuple[dict[str, Any], dict[str, Any]]:
        s = self.s
        arrays = {
            "x": s.x,
            "z": np.asarray(s.z, dtype=float),
            "log_jac": np.asarray(s.log_jac, dtype=float),
            "scale": np.asarray(s.scale, dtype=float),
            "accepted": np.asarray(s.accepted, dtype=np.int64),
        }
        if s.joint is not None:
            arrays |= s.joint.arrays()
        return arrays, {"lp": s.lp, "rng": self.rng.bit_generator.state}

    def restore(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
        self.rng.bit_generator.state = meta["rng"]
        self.s = _State(
            x=np.array(arrays["x"], dtype=float),
            z=arrays["z"].tolist(),
            log_jac=arrays["log_jac"].tolist(),
            lp=float(meta["lp"]),
            scale=arrays["scale"].tolist(),
            accepted=[int(v) for v in arrays["accepted"]],
            joint=jm.JointState.from_arrays(arrays) if "joint_chol" in arrays else None,
        )


@dataclass(frozen=True)
class _Loop:
    """The inner loop: what stays fixed during a run."""

    log_density: LogDensity
    maps: list[ScalarMap | None]
    active: list[int]
    transforms: bool
    callback: Callback | None
    joint: list[int]
    n_burn: int
    joint_after_burn: int = 0
    screen: bool = False

    def block(
        self,
        s: _State,
        rng: np.random.Generator,
        size: int,
        n_done: int,
        keep_every: int,
        keep_start: int = 0,
    ) -> list[tuple[NDArray[np.float64], float]]:
        """Run ``size`` sweeps after ``n_done``; keep ``(x copy, lp)`` every ``keep_every``
        iterations counted from ``keep_start`` (``keep_every = 0``: keep none)."""
        n_act = len(self.active)
        eps = rng.standard_normal((size, n_act)).tolist()
        log_u = np.log1p(-rng.random((size, n_act))).tolist()
        if self.joint:
            # (size, 1, |J|) draws the stream of (size, |J|): one joint move per sweep
            # consumes the generator as it always did
            n_moves = max(1, self.joint_after_burn)
            eps_j = rng.standard_normal((size, n_moves, len(self.joint)))
            log_u_j = np.log1p(-rng.random((size, n_moves))).tolist()
            precision = None
            if self.screen:
                log_u_screen = np.log1p(-rng.random((size, n_moves))).tolist()
                assert s.joint is not None
                precision = jm.screen_precision(s.joint)  # C changes between blocks only
        f_logp, maps, active, callback = self.log_density, self.maps, self.active, self.callback
        inside = set(self.joint)
        reflect = not self.transforms
        x, z, log_jac, scale, accepted = s.x, s.z, s.log_jac, s.scale, s.accepted
        lp = s.lp
        kept: list[tuple[NDArray[np.float64], float]] = []
        for row, (e_row, u_row) in enumerate(zip(eps, log_u, strict=True)):
            only = jm.joint_only(n_done + row, self.n_burn, self.joint_after_burn)
            for k, i in enumerate(active):
                if only and i in inside:
                    continue
                zi = z[i] + scale[i] * e_row[k]
                f = maps[i]
                if f is None:
                    xi, lji = zi, 0.0
                else:
                    try:
                        xi, lji = f(zi)
                    except OverflowError:
                        continue
                    if reflect:
                        zi = xi
                old = x[i]
                x[i] = xi
                lp_new = f_logp(x)
                if not lp_new < _INF:
                    check_log_density(lp_new, x)
                if u_row[k] < lp_new + lji - lp - log_jac[i]:
                    lp = lp_new
                    z[i] = zi
                    log_jac[i] = lji
                    accepted[i] += 1
                else:
                    x[i] = old
            if self.joint:
                s.lp = lp
                assert s.joint is not None
                ready = jm.screen_in_use(s.joint, precision)
                for move in range(self.joint_after_burn if only else 1):
                    screen = None if ready is None else (ready, log_u_screen[row][move])
                    self._joint_move(s, eps_j[row, move], log_u_j[row][move], screen)
                lp = s.lp
                if jm.collecting(n_done + row, self.n_burn):
                    if jm.restarting(n_done + row, self.n_burn):
                        s.joint.restart()
                    s.joint.collect(np.array([z[i] for i in self.joint]))
            done = n_done + row + 1
            if keep_every and (done - keep_start) % keep_every == 0:
                kept.append((x.copy(), float(lp)))
            if callback is not None:
                callback(done)
        s.lp = lp
        return kept

    def _joint_move(
        self,
        s: _State,
        eps: NDArray[np.float64],
        log_u: float,
        screen: tuple[NDArray[np.float64], float] | None = None,
    ) -> None:
        """One Metropolis update of the joint block (:mod:`~bayescal.mcmc.samplers.joint`);
        with ``screen = (precision, log u)`` first the stand-in's test (delayed acceptance)."""
        js, joint, x, z, log_jac = s.joint, self.joint, s.x, s.z, s.log_jac
        assert js is not None
        z_old = np.array([z[i] for i in joint])
        z_new = jm.propose(z_old, js.chol, eps)
        mapped = jm.map_values(self.maps, joint, z_new)
        if mapped is None:
            return
        screened = 0.0
        if screen is not None:
            screened = jm.screen_log_ratio(z_new, z_old, js.mean, screen[0])
            if not screen[1] < screened:
                js.screened += 1
                return
        values, jacobians = mapped
        old = [x[i] for i in joint]
        for k, i in enumerate(joint):
            x[i] = values[k]
        lp_new = self.log_density(x)
        if not lp_new < _INF:
            check_log_density(lp_new, x)
        ratio = jm.log_ratio(lp_new, jacobians, s.lp, [log_jac[i] for i in joint])
        if log_u < ratio - screened:
            s.lp = lp_new
            for k, i in enumerate(joint):
                z[i] = float(z_new[k])
                log_jac[i] = jacobians[k]
            js.accepted += 1
        else:
            for k, i in enumerate(joint):
                x[i] = old[k]


def joint_covariance(
    js: jm.JointState | None, joint: Sequence[int], d: int
) -> NDArray[np.float64] | None:
    """The joint move's final proposal covariance embedded in ``(d, d)`` (``None``: none)."""
    if js is None:
        return None
    cov = np.zeros((d, d))
    cov[np.ix_(joint, joint)] = js.chol @ js.chol.T
    return cov
