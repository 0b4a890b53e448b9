"""Training the emulator: the hyperparameter posterior (eq. 9), its MCMC and the MAP.

Hyperparameter posterior (the paper's eq. 9)
---------------------------------------------
For every basis ``j`` the weights ``w_j`` (``R m*``, run-major) are
``N(0, (lambda k_j^T k_j)^-1 I + S_theta,j ⊗ S_x,j)`` (eqs. 5, 10). The
sampled vector is ``[beta_1j .. beta_rj, tau_j]`` for ``j = 1..p``, then
``lambda``: ``d = p (r + 1) + 1`` coordinates, all positive. The priors are

* ``rho_lj ~ Beta(a, b)`` (paper: ``Beta(1, 0.1)``), carried as
  ``beta = -4 ln rho`` on ``[0, inf)``: the density of ``beta`` is the Beta
  density of ``rho`` times the Jacobian ``|d rho / d beta| = rho / 4``, with
  ``1 - rho = -expm1(-beta / 4)`` so the pile-up of ``rho`` at 1 sits at
  ``beta = 0`` where floats are precise;
* ``tau_j ~ Gamma(5, 5)``;
* ``lambda ~ Gamma`` after the eq. 7 update (``Assembled.lam_prior``).

:class:`TrainingPosterior` evaluates it up to a constant. In
Metropolis-within-Gibbs one coordinate moves at a time, so only that basis's
term changes (all of them for ``lambda``, but then only the nugget moves):
the object keeps, per basis, the eigen-decompositions of the correlation
factors ``R_theta`` and ``R_x``, the half-rotated weights ``Q_t^T W`` and the
rotated weights for the last few values of the correlation parameters, and
the terms of the other bases. A move of a ``theta`` correlation parameter
costs one ``R x R`` eigen-decomposition and the rotation ``(Q_t^T W) Q_x``
(``O(R^2 m* + R m*^2)``), one of an ``x`` parameter one ``m* x m*``
eigen-decomposition and ``O(R m*^2)``; a move of ``tau`` or ``lambda`` costs
``O(R m*)`` per basis.

Training, MAP
-------------
The MAP is the mode of the posterior density **of the log-scale
coordinates** ``(ln beta, ln tau, ln lambda)``. That mode exists; the mode of
the density of ``beta`` itself does not for inputs without influence (the
``Beta(1, 0.1)`` prior diverges at ``rho = 1``). :func:`train` finds it in one
of two ways (``method``):

``"map"`` (default)
    Multi-start L-BFGS-B with the exact gradient
    (:mod:`bayescal.emulator.mapfit`, :mod:`bayescal.emulator.gradient`); the
    hyperparameters' uncertainty is the Laplace approximation at the MAP,
    whose draws are kept in ``hyper_draws`` (one "chain" of independent
    draws; ``hyper_lp`` and ``hyper_acceptance`` are NaN there: not
    evaluated, nothing accepted). Its length is set by the optimiser's
    convergence criteria and the multi-start rule, not by a number of sweeps.
``"mcmc"``
    The paper's route: adaptive Metropolis-within-Gibbs chains (proposal
    widths adapted during burn-in only, each coordinate sampled on the log
    scale), the best draw by the log-scale density, refined by a short
    L-BFGS-B search. Both the best draw and the refined point are kept.

The trained result is an :class:`~bayescal.emulator.gp.Emulator`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Literal, get_args

import numpy as np
from numpy.typing import ArrayLike
from scipy import optimize

from bayescal.design import log_gamma
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.gradient import Eq9Data, LogScalePosterior
from bayescal.emulator.hyper import HyperLayout, HyperPriors, log_prior_beta
from bayescal.emulator.kernel import LOG_2PI, FloatArray
from bayescal.emulator.kron import Lru, SymEig
from bayescal.emulator.mapfit import (
    MapSettings,
    default_processes,
    find_map,
    laplace_covariance,
    laplace_draws,
    laplace_hessian,
)
from bayescal.errors import ConfigError
from bayescal.mcmc.chains import ChainBackend, Chains, run_chains
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs

__all__ = ["TRAINING_METHODS", "TrainingMethod", "TrainingPosterior", "train"]

TrainingMethod = Literal["map", "mcmc"]
TRAINING_METHODS: tuple[str, ...] = get_args(TrainingMethod)


class TrainingPosterior(Eq9Data):
    """Log posterior of eq. 9 over ``(beta, tau, lambda)``, up to a constant; picklable.

    Built from the arrays of :class:`~bayescal.emulator.gradient.Eq9Data` (same
    parameters).
    """

    CACHES = ("_eig_t", "_eig_x", "_half", "_rot", "_terms")

    def _reset_caches(self) -> None:
        self._eig_t = [Lru() for _ in range(self.p)]
        self._eig_x = [Lru() for _ in range(self.p)]
        self._half = [Lru() for _ in range(self.p)]  # Q_t^T W, keyed on beta_theta
        self._rot = [Lru() for _ in range(self.p)]
        self._terms = [Lru() for _ in range(self.p)]

    def _eig(self, dist: FloatArray, beta: FloatArray) -> SymEig:
        corr = np.exp(-np.tensordot(beta, dist, axes=1))
        return SymEig.of(corr)

    def basis_loglik(self, j: int, beta: FloatArray, tau: float, lam: float) -> float:
        """``log N(w_j; 0, a_j I + tau^-1 R_theta ⊗ R_x)`` of basis ``j``.

        Raises
        ------
        numpy.linalg.LinAlgError
            If the covariance is not numerically positive definite.
        """
        bt, bx = beta[: self.t], beta[self.t :]
        kt, kx = bt.tobytes(), bx.tobytes()
        eig_t = self._eig_t[j].get(kt, lambda: self._eig(self.d_theta, bt))
        eig_x = self._eig_x[j].get(kx, lambda: self._eig(self.d_x, bx))

        def rotate() -> FloatArray:
            # (Q_t^T W) Q_x with the left half kept: a move of an x parameter
            # costs one R m*^2 product instead of R^2 m* + R m*^2.
            half = self._half[j].get(kt, lambda: eig_t.vectors.T @ self.w_grid[j])
            rot = half @ eig_x.vectors
            return rot * rot

        rot_sq = self._rot[j].get(kt + kx, rotate)
        den = np.multiply.outer(eig_t.values / tau, eig_x.values)
        den += 1.0 / (lam * self.ktk[j])
        if not den.min() > 0.0:
            raise np.linalg.LinAlgError("training covariance is not positive definite")
        quad = float(np.sum(rot_sq / den))
        return -0.5 * (den.size * LOG_2PI + float(np.sum(np.log(den))) + quad)

    def _basis_term(self, j: int, block: FloatArray, lam: float) -> float:
        beta, tau = block[:-1], float(block[-1])
        pr = self.priors
        prior = log_prior_beta(beta, pr.rho_a, pr.rho_b) + log_gamma(tau, pr.tau_shape, pr.tau_rate)
        if prior == -math.inf:
            return prior
        try:
            return prior + self.basis_loglik(j, beta, tau, lam)
        except np.linalg.LinAlgError:
            return -math.inf

    def __call__(self, v: ArrayLike) -> float:
        """Log posterior (eq. 9) at ``v = [beta_1, tau_1, ..., beta_p, tau_p, lambda]``."""
        arr = np.asarray(v, dtype=float)
        lam = float(arr[self.layout.lam_index])
        total = log_gamma(lam, *self.lam_prior)
        if total == -math.inf:
            return total
        lam_key = arr[self.layout.lam_index :].tobytes()
        for j in range(self.p):
            block = arr[self.layout.block(j)]
            key = block.tobytes() + lam_key
            total += self._terms[j].get(key, partial(self._basis_term, j, block, lam))
            if total == -math.inf:
                return total
        return total


def _starts(
    layout: HyperLayout, lam_prior: tuple[float, float], n_chains: int, rng: np.random.Generator
) -> FloatArray:
    """Dispersed starting points: beta about 1, tau about 1, lambda about its prior mean."""
    shape, rate = lam_prior
    out: list[FloatArray] = []
    for _ in range(n_chains):
        beta = np.exp(rng.normal(0.0, 0.5, (layout.p, layout.r)))
        tau = np.exp(rng.normal(0.0, 0.3, layout.p))
        lam = shape / rate * math.exp(rng.normal(0.0, 1.0 / math.sqrt(shape)))
        out.append(layout.pack(beta, tau, lam))
    return np.array(out)


def _initial_scales(layout: HyperLayout, lam_shape: float) -> FloatArray:
    """Log-scale proposal widths: 0.5 for beta, 0.3 for tau, ~2.4 prior sd for lambda."""
    beta = np.full((layout.p, layout.r), 0.5)
    return layout.pack(beta, np.full(layout.p, 0.3), 2.4 / math.sqrt(lam_shape))


@dataclass(frozen=True)
class _LogScale:
    """Negative log-scale posterior density ``-(log p(e^u) + sum u)`` for the optimiser."""

    target: TrainingPosterior

    def __call__(self, u: FloatArray) -> float:
        with np.errstate(over="ignore"):
            value = self.target(np.exp(u)) + float(np.sum(u))
        return 1e300 if not math.isfinite(value) else -value


def _map(
    target: TrainingPosterior, chains: Chains, refine: bool, max_iter: int
) -> tuple[FloatArray, float, FloatArray, float]:
    """Best draw and refined MAP on the log scale, with their log-scale densities."""
    draws = chains.draws.reshape(-1, target.layout.d)
    score = chains.log_density.reshape(-1) + np.sum(np.log(draws), axis=1)
    best_i = int(np.argmax(score))
    best, best_score = draws[best_i].copy(), float(score[best_i])
    if not refine:
        return best, best_score, best, best_score
    f = _LogScale(target)
    res = optimize.minimize(
        f, np.log(best), method="L-BFGS-B", options={"maxiter": max_iter, "maxfun": 40 * max_iter}
    )
    if math.isfinite(res.fun) and -res.fun > best_score:
        return best, best_score, np.exp(res.x), float(-res.fun)
    return best, best_score, best, best_score


@dataclass(frozen=True)
class _Fit:
    """What a training method hands to the :class:`Emulator` (see its attributes)."""

    v_map: FloatArray
    draws: FloatArray
    lp: FloatArray
    acceptance: FloatArray
    best: FloatArray
    best_score: float
    map_score: float


@dataclass(frozen=True)
class _Progress:
    """Reports a share of the work as the MCMC iteration count the caller expects."""

    callback: Callable[[int], None] | None
    total: int
    parts: int

    def __call__(self, done: int) -> None:
        if self.callback is not None:
            self.callback(min(self.total, round(self.total * done / self.parts)))


def _warm_blocks(warm: Emulator | None, assembled: Assembled) -> tuple[FloatArray, ...]:
    """``ln [beta_j, tau_j]`` of each basis of ``warm`` (none where its inputs differ)."""
    if warm is None or tuple(warm.input_labels) != tuple(assembled.input_labels):
        return ()
    blocks = np.column_stack([np.log(warm.beta), np.log(warm.tau)])
    return tuple(blocks)


def _fit_map(
    target: LogScalePosterior,
    n_draws: int,
    seed: int,
    processes: int,
    settings: MapSettings | None,
    progress: _Progress,
    warm: tuple[FloatArray, ...] = (),
) -> _Fit:
    """``method="map"``: multi-start L-BFGS-B, then the Laplace approximation."""
    layout = target.layout
    found = find_map(
        target, seed=seed, settings=settings, processes=processes, callback=progress, warm=warm
    )
    cov = laplace_covariance(laplace_hessian(target, found.u))
    draws = laplace_draws(found.u, cov, n_draws, np.random.default_rng([seed, 3]))
    progress(progress.parts)
    return _Fit(
        v_map=np.exp(found.u),
        draws=draws[None, :, :],
        lp=np.full((1, n_draws), np.nan),
        acceptance=np.full((1, layout.d), np.nan),
        best=np.exp(found.u_start),
        best_score=found.value_start,
        map_score=found.value,
    )


def train(
    assembled: Assembled,
    *,
    method: TrainingMethod = "map",
    n_burn: int = 500,
    n_draws: int = 1000,
    n_chains: int = 2,
    seed: int = 0,
    backend: ChainBackend = "serial",
    priors: HyperPriors | None = None,
    refine: bool = True,
    max_iter: int = 100,
    max_adapt: float = 0.2,
    callback: Callable[[int], None] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
    map_settings: MapSettings | None = None,
    warm: Emulator | None = None,
) -> Emulator:
    """Train the emulator: the MAP of eq. 9 and the conditioned GP (method.md section 3).

    Parameters
    ----------
    assembled
        The assembled data (:func:`bayescal.emulator.assemble.assemble`).
    method
        ``"map"`` (multi-start L-BFGS-B with the exact gradient and a Laplace
        approximation; default) or ``"mcmc"`` (the paper's Metropolis-within-Gibbs
        chains, best draw refined); see the module docstring.
    n_burn
        ``"mcmc"``: burn-in sweeps per chain (proposal widths adapted, then frozen).
    n_draws
        ``"mcmc"``: kept sweeps per chain; ``"map"``: draws from the Laplace
        approximation.
    n_chains
        ``"mcmc"``: number of chains (dispersed starts).
    seed
        Root seed of the chains or of the random starts (recorded in the emulator).
    backend
        ``"processes"`` or ``"auto"`` (``"mcmc"``: one worker per chain;
        ``"map"``: the bases searched in up to ``os.cpu_count()`` workers),
        ``"serial"`` or ``"vectorised"`` (``"mcmc"``: the chains in lockstep
        here, see :func:`bayescal.mcmc.chains.run_chains`; ``"map"``: as
        ``"serial"``).
    priors
        Priors of ``tau`` and ``rho`` (default: the paper's).
    refine
        ``"mcmc"``: refine the best draw by L-BFGS-B on the log scale.
    max_iter
        ``"mcmc"``: iterations of the refinement.
    max_adapt
        ``"mcmc"``: cap of the per-batch change of a log proposal width during burn-in.
    callback
        Progress: called with the iterations completed over all chains
        (``"map"``: the share of the search done, in the same units).
    checkpoint_dir
        ``"mcmc"``: folder for per-chain snapshots; a killed run resumes from
        them with identical draws (see :func:`bayescal.mcmc.chains.run_chains`).
    checkpoint_seconds
        Minimum wall time between two snapshots of a chain. [s]
    map_settings
        ``"map"``: settings of the search (:class:`~bayescal.emulator.mapfit.MapSettings`).
    warm
        ``"map"``: an emulator of a similar problem (the same inputs, e.g. the
        sequential design's previous step) whose MAP starts the search of each of
        its bases (:func:`~bayescal.emulator.mapfit.find_map`, "Warm starts"): a
        local search, much cheaper than the multi-start one. Ignored where its
        inputs differ, and by ``"mcmc"``.

    Returns
    -------
    Emulator
    """
    if method not in TRAINING_METHODS:
        raise ConfigError(
            f"training method must be one of {list(TRAINING_METHODS)}, got {method!r}"
        )
    hp = HyperPriors() if priors is None else priors
    args = (assembled.theta, assembled.x, assembled.w, assembled.basis.ktk, assembled.lam_prior)
    if method == "map":
        p = assembled.basis.p
        progress = _Progress(callback, n_chains * (n_burn + n_draws), p + 2)
        processes = default_processes(p) if backend in ("processes", "auto") else 1
        fit = _fit_map(
            LogScalePosterior(*args, hp),
            n_draws,
            seed,
            processes,
            map_settings,
            progress,
            _warm_blocks(warm, assembled),
        )
    else:
        target = TrainingPosterior(*args, hp)
        layout = target.layout
        starts = _starts(layout, assembled.lam_prior, n_chains, np.random.default_rng([seed, 1]))
        sampler = MetropolisWithinGibbs(
            n_burn=n_burn,
            lower=[0.0] * layout.d,
            scales=_initial_scales(layout, assembled.lam_prior[0]).tolist(),
            batch_size=25,
            max_adapt=max_adapt,
        )
        chains = run_chains(
            sampler,
            target,
            starts,
            n_draws,
            seed=seed,
            names=layout.names(assembled.input_labels),
            backend=backend,
            callback=callback,
            checkpoint_dir=checkpoint_dir,
            checkpoint_seconds=checkpoint_seconds,
        )
        best, best_score, v_map, map_score = _map(target, chains, refine, max_iter)
        fit = _Fit(
            v_map, chains.draws, chains.log_density, chains.acceptance, best, best_score, map_score
        )
    beta, tau, lam = HyperLayout(assembled.basis.p, len(assembled.input_labels)).unpack(fit.v_map)
    return Emulator(
        parameter_names=assembled.parameter_names,
        input_labels=tuple(assembled.input_labels),
        theta_normaliser=assembled.theta_normaliser,
        outputs=assembled.outputs,
        basis=assembled.basis,
        inputs=assembled.inputs,
        theta=assembled.theta,
        x=assembled.x,
        w=assembled.w,
        y_std=assembled.y_std,
        beta=beta,
        tau=tau,
        lam=lam,
        lam_prior=assembled.lam_prior,
        hyper_draws=fit.draws,
        hyper_lp=fit.lp,
        hyper_acceptance=fit.acceptance,
        best_draw=fit.best,
        log_post_best=fit.best_score,
        log_post_map=fit.map_score,
        seed=int(seed),
        hyper_priors=hp,
    )
