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

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.calibration.batch import BatchSession
from bayescal.calibration.grid import StackedGrid
from bayescal.calibration.kron import CalibrationAlgebra, Kind, make_algebra
from bayescal.calibration.orthogonal import constraint_matrix
from bayescal.calibration.priors import CalibrationPriors
from bayescal.design import Prior
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.kron import Lru
from bayescal.emulator.noise import DELTA_RANGE, PHI_MAX, GlsPieces, ObservationModel
from bayescal.errors import ConfigError
from bayescal.mcmc.chains import ChainBackend, Chains, dispersed_starts, run_chains
from bayescal.mcmc.samplers.base import fixed_mask
from bayescal.mcmc.samplers.lockstep import LockstepTarget, RowLoop, Stateless
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs

__all__ = [
    "LAMBDA_NAMES",
    "BatchedPosterior",
    "CalibrationPosterior",
    "Moves",
    "build_target",
    "default_sampler",
    "default_starts",
    "emulator_algebra",
    "hold_theta",
    "sample",
]

LAMBDA_NAMES = ("lambda", "lambda_star")
#: How a sweep moves the coordinates (:func:`default_sampler`).
Moves = Literal["gibbs", "joint"]
BoolArray = NDArray[np.bool_]


class CalibrationPosterior:
    """Log posterior of eq. 16 at ``[u_1 .. u_t, lambda, lambda*.., phi..]``, up to a constant.

    With one white output (``observations`` omitted, or one white output) the
    vector is the paper's ``[u, lambda, lambda*]``. With an
    :class:`~bayescal.emulator.noise.ObservationModel` it holds one
    ``lambda*`` per output and one AR(1) coefficient ``phi`` per output with
    AR(1) errors (:mod:`bayescal.emulator.noise`).

    Picklable (for chains in worker processes). Non-positive-definite
    covariances count as zero density. Offers its lockstep form
    (:meth:`lockstep`) for chains run together.

    Parameters
    ----------
    algebra
        Likelihood back end (Kronecker or dense) built with the MAP kernels and
        the least-squares observed weights.
    priors
        One prior per parameter, in the order of ``u``.
    lam_prior
        ``(shape, rate)`` of the Gamma prior of ``lambda``.
    lam_star_prior
        ``(shape, rate)`` of the Gamma prior of ``lambda*`` (one white output);
        ignored with ``observations``.
    observations
        The outputs' error models and the measured periods; their ``lambda*``
        priors are eq. 7-updated for white outputs.
    """

    def __init__(
        self,
        algebra: CalibrationAlgebra,
        priors: Sequence[Prior],
        lam_prior: tuple[float, float],
        lam_star_prior: tuple[float, float] | None = None,
        observations: ObservationModel | None = None,
    ) -> None:
        self.algebra = algebra
        self.observations = observations
        if observations is None:
            if lam_star_prior is None:
                raise ConfigError("give lam_star_prior or an observation model")
            stars: tuple[tuple[float, float], ...] = (lam_star_prior,)
        else:
            stars = tuple(
                observations.white_prior(q) if o.model == "white" else o.prior
                for q, o in enumerate(observations.outputs)
            )
        n_phi = 0 if observations is None else len(observations.ar_outputs)
        n_delta = 0 if observations is None else len(observations.delta_coordinates)
        self.prior_terms = CalibrationPriors(tuple(priors), lam_prior, stars, n_phi, n_delta)
        self.t = self.prior_terms.t
        self._reset()

    def _reset(self) -> None:
        self._observed_memo = Lru(2)
        self._constraint_memo = Lru(2)

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state.pop("_observed_memo")
        state.pop("_constraint_memo")
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._reset()

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
        """``(shape, rate)`` of the Gamma prior of the (first) ``lambda*``."""
        return self.prior_terms.lam_star

    @property
    def d(self) -> int:
        """Length of the sampled vector."""
        return self.prior_terms.d

    @property
    def aux_names(self) -> tuple[str, ...]:
        """Names of the coordinates after theta*: ``lambda``, the ``lambda*``, the ``phi``."""
        if self.observations is None:
            return LAMBDA_NAMES
        return ("lambda", *self.observations.names())

    @property
    def coupled(self) -> bool:
        """Whether an output has AR(1) errors (its weights' noise coupled, ``phi`` sampled)."""
        return self.observations is not None and self.observations.coupled

    @property
    def plain(self) -> bool:
        """One white output without a discrepancy: the paper's ``[u, lambda, lambda*]``."""
        return self.prior_terms.d == self.t + 2

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
        """Log prior density of the sampled vector (up to a constant)."""
        return self.prior_terms.scalar(v)

    def __call__(self, v: ArrayLike) -> float:
        """Log posterior (eq. 16) at ``v = [u_1 .. u_t, lambda, lambda*.., phi..]``."""
        arr = np.asarray(v, dtype=float)
        prior = self.log_prior(arr)
        if prior == -math.inf:
            return prior
        t = self.t
        try:
            if self.plain:
                lik = self.algebra.logpdf(arr[:t], float(arr[t]), float(arr[t + 1]))
            else:
                lik = self._likelihood(arr)
        except np.linalg.LinAlgError:
            return -math.inf
        return prior + lik

    def _likelihood(self, arr: FloatArray) -> float:
        """Several outputs, or AR(1) errors (:mod:`bayescal.emulator.noise`)."""
        obs = self.observations
        assert obs is not None  # only called with an observation model
        t, n_out, n_phi = self.t, obs.n_outputs, self.prior_terms.n_phi
        lam_star = arr[t + 1 : t + 1 + n_out]
        a = 1.0 / (float(arr[t]) * self.algebra.data.ktk)
        a_star = obs.white_nuggets(lam_star)
        delta, independent = self._delta(arr[t + 1 + n_out + n_phi :])
        if independent is not None:  # no covariance between periods: a period's noise block
            a_star = a_star + independent
        constraint = self._constraint(arr[:t], a)
        if not self.coupled:
            return self.algebra.pieces_nuggets(arr[:t], a, a_star, delta, constraint).logpdf
        phi = arr[t + 1 + n_out : t + 1 + n_out + n_phi]
        algebra, pieces = self._observed_memo.get(phi.tobytes(), lambda: self._observed(phi))
        groups = [
            (
                obs.outputs[q].bases,
                piece.h0_inv / float(lam_star[q])
                + (
                    0.0 if independent is None else np.diag(independent[list(obs.outputs[q].bases)])
                ),
            )
            for q, piece in zip(obs.ar_outputs, pieces, strict=True)
        ]
        total = algebra.pieces_grouped(arr[:t], a, a_star, groups, delta, constraint).logpdf
        for q, piece in zip(obs.ar_outputs, pieces, strict=True):
            total += obs.remainder(q, piece, float(lam_star[q]))
        return total

    def _constraint(self, theta_star: FloatArray, a: FloatArray) -> FloatArray | None:
        """``F`` of the orthogonal discrepancies at theta* (recomputed wherever theta* or
        ``lambda`` moved: the model's sensitivities move with them), else None."""
        obs = self.observations
        if obs is None or not obs.orthogonal_outputs:
            return None
        bases = [obs.outputs[q].bases for q in obs.orthogonal_outputs]
        ktk = self.algebra.data.ktk
        f: FloatArray = self._constraint_memo.get(
            theta_star.tobytes() + a.tobytes(),
            lambda: constraint_matrix(self.algebra.mean_gradient(theta_star, a), ktk, bases),
        )
        return f if f.shape[2] else None

    def _delta(self, rel: FloatArray) -> tuple[FloatArray | None, FloatArray | None]:
        """Per-basis discrepancy variances ``r_o tau_j^-1`` from the outputs' ``r``:
        the part over the periods' conditions and the part independent between periods."""
        obs = self.observations
        if obs is None or not obs.delta_outputs:
            return None, None
        variances = np.array([k.variance for k in self.algebra.data.kernels])
        return obs.discrepancy_variances(rel, variances)

    def _observed(self, phi: FloatArray) -> tuple[CalibrationAlgebra, list[GlsPieces]]:
        """The algebra with the AR(1) outputs' GLS weights at ``phi``, and their pieces."""
        obs = self.observations
        assert obs is not None
        w_star = np.array(self.algebra.data.w_star, dtype=float)
        pieces = []
        for q, value in zip(obs.ar_outputs, phi, strict=True):
            piece = obs.gls(q, float(value))
            w_star[:, list(obs.outputs[q].bases)] = piece.w_hat
            pieces.append(piece)
        return self.algebra.with_observations(w_star), pieces

    def lockstep_preferred(self, n_chains: int, workers: int) -> bool:
        """Whether ``backend="auto"`` runs the chains in lockstep (in groups over ``workers``).

        Yes where the batched likelihood exists (:meth:`lockstep`: one white
        output, the Kronecker algebra, every period observed): there a lockstep
        group of two or more chains costs less per chain than one serial chain
        at every size measured (``docs/benchmarks.md``), so groups spread over
        the workers beat one chain per worker. Elsewhere the lockstep form loops
        over the rows, no faster than one chain: worker processes instead.
        """
        del n_chains, workers  # the answer does not depend on them (see above)
        if not self.plain or self.algebra.stacked_grid() is None:
            return False
        data = self.algebra.data
        return bool(data.obs_index.size == data.x.shape[0])

    def lockstep(self) -> LockstepTarget:
        """The same log posterior for ``B`` chains in lockstep.

        The batched likelihood (:class:`BatchedPosterior`) for one white
        output; otherwise the rows are evaluated one by one.
        """
        if self.plain:
            return BatchedPosterior(self.algebra, self.prior_terms)
        return Stateless(RowLoop(self))


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
        return out  # prior: batch(), with the joint densities (propose adds them again)

    def propose(self, points: FloatArray, coordinate: int | tuple[int, ...]) -> FloatArray:
        """Log posterior with ``coordinate`` of the current points replaced (a tuple:
        several coordinates of theta*, moved jointly)."""
        session, t = self._session, self.t
        if session is None:
            return self(points)
        moved = coordinate if isinstance(coordinate, tuple) else (coordinate,)
        if len(moved) > 1 and max(moved) >= t:
            raise ValueError(f"a joint move must stay within theta* (0..{t - 1}), got {moved}")
        terms = self._prior_terms.copy()
        for k in moved:
            terms[:, k] = self.priors.term(points[:, k], k)
        prior = terms.sum(axis=1) + self.priors.joint_term(points)
        coordinate = moved[0]
        if coordinate < t:
            values, ok = session.propose_theta(points[:, :t])
        else:
            # Rows outside the prior are evaluated at their current precision (-inf anyway).
            column = points[:, coordinate]
            current = session.lam if coordinate == t else session.lam_star
            value = np.where(column > 0.0, column, current)
            move = session.propose_lam if coordinate == t else session.propose_lam_star
            values, ok = move(value)
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
    lam_star_prior: tuple[float, float] | None,
    priors: Sequence[Prior],
    *,
    algebra: Kind = "kronecker",
    observations: ObservationModel | None = None,
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
        ``(shape, rate)`` of the Gamma prior of ``lambda*`` (eq. 7 for ``Y*``);
        ``None`` with ``observations``.
    priors
        The theta* priors on the design's bounds, in the emulator's parameter order.
    algebra
        ``"kronecker"`` (fast, default) or ``"dense"`` (reference).
    observations
        The outputs' error models (:mod:`bayescal.emulator.noise`); default:
        one white output with ``lam_star_prior``.
    """
    if len(priors) != len(emulator.parameter_names):
        raise ConfigError(
            f"got {len(priors)} priors for the emulator's {len(emulator.parameter_names)} "
            f"parameters {list(emulator.parameter_names)}"
        )
    alg = emulator_algebra(emulator, w_star, algebra)
    return CalibrationPosterior(alg, priors, emulator.lam_prior, lam_star_prior, observations)


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


def default_sampler(
    target: CalibrationPosterior, n_burn: int, moves: Moves = "gibbs"
) -> MetropolisWithinGibbs:
    """Metropolis-within-Gibbs as ``calibrate`` configures it for ``target``.

    ``moves = "gibbs"`` (default): every sweep moves each coordinate once, then
    theta* jointly once. ``"joint"``: the joint block also holds every
    ``lambda*``, ``phi`` and discrepancy ``r`` (for one white output, whose
    sharply known ``lambda*`` keeps its own moves, theta* alone: the batched
    likelihood moves theta* jointly only), its covariance is learnt during
    burn-in, and after burn-in each sweep moves the block as many times as it
    has coordinates instead of one at a time (``lambda``, uncorrelated with
    the rest, keeps its own move). Where the block is more than theta*, its
    proposals are screened by a stand-in learnt during burn-in (delayed
    acceptance, :mod:`bayescal.mcmc.samplers.joint`): the same posterior with
    about half the evaluations. :mod:`bayescal.mcmc.samplers.mwg`.
    """
    t, terms = target.t, target.prior_terms
    n_prec = 1 + terms.n_outputs
    lower = [0.0] * (t + n_prec) + [-PHI_MAX] * terms.n_phi + [DELTA_RANGE[0]] * terms.n_delta
    upper = (
        [1.0] * t + [math.inf] * n_prec + [PHI_MAX] * terms.n_phi + [DELTA_RANGE[1]] * terms.n_delta
    )
    # Logit-scale widths for theta* and phi, ~2.4 prior log-sd for the sharply
    # known precisions (an AR(1) output's lambda* is judged by its white eq. 7 update).
    shapes = [terms.lam[0], *_start_gammas(target)[:, 0]]
    scales = [0.5] * t + [2.4 / math.sqrt(a) for a in shapes]
    scales += [0.5] * terms.n_phi + [1.0] * terms.n_delta
    # Short batches and a generous cap: the widths of sharply identified
    # parameters must shrink by ~e^3 within a burn-in of a few hundred sweeps.
    # theta* also moves jointly once per sweep: correlated parameters (a resistance
    # split, heat loss against solar gains) form ridges that one-coordinate steps crawl.
    joint = tuple(range(t)) if t >= 2 else ()
    if moves not in ("gibbs", "joint"):
        raise ConfigError(f"moves must be 'gibbs' or 'joint', got {moves!r}")
    after, screen = 0, False
    if moves == "joint":
        if not target.plain:
            joint = tuple(range(t)) + tuple(range(t + 1, target.d))
            # delayed acceptance: chains run one per process here, so every
            # proposal the stand-in turns down saves an evaluation
            screen = True
        after = len(joint)
    return MetropolisWithinGibbs(
        n_burn=n_burn,
        lower=lower,
        upper=upper,
        scales=scales,
        batch_size=25,
        max_adapt=0.25,
        joint=joint,
        joint_after_burn=after,
        screen=screen,
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
    columns = [u, lam]
    for shape, rate in _start_gammas(target):
        columns.append(rng.gamma(shape, 1.0 / rate, n_chains))
    if target.prior_terms.n_phi:
        columns.append(rng.uniform(0.0, 0.9, (n_chains, target.prior_terms.n_phi)))
    if target.prior_terms.n_delta:
        low, high = np.log(DELTA_RANGE[0]), np.log(DELTA_RANGE[1])
        span = rng.uniform(0.1, 0.6, (n_chains, target.prior_terms.n_delta))
        columns.append(np.exp(low + span * (high - low)))
    return np.column_stack(columns)


def _start_gammas(target: CalibrationPosterior) -> FloatArray:
    """Gamma ``(shape, rate)`` per output to start ``lambda*`` from, ``(O, 2)``.

    The prior of a white output (eq. 7-updated, sharp); for an AR(1) output,
    whose prior is weak, the white eq. 7 update of its data, a sensible scale.
    """
    obs = target.observations
    pairs = list(target.prior_terms.lam_stars)
    if obs is not None:
        for q in obs.ar_outputs:
            pairs[q] = obs.white_prior(q)
    return np.array(pairs, dtype=float)


def hold_theta(
    sampler: MetropolisWithinGibbs,
    starts: ArrayLike,
    u: ArrayLike,
    indices: Sequence[int] | None = None,
) -> tuple[MetropolisWithinGibbs, FloatArray]:
    """The sampler and starts with theta* coordinates held at ``u``.

    ``indices``: the theta* coordinates held, one per entry of ``u`` (default:
    the first ``len(u)``, every theta* coordinate where ``u`` has ``t``
    entries, except those where ``u`` is NaN). The chains then sample the
    other coordinates of the same target (with every theta* held: only
    ``lambda``, the ``lambda*``, the ``phi`` and the discrepancy's ``r``): a
    held coordinate keeps its start value (the sampler's ``fixed``
    coordinates, whose acceptance is NaN, so the diagnostics pass over them),
    leaves the joint block and its sampling map becomes the identity (a value
    on a prior bound stays a valid start). The catalogue model of ``bayescal
    compare`` is this target at the nominal values
    (:mod:`bayescal.pipeline.catalogue`); ``[design] reuse_screening`` holds
    the screened-out inputs of the emulator at theirs
    (:mod:`bayescal.pipeline.reuse`).
    """
    held = np.asarray(u, dtype=float).reshape(-1)
    if indices is None:  # NaN entries: coordinates sampled, not held
        at = np.flatnonzero(~np.isnan(held)).tolist()
        held = held[at]
    else:
        at = [int(i) for i in indices]
    if len(at) != held.size:
        raise ValueError(f"{held.size} held values for {len(at)} coordinates")
    if not np.all((held >= 0.0) & (held <= 1.0)):
        raise ConfigError(f"held theta* {held.tolist()} lies outside the prior bounds [0, 1]")
    x0 = np.array(starts, dtype=float)
    x0[:, at] = held
    d = x0.shape[1]
    lower = list(sampler.lower if sampler.lower is not None else [-math.inf] * d)
    upper = list(sampler.upper if sampler.upper is not None else [math.inf] * d)
    for i in at:
        lower[i], upper[i] = -math.inf, math.inf
    joint = tuple(i for i in sampler.joint if i not in at)
    joint = joint if len(joint) >= 2 else ()
    fixed = sorted({*at, *(np.flatnonzero(fixed_mask(sampler.fixed, d)).tolist())})
    held_sampler = dataclasses.replace(
        sampler,
        fixed=tuple(fixed),
        lower=lower,
        upper=upper,
        joint=joint,
        joint_after_burn=len(joint) if joint and sampler.joint_after_burn else 0,
        screen=sampler.screen and bool(joint),
    )
    return held_sampler, x0


def sample(
    target: CalibrationPosterior,
    n_draws: int,
    *,
    n_burn: int = 1000,
    n_chains: int = 4,
    seed: int = 0,
    backend: ChainBackend = "auto",
    names: Sequence[str] | None = None,
    callback: Callable[[int], None] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
    starts: ArrayLike | None = None,
    sampler: Any = None,
    moves: Moves = "gibbs",
    held: ArrayLike | None = None,
    held_at: Sequence[int] | None = None,
) -> Chains:
    """Metropolis-within-Gibbs sweeps of ``target``, no diagnostics.

    Parameters
    ----------
    target
        From :func:`build_target`.
    n_draws, n_burn, n_chains, seed
        Kept draws and burn-in sweeps per chain, chains, root seed.
    backend
        ``"auto"`` (lockstep groups over the workers where the batched
        likelihood exists, else worker processes), ``"processes"``,
        ``"serial"``, ``"vectorised"`` (lockstep, batched likelihood) or
        ``"vectorised-processes"``; see :func:`bayescal.mcmc.chains.run_chains`.
    names
        Coordinate names (default: ``x0, x1, ...``).
    callback, checkpoint_dir, checkpoint_seconds
        Progress and snapshots, as :func:`~bayescal.mcmc.chains.run_chains`.
    starts
        Starting points ``(n_chains, t + 2)``; default :func:`default_starts`.
    sampler
        Another sampler (default :func:`default_sampler`).
    moves
        ``"gibbs"`` or ``"joint"``: how :func:`default_sampler` moves the
        coordinates (ignored with ``sampler``).
    held
        theta* on the normalised scale ``(t,)`` to hold fixed (:func:`hold_theta`;
        a Metropolis-within-Gibbs ``sampler`` only): the chains sample the error
        model's parameters alone. ``None``: theta* is sampled.
    held_at
        The theta* coordinates ``held`` holds, one per entry (default: all of them).

    Returns
    -------
    Chains
        Draws of ``[u, lambda, lambda*]``, ``(chains, draws, t + 2)``.
    """
    x0 = default_starts(target, n_chains, seed) if starts is None else starts
    chosen = default_sampler(target, n_burn, moves) if sampler is None else sampler
    if held is not None:
        chosen, x0 = hold_theta(chosen, x0, held, held_at)
    return run_chains(
        chosen,
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
