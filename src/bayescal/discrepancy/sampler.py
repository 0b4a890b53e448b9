"""Chains of the discrepancy phase: lockstep, whitened, with the paper's periodic update.

Why the old random walk mixed slowly
------------------------------------
After an update the target of a chain leans towards the ``theta*`` it was
estimated at (:mod:`bayescal.discrepancy.phase`), so the draws of one chain stay
correlated across updates: on the box examples a chain needs tens of updates
per effective draw, and four chains of Metropolis-within-Gibbs on the raw
parameters (strongly correlated: the heat-loss coefficient, the capacity and
the solar gains trade off) reached R-hat 1.36 (co-heating) and 1.65
(free-float) after 4 x 30 000 sweeps (docs/validation/benchmarks-log.md). Two things help:
cheap sweeps, so that many updates fit in the time, and proposals that fit
the posterior's shape, so that a chain reaches each new target within a few
sweeps. A parameter piled up at a bound (the box's r_ag) still mixes slowly:
its ESS grows with the number of updates (a smaller ``update_interval``), not
with the sweeps between them, and the phase says when it stopped short.

How the chains run
------------------
* **Lockstep.** All ``B`` chains advance together: one batched evaluation of
  eq. 19 per coordinate update for all chains
  (:class:`~bayescal.discrepancy.batched.BatchedDelta`), through
  :func:`bayescal.mcmc.samplers.lockstep.run_lockstep`, the sampler the
  calibration uses; an update re-estimates every chain's ``w*``, ``B`` and the
  constant of eq. 23 from one emulator prediction (each chain's realisations
  from its own generator).
* **Whitened coordinates.** The chains move ``z`` with
  ``u = sigmoid(m + L z)`` (:class:`Whitening`): ``m`` and ``L L^T`` are the mean
  and covariance of ``logit(u)``, first from the calibration posterior, then
  (halfway through the burn-in) from the phase's own burn-in draws pooled over
  the chains. Metropolis-within-Gibbs on ``z`` then moves along the
  posterior's principal directions, not along the correlated parameters. The
  target on ``z`` carries the Jacobian ``sum log u (1 - u)`` (the constant
  ``log |L|`` dropped).
* **Adaptation.** During burn-in one proposal width per coordinate, common
  to all chains, goes up by ``exp(delta_n)`` after each batch of
  ``batch_size`` sweeps if the acceptance rate pooled over the chains exceeded
  0.44 and down otherwise (``delta_n = min(max_adapt, n^-1/2)``, Roberts and
  Rosenthal 2009); afterwards it is frozen, so between two updates each chain
  is an exact Metropolis chain for its target.
* **Length by convergence.** After burn-in at least ``n_draws`` sweeps per
  chain are kept; then, until every parameter has R-hat <= ``rhat_max`` and bulk
  and tail ESS >= ``ess_min`` (:func:`bayescal.mcmc.diagnostics.diagnose`, on
  all chains), the chains are extended by half their length at a time, up to
  ``max_draws``. Which length was reached, and whether the criteria were met,
  is in :class:`DeltaDraws`.
* **Checkpoints.** Between batches, at most every ``checkpoint_seconds``, one
  snapshot of every chain (points, widths, whitening, the current ``w*``, ``B``
  and eq. 23 constants, the draws kept so far and every generator's state)
  is written atomically (``delta.npz``); a killed phase resumes from it with
  the draws of an uninterrupted run.

The draws depend on the seed only: chain ``k``'s generator is
``default_rng(SeedSequence(seed).spawn(B)[k])`` and every random number of that
chain (its realisations and its Metropolis steps) comes from it.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import special

from bayescal.calibration.priors import ThetaPriors
from bayescal.discrepancy.batched import BatchedDelta, Segment
from bayescal.discrepancy.moments import GlsObservations
from bayescal.discrepancy.phase import DeltaPhase
from bayescal.emulator.kernel import FloatArray
from bayescal.errors import ConfigError
from bayescal.mcmc.checkpoint import ChainCheckpoint
from bayescal.mcmc.diagnostics import diagnose, extended_length
from bayescal.mcmc.samplers.lockstep import run_lockstep
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs
from bayescal.mcmc.samplers.schedule import fingerprint

__all__ = ["CHECKPOINT_FILE", "DeltaDraws", "DeltaSettings", "Whitening", "run_delta_chains"]

#: Snapshot file of the phase in a checkpoint folder.
CHECKPOINT_FILE = "delta.npz"
_CLIP = 1e-9  # normalised values are kept this far inside (0, 1) for the logit
_TARGET_ACCEPTANCE = 0.44


@dataclass(frozen=True)
class Whitening:
    """``u = sigmoid(m + L z)``: sampling coordinates ``z`` of normalised ``theta* = u``.

    Attributes
    ----------
    mean
        ``m``, mean of ``logit(u)`` ``(t,)``. [-]
    chol
        ``L``, lower Cholesky factor of the covariance of ``logit(u)`` ``(t, t)``. [-]
    """

    mean: FloatArray
    chol: FloatArray

    @classmethod
    def of(cls, unit_draws: ArrayLike) -> Whitening:
        """From draws of ``u`` ``(..., t)``: mean and covariance of their logits.

        Parameters with no spread get a width of 0.01 on the logit scale (their
        chains then adapt the proposal width).
        """
        u = np.asarray(unit_draws, dtype=float)
        flat = np.clip(u.reshape(-1, u.shape[-1]), _CLIP, 1.0 - _CLIP)
        v = special.logit(flat)
        mean = v.mean(axis=0)
        t = v.shape[1]
        cov = np.atleast_2d(np.cov(v, rowvar=False)) if v.shape[0] > 1 else np.zeros((t, t))
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        floor = np.where(sd > 1e-6, sd, 0.01)
        corr = cov / np.outer(np.where(sd > 1e-6, sd, 1.0), np.where(sd > 1e-6, sd, 1.0))
        corr[~np.outer(sd > 1e-6, sd > 1e-6)] = 0.0
        np.fill_diagonal(corr, 1.0)
        # A correlation matrix nearer the identity by 1e-6 stays factorisable when the
        # draws are (nearly) collinear.
        chol = np.linalg.cholesky((1.0 - 1e-6) * corr + 1e-6 * np.eye(t)) * floor[:, None]
        return cls(mean, chol)

    def unit(self, z: ArrayLike) -> FloatArray:
        """``u`` at ``z`` ``(..., t)``."""
        out: FloatArray = special.expit(self.mean + np.asarray(z, dtype=float) @ self.chol.T)
        return out

    def z(self, u: ArrayLike) -> FloatArray:
        """``z`` at ``u`` ``(..., t)`` (clipped inside (0, 1))."""
        v = special.logit(np.clip(np.asarray(u, dtype=float), _CLIP, 1.0 - _CLIP)) - self.mean
        out: FloatArray = np.linalg.solve(self.chol, v.T).T
        return out

    def log_jacobian(self, z: ArrayLike) -> FloatArray:
        """``sum_k log(u_k (1 - u_k))`` at ``z`` ``(..., t)`` (``log |L|`` dropped)."""
        v = self.mean + np.asarray(z, dtype=float) @ self.chol.T
        # log u (1 - u) = -(softplus(v) + softplus(-v)), exact for large |v|.
        out: FloatArray = -(np.logaddexp(0.0, v) + np.logaddexp(0.0, -v)).sum(axis=-1)
        return out


@dataclass(frozen=True)
class DeltaSettings:
    """How long and how the discrepancy-phase chains run.

    Parameters
    ----------
    n_burn
        Burn-in sweeps per chain (widths adapted, whitening re-estimated, discarded).
    n_draws
        Kept sweeps per chain before the first convergence check.
    max_draws
        Most kept sweeps per chain (``n_draws``: no extension).
    update_interval
        Sweeps between two updates of ``Delta``, ``A``, ``w*`` and ``B``.
    batch_size
        Sweeps per adaptation batch (and the most sweeps between two snapshots).
    max_adapt
        Cap of the per-batch change of a log proposal width.
    rhat_max, ess_min
        Convergence criteria: largest R-hat, smallest bulk and tail ESS.
    growth
        Factor by which the kept sweeps grow between two checks.
    """

    n_burn: int
    n_draws: int
    max_draws: int
    update_interval: int
    batch_size: int = 25
    max_adapt: float = 0.25
    rhat_max: float = 1.01
    ess_min: float = 400.0
    growth: float = 1.5

    def __post_init__(self) -> None:
        for name, least in (
            ("n_burn", 0),
            ("n_draws", 4),
            ("update_interval", 1),
            ("batch_size", 1),
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
                raise ConfigError(f"{name} must be an integer >= {least}, got {value!r}")
        if not isinstance(self.max_draws, int | np.integer) or self.max_draws < self.n_draws:
            raise ConfigError(
                f"max_draws must be an integer >= n_draws = {self.n_draws}, got {self.max_draws!r}"
            )
        if not (self.growth > 1.0 and self.max_adapt > 0.0):
            raise ConfigError("growth must be > 1 and max_adapt > 0")


@dataclass(frozen=True)
class DeltaDraws:
    """What the chains of the discrepancy phase produced.

    Attributes
    ----------
    unit_draws
        theta* on the normalised scale ``(chains, draws, t)``. [-]
    log_density
        Log target (prior + eq. 19 + eq. 23 constant of the chain's current
        update) at the draws ``(chains, draws)``.
    acceptance
        Acceptance rate after burn-in per chain and whitened coordinate ``(chains, t)``.
    scales
        Final proposal widths of the whitened coordinates ``(t,)``.
    updates
        Updates of ``Delta`` per chain, burn-in included.
    converged
        Whether the convergence criteria were met (always checked at the end).
    """

    unit_draws: FloatArray
    log_density: FloatArray
    acceptance: FloatArray
    scales: FloatArray
    updates: int
    converged: bool


class SegmentTarget:
    """The log target of every chain on ``z`` between two updates (batched).

    ``log p(u) + eq. 19 + eq. 23 constant + log |du/dz|`` at ``u = whitening.unit(z)``,
    row ``b`` with chain ``b``'s observed weights and nuggets.
    """

    def __init__(
        self,
        likelihood: BatchedDelta,
        priors: ThetaPriors,
        whitening: Whitening,
        segment: Segment,
        extra: FloatArray,
    ) -> None:
        self.likelihood = likelihood
        self.priors = priors
        self.whitening = whitening
        self.segment = segment
        self.extra = extra

    def log_posterior(self, u: FloatArray) -> FloatArray:
        """Prior + eq. 19 + eq. 23 constant at ``u`` ``(B, t)``, one row per chain."""
        prior = self.priors.batch(u)
        inside = np.isfinite(prior)
        lik = np.full(u.shape[0], -math.inf)
        if inside.all():
            lik = self.likelihood(u, self.segment)
        elif inside.any():
            rows = np.flatnonzero(inside)
            lik[rows] = self.likelihood(u[rows], self.segment.rows(rows))
        out: FloatArray = prior + lik + self.extra
        return out

    def __call__(self, z: FloatArray) -> FloatArray:
        """Log target at ``z`` ``(B, t)``."""
        zz = np.asarray(z, dtype=float)
        out: FloatArray = self.log_posterior(self.whitening.unit(zz))
        out = out + self.whitening.log_jacobian(zz)
        return np.where(np.isnan(out), -math.inf, out)


@dataclass
class _State:
    """Everything the loop needs to continue (what a snapshot holds)."""

    z: FloatArray
    scale: FloatArray
    whitening: Whitening
    w_star: FloatArray  # (B, m*, p) of the current update
    nuggets: FloatArray  # (B, p, m*)
    extra: FloatArray  # (B,)
    sweep: int = 0
    n_batch: int = 0
    updates: int = 0
    next_check: int = 0
    converged: bool = False
    accepted: FloatArray = field(default_factory=lambda: np.zeros(0))
    kept: list[FloatArray] = field(default_factory=list)  # (B, n, t) blocks, u
    kept_lp: list[FloatArray] = field(default_factory=list)  # (B, n) blocks
    burn: list[FloatArray] = field(default_factory=list)  # (B, n, t) blocks for re-whitening

    def n_kept(self) -> int:
        return sum(block.shape[1] for block in self.kept)


def run_delta_chains(
    phase: DeltaPhase,
    likelihood: BatchedDelta,
    starts: ArrayLike,
    whitening: Whitening,
    settings: DeltaSettings,
    seed: int,
    *,
    names: Sequence[str] | None = None,
    callback: Callable[[int], None] | None = None,
    checkpoint: ChainCheckpoint | None = None,
) -> DeltaDraws:
    """Run the discrepancy-phase chains in lockstep (module docstring).

    Parameters
    ----------
    phase
        The fixed pieces and the update of eqs. 20–25.
    likelihood
        The batched eq. 19 on the emulator's grid with the fixed nuggets.
    starts
        Normalised starting points, one row per chain ``(B, t)``.
    whitening
        The initial sampling coordinates (from the calibration posterior).
    settings
        Lengths, update interval, adaptation and convergence criteria.
    seed
        Root seed; chain ``k`` uses ``SeedSequence(seed).spawn(B)[k]``.
    names
        Parameter names for the convergence checks (default ``x0, x1, ...``).
    callback
        Progress: called with the sweeps completed over all chains.
    checkpoint
        Where the snapshot goes (``None``: no snapshots); a matching one is resumed.

    Returns
    -------
    DeltaDraws
    """
    u0 = np.atleast_2d(np.asarray(starts, dtype=float))
    n_chains, t = u0.shape
    rngs = [np.random.default_rng(c) for c in np.random.SeedSequence(seed).spawn(n_chains)]
    fp = fingerprint(settings, u0, [r.bit_generator.state for r in rngs])
    loop = _Loop(phase, likelihood, settings, rngs, list(names or [f"x{i}" for i in range(t)]))
    resumed = None if checkpoint is None else checkpoint.load(fp)
    state = loop.fresh(u0, whitening) if resumed is None else loop.restore(*resumed)
    while not loop.finished(state):
        loop.step(state)
        if callback is not None:
            callback(n_chains * state.sweep)
        if checkpoint is not None and (checkpoint.due() or loop.finished(state)):
            checkpoint.save(*loop.snapshot(state, fp))
    kept = np.concatenate(state.kept, axis=1)
    lps = np.concatenate(state.kept_lp, axis=1)
    return DeltaDraws(
        unit_draws=kept,
        log_density=lps,
        acceptance=state.accepted / kept.shape[1],
        scales=state.scale.copy(),
        updates=state.updates,
        converged=state.converged,
    )


@dataclass
class _Loop:
    """One step of the phase at a time: update if due, then a batch of lockstep sweeps."""

    phase: DeltaPhase
    likelihood: BatchedDelta
    settings: DeltaSettings
    rngs: list[np.random.Generator]
    names: list[str]

    @property
    def n_chains(self) -> int:
        return len(self.rngs)

    def fresh(self, u0: FloatArray, whitening: Whitening) -> _State:
        t = u0.shape[1]
        empty = np.zeros(0)
        state = _State(
            z=whitening.z(u0),
            scale=np.full(t, 1.0),
            whitening=whitening,
            w_star=empty,
            nuggets=empty,
            extra=empty,
            next_check=self.settings.n_draws,
            accepted=np.zeros((self.n_chains, t)),
        )
        return state

    def finished(self, state: _State) -> bool:
        s = self.settings
        n = state.n_kept()
        return n >= s.max_draws or (n >= state.next_check and state.converged)

    def _update(self, state: _State) -> None:
        """Eqs. 20–25 at every chain's current point, each with its own generator."""
        gls: list[GlsObservations] = self.phase.observations(
            state.whitening.unit(state.z), self.rngs
        )
        state.w_star = np.stack([g.w_star for g in gls])
        state.nuggets = np.stack([g.nuggets for g in gls])
        state.extra = np.array([g.extra for g in gls])
        state.updates += 1

    def _target(self, state: _State) -> SegmentTarget:
        segment = self.likelihood.segment(state.w_star, state.nuggets)
        return SegmentTarget(
            self.likelihood, self.phase.theta_priors, state.whitening, segment, state.extra
        )

    def _block(self, state: _State) -> int:
        """Sweeps of the next batch: up to the next update, the end of burn-in, the
        re-whitening point, the next check."""
        s = self.settings
        sweep = state.sweep
        ends = [sweep + s.batch_size, (sweep // s.update_interval + 1) * s.update_interval]
        if sweep < s.n_burn:
            ends.append(s.n_burn)
            if sweep < s.n_burn // 2:
                ends.append(s.n_burn // 2)
        else:
            ends.append(s.n_burn + state.next_check)
        return min(e for e in ends if e > sweep) - sweep

    def step(self, state: _State) -> None:
        s = self.settings
        if state.sweep % s.update_interval == 0 or state.w_star.size == 0:
            self._update(state)
        size = self._block(state)
        burning = state.sweep < s.n_burn
        sampler = MetropolisWithinGibbs(n_burn=0, scales=state.scale.tolist(), batch_size=size)
        results = run_lockstep(sampler, self._target(state), state.z, size, self.rngs)
        draws = np.stack([r.draws for r in results])  # (B, size, t) of z
        lps = np.stack([r.log_density for r in results])
        acc = np.stack([r.acceptance for r in results])  # (B, t)
        state.z = draws[:, -1].copy()
        unit = state.whitening.unit(draws)
        state.sweep += size
        if burning:
            self._adapt(state, acc.mean(axis=0))
            half = s.n_burn // 2
            if state.sweep - size >= s.n_burn // 4 and state.sweep <= half:
                state.burn.append(unit)
            if state.sweep == half:
                self._rewhiten(state)
            return
        state.kept.append(unit)
        state.kept_lp.append(lps - state.whitening.log_jacobian(draws))
        state.accepted += acc * size
        if state.n_kept() >= state.next_check:
            self._check(state)

    def _adapt(self, state: _State, acceptance: FloatArray) -> None:
        state.n_batch += 1
        step = min(self.settings.max_adapt, state.n_batch**-0.5)
        state.scale = state.scale * np.where(
            acceptance > _TARGET_ACCEPTANCE, math.exp(step), math.exp(-step)
        )

    def _rewhiten(self, state: _State) -> None:
        """New sampling coordinates from the burn-in draws pooled over the chains."""
        if not state.burn:
            return
        pooled = np.concatenate(state.burn, axis=1)
        if pooled.shape[0] * pooled.shape[1] > 4 * pooled.shape[2]:
            u = state.whitening.unit(state.z)
            state.whitening = Whitening.of(pooled)
            state.z = state.whitening.z(u)
        state.burn = []

    def _check(self, state: _State) -> None:
        s = self.settings
        draws = np.concatenate(state.kept, axis=1)
        diag = diagnose(draws, self.names)
        state.converged = bool(
            np.all(diag.rhat <= s.rhat_max)
            and np.all(diag.ess_bulk >= s.ess_min)
            and np.all(diag.ess_tail >= s.ess_min)
        )
        n = draws.shape[1]
        if not state.converged:
            state.next_check = extended_length(n, s.max_draws, s.growth)

    # ---------------------------------------------------------------- snapshots

    def snapshot(self, state: _State, fp: str) -> tuple[dict[str, Any], dict[str, Any]]:
        t = state.z.shape[1]
        b = self.n_chains
        arrays: dict[str, Any] = {
            "z": state.z,
            "scale": state.scale,
            "w_mean": state.whitening.mean,
            "w_chol": state.whitening.chol,
            "w_star": state.w_star,
            "nuggets": state.nuggets,
            "extra": state.extra,
            "accepted": state.accepted,
            "kept": _joined(state.kept, (b, 0, t)),
            "kept_lp": _joined(state.kept_lp, (b, 0)),
            "burn": _joined(state.burn, (b, 0, t)),
        }
        meta = {
            "fingerprint": fp,
            "rng": [copy.deepcopy(r.bit_generator.state) for r in self.rngs],
            "sweep": state.sweep,
            "n_batch": state.n_batch,
            "updates": state.updates,
            "next_check": state.next_check,
            "converged": state.converged,
        }
        return arrays, meta

    def restore(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> _State:
        for rng, rs in zip(self.rngs, meta["rng"], strict=True):
            rng.bit_generator.state = rs
        kept, kept_lp, burn = arrays["kept"], arrays["kept_lp"], arrays["burn"]
        return _State(
            z=np.array(arrays["z"], dtype=float),
            scale=np.array(arrays["scale"], dtype=float),
            whitening=Whitening(np.array(arrays["w_mean"]), np.array(arrays["w_chol"])),
            w_star=np.array(arrays["w_star"], dtype=float),
            nuggets=np.array(arrays["nuggets"], dtype=float),
            extra=np.array(arrays["extra"], dtype=float),
            sweep=int(meta["sweep"]),
            n_batch=int(meta["n_batch"]),
            updates=int(meta["updates"]),
            next_check=int(meta["next_check"]),
            converged=bool(meta["converged"]),
            accepted=np.array(arrays["accepted"], dtype=float),
            kept=[kept] if kept.shape[1] else [],
            kept_lp=[kept_lp] if kept_lp.shape[1] else [],
            burn=[burn] if burn.shape[1] else [],
        )


def _joined(blocks: list[FloatArray], empty: tuple[int, ...]) -> FloatArray:
    return np.concatenate(blocks, axis=1) if blocks else np.zeros(empty)


def checkpoint_file(folder: str | os.PathLike[str], every_seconds: float) -> ChainCheckpoint:
    """The phase's :class:`~bayescal.mcmc.checkpoint.ChainCheckpoint` in ``folder``."""
    return ChainCheckpoint(Path(folder) / CHECKPOINT_FILE, every_seconds)
