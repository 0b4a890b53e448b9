"""Gaussian-process emulator: hyperparameter posterior, training, prediction, LOO-CV.

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
:func:`train` runs adaptive Metropolis-within-Gibbs chains (proposal widths
adapted during burn-in only, each coordinate sampled on the log scale) and
takes as MAP the mode of the posterior density **of the sampled log-scale
coordinates** ``(ln beta, ln tau, ln lambda)``: the best draw by that
density, refined by a short L-BFGS-B search. That mode exists; the mode of the
density of ``beta`` itself does not for inputs without influence (the
``Beta(1, 0.1)`` prior diverges at ``rho = 1``). Both the best draw and the
refined point are kept.

Prediction
----------
With hyperparameters fixed at the MAP, each basis weight at a new input
``z0 = [theta0, x0]`` is predicted by the GP conditional on the training
weights (exact, through the Kronecker eigen-decomposition), then mapped
through ``K`` and the standardisation. The variance of an output sample is
``sum_j k_j^2 var(w_j) + 1 / lambda`` (latent-weight uncertainty plus the
simulator's out-of-basis part, eq. 3) times ``sd^2``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import optimize, special

from bayescal.calibration.chains import Chains, run_chains
from bayescal.calibration.diagnostics import Diagnostics, diagnose
from bayescal.calibration.samplers.mwg import MetropolisWithinGibbs
from bayescal.emulator.assemble import Assembled, OutputStack
from bayescal.emulator.basis import Basis, InputPCA, Normaliser
from bayescal.emulator.kernel import LOG_2PI, FloatArray, SeparableKernel
from bayescal.emulator.kron import SymEig
from bayescal.errors import ConfigError, DataError

__all__ = [
    "Emulator",
    "HyperLayout",
    "HyperPriors",
    "LooResult",
    "TrainingPosterior",
    "train",
]

Backend = Literal["processes", "serial"]
_LOG4 = math.log(4.0)


@dataclass(frozen=True)
class HyperPriors:
    """Priors of the covariance hyperparameters (paper: Gamma(5, 5) and Beta(1, 0.1)).

    Parameters
    ----------
    tau_shape, tau_rate
        Gamma prior of each ``tau_j``. [-]
    rho_a, rho_b
        Beta prior of each ``rho_lj``. [-]
    """

    tau_shape: float = 5.0
    tau_rate: float = 5.0
    rho_a: float = 1.0
    rho_b: float = 0.1

    def __post_init__(self) -> None:
        for name in ("tau_shape", "tau_rate", "rho_a", "rho_b"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"hyperprior {name} must be finite and > 0, got {value!r}")


@dataclass(frozen=True)
class HyperLayout:
    """Positions of the hyperparameters in the sampled vector.

    Parameters
    ----------
    p
        Number of basis vectors.
    r
        Number of inputs ``t + s``.
    """

    p: int
    r: int

    @property
    def d(self) -> int:
        """Length of the vector: ``p (r + 1) + 1``."""
        return self.p * (self.r + 1) + 1

    @property
    def lam_index(self) -> int:
        """Index of ``lambda`` (the last)."""
        return self.p * (self.r + 1)

    def block(self, j: int) -> slice:
        """``[beta_1j .. beta_rj, tau_j]`` of basis ``j``."""
        return slice(j * (self.r + 1), (j + 1) * (self.r + 1))

    def pack(self, beta: ArrayLike, tau: ArrayLike, lam: float) -> FloatArray:
        """``beta`` ``(p, r)``, ``tau`` ``(p,)`` and ``lambda`` -> vector ``(d,)``."""
        b = np.asarray(beta, dtype=float).reshape(self.p, self.r)
        t = np.asarray(tau, dtype=float).reshape(self.p, 1)
        return np.concatenate([np.hstack([b, t]).reshape(-1), [float(lam)]])

    def unpack(self, v: ArrayLike) -> tuple[FloatArray, FloatArray, float]:
        """Vector ``(d,)`` -> ``beta`` ``(p, r)``, ``tau`` ``(p,)``, ``lambda``."""
        arr = np.asarray(v, dtype=float)
        blocks = arr[: self.lam_index].reshape(self.p, self.r + 1)
        return blocks[:, : self.r].copy(), blocks[:, self.r].copy(), float(arr[self.lam_index])

    def names(self, labels: Sequence[str]) -> list[str]:
        """Coordinate names: ``beta[<input>,<j>]``, ``tau[<j>]``, ``lambda``."""
        out: list[str] = []
        for j in range(self.p):
            out.extend(f"beta[{label},{j}]" for label in labels)
            out.append(f"tau[{j}]")
        return [*out, "lambda"]


class _Lru:
    """A tiny least-recently-used memo (MwG alternates proposed and current values)."""

    def __init__(self, size: int = 3) -> None:
        self.size = size
        self.items: dict[bytes, Any] = {}

    def get(self, key: bytes, make: Callable[[], Any]) -> Any:
        if key in self.items:
            value = self.items.pop(key)
        else:
            value = make()
            if len(self.items) >= self.size:
                del self.items[next(iter(self.items))]
        self.items[key] = value
        return value


def _squared_distances(a: FloatArray) -> FloatArray:
    """``(d, N, N)``: ``(a_il - a_kl)^2`` for every column ``l``."""
    diff = a.T[:, :, None] - a.T[:, None, :]
    return diff * diff


def _log_prior_beta(beta: FloatArray, a: float, b: float) -> float:
    """Sum of log densities of ``beta = -4 ln rho`` with ``rho ~ Beta(a, b)``."""
    if not np.all(beta > 0.0):
        return -math.inf
    log_rho = -0.25 * beta
    with np.errstate(divide="ignore"):
        log1m = np.log(-np.expm1(log_rho))
    if not np.all(np.isfinite(log1m)):
        return -math.inf  # beta below ~1e-300: no float can represent 1 - rho
    terms = a * log_rho + (b - 1.0) * log1m
    return float(np.sum(terms)) - beta.size * (_LOG4 + float(special.betaln(a, b)))


def _log_gamma(value: float, shape: float, rate: float) -> float:
    """Log Gamma(shape, rate) density up to its constant; ``-inf`` for value <= 0."""
    if not value > 0.0:
        return -math.inf
    return (shape - 1.0) * math.log(value) - rate * value


class TrainingPosterior:
    """Log posterior of eq. 9 over ``(beta, tau, lambda)``, up to a constant; picklable.

    Parameters
    ----------
    theta
        Normalised design, ``(R, t)``. [-]
    x
        Normalised variable conditions, ``(m*, s)``. [-]
    w
        Simulator weights, ``(R m*, p)``, run-major rows. [-]
    ktk
        ``k_j^T k_j``, ``(p,)``. [-]
    lam_prior
        ``(shape, rate)`` of the Gamma prior of ``lambda`` (eq. 7).
    priors
        Priors of ``tau`` and ``rho``.
    """

    def __init__(
        self,
        theta: ArrayLike,
        x: ArrayLike,
        w: ArrayLike,
        ktk: ArrayLike,
        lam_prior: tuple[float, float],
        priors: HyperPriors | None = None,
    ) -> None:
        self.theta = np.asarray(theta, dtype=float)
        self.x = np.asarray(x, dtype=float)
        w_arr = np.asarray(w, dtype=float)
        n_runs, n_per = self.theta.shape[0], self.x.shape[0]
        if w_arr.ndim != 2 or w_arr.shape[0] != n_runs * n_per:
            raise DataError(
                f"weights have shape {w_arr.shape}, expected ({n_runs} runs x {n_per} periods, p)"
            )
        self.p = w_arr.shape[1]
        self.t = self.theta.shape[1]
        self.layout = HyperLayout(self.p, self.t + self.x.shape[1])
        self.w_grid = w_arr.T.reshape(self.p, n_runs, n_per)
        self.ktk = np.asarray(ktk, dtype=float).reshape(self.p)
        self.lam_prior = (float(lam_prior[0]), float(lam_prior[1]))
        self.priors = HyperPriors() if priors is None else priors
        self.d_theta = _squared_distances(self.theta)
        self.d_x = _squared_distances(self.x)
        self._reset_caches()

    def _reset_caches(self) -> None:
        self._eig_t = [_Lru() for _ in range(self.p)]
        self._eig_x = [_Lru() for _ in range(self.p)]
        self._half = [_Lru() for _ in range(self.p)]  # Q_t^T W, keyed on beta_theta
        self._rot = [_Lru() for _ in range(self.p)]
        self._terms = [_Lru() for _ in range(self.p)]

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        for key in ("_eig_t", "_eig_x", "_half", "_rot", "_terms"):
            state.pop(key)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._reset_caches()

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
        prior = _log_prior_beta(beta, pr.rho_a, pr.rho_b) + _log_gamma(
            tau, pr.tau_shape, pr.tau_rate
        )
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
        total = _log_gamma(lam, *self.lam_prior)
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


@dataclass(frozen=True)
class _Conditional:
    """GP of one basis conditioned on weights on a grid (hyperparameters fixed)."""

    kernel: SeparableKernel
    theta: FloatArray  # (R, t)
    x: FloatArray  # (m*, s)
    q_t: FloatArray  # eigenvectors of S_theta (with tau^-1)
    q_x: FloatArray  # eigenvectors of S_x
    inv_den: FloatArray  # 1 / (l_k l_i + a), (R, m*)
    h: FloatArray  # A^-1 w as an (R, m*) matrix

    @classmethod
    def build(
        cls, kernel: SeparableKernel, theta: FloatArray, x: FloatArray, v: FloatArray, a: float
    ) -> _Conditional:
        eig_t = SymEig.of(kernel.theta_cov(theta))
        eig_x = SymEig.of(kernel.x_corr(x))
        den = np.multiply.outer(eig_t.values, eig_x.values) + a
        rot = eig_t.vectors.T @ v @ eig_x.vectors
        h = eig_t.vectors @ (rot / den) @ eig_x.vectors.T
        return cls(kernel, theta, x, eig_t.vectors, eig_x.vectors, 1.0 / den, h)

    def predict(self, theta_new: FloatArray, x_new: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Mean and variance ``(q,)`` of the latent weight at ``q`` paired inputs."""
        c_t = self.kernel.theta_cov(theta_new, self.theta)  # (q, R), carries tau^-1
        c_x = self.kernel.x_corr(x_new, self.x)  # (q, m*)
        mean = np.sum((c_t @ self.h) * c_x, axis=1)
        a_t = c_t @ self.q_t
        a_x = c_x @ self.q_x
        reduction = np.sum(((a_t * a_t) @ self.inv_den) * (a_x * a_x), axis=1)
        return mean, np.maximum(self.kernel.variance - reduction, 0.0)

    def leave_one_run_out(self, v: FloatArray, a: float) -> tuple[FloatArray, FloatArray]:
        """Latent mean and variance ``(R, m*)`` of each run predicted from the others.

        Closed form of dropping run ``b`` (all its periods) and conditioning on
        the rest: with ``A = S_theta ⊗ S_x + a I`` and ``P = A^-1``, the
        predictive covariance of ``v_b`` is ``(P_bb)^-1`` and its mean
        ``v_b - (P_bb)^-1 (A^-1 v)_b``. Since ``P_bb = Q_x diag(g_b) Q_x^T`` with
        ``g_b,i = sum_k Q_theta[b, k]^2 / (l_k l_i + a)``, every run costs
        ``O(m*^2)`` instead of a new ``O(R^3 + m*^3)`` factorisation.

        Parameters
        ----------
        v
            The training weights of this basis on the grid ``(R, m*)``. [-]
        a
            The nugget the covariance was built with. [-]
        """
        g = (self.q_t * self.q_t) @ self.inv_den  # (R, m*)
        mean = v - ((self.h @ self.q_x) / g) @ self.q_x.T
        var = (1.0 / g) @ (self.q_x * self.q_x).T - a
        return mean, np.maximum(var, 0.0)


@dataclass(frozen=True)
class ConditionalPieces:
    """The factorised training covariance of every basis, stacked over bases.

    Stored in the artefact so that a loaded emulator predicts bit for bit what the
    saved one did (a fresh eigen-decomposition may differ in the last bits).

    Attributes
    ----------
    q_t
        Eigenvectors of ``S_theta``, ``(p, R, R)``.
    q_x
        Eigenvectors of ``S_x``, ``(p, m*, m*)``.
    inv_den
        ``1 / (l_k l_i + a)``, ``(p, R, m*)``.
    h
        ``A^-1 w`` as ``(p, R, m*)``.
    """

    q_t: FloatArray
    q_x: FloatArray
    inv_den: FloatArray
    h: FloatArray


@dataclass(frozen=True)
class LooResult:
    """Leave-one-run-out cross-validation of the emulator.

    Attributes
    ----------
    rmse
        Output name -> RMSE over all held-out runs, periods and samples, in the
        output's unit.
    output_sd
        Output name -> SD of the simulated output over all runs, periods and
        samples, same unit (the scale the RMSE is judged against).
    rmse_run
        RMSE per held-out run and output, ``(R, n_outputs)``.
    z
        Standardised residuals ``(y - mean) / sd_pred``, ``(R, N, m*)``. [-]
    """

    rmse: dict[str, float]
    output_sd: dict[str, float]
    rmse_run: FloatArray
    z: FloatArray

    def coverage(self, level: float = 0.95) -> float:
        """Fraction of held-out samples inside their central ``level`` band."""
        half = float(special.ndtri(0.5 + 0.5 * level))
        return float(np.mean(np.abs(self.z) <= half))


@dataclass(frozen=True)
class Emulator:
    """A trained emulator (immutable): data, hyperparameters at the MAP and their draws.

    Attributes
    ----------
    parameter_names
        Calibration parameters (the first ``t`` inputs).
    input_labels
        Labels of all ``r`` inputs ``[theta, x]``.
    theta_normaliser
        Prior bounds of theta (physical <-> [0, 1]).
    outputs
        Standardisation and stacking of the outputs.
    basis
        Output PCA basis ``K``.
    inputs
        PCA of the boundary conditions (``inputs.transform`` gives ``x`` of new periods).
    theta
        Normalised design ``(R, t)``. [-]
    x
        Normalised variable conditions of the training periods ``(m*, s)``. [-]
    w
        Training weights ``(R m*, p)``, run-major. [-]
    y_std
        Standardised training simulations ``(N, R m*)`` (for cross-validation). [-]
    beta
        MAP ``-4 ln rho``, ``(p, r)``. [-]
    tau
        MAP GP precisions ``(p,)``. [-]
    lam
        MAP simulator precision ``lambda``. [-]
    lam_prior
        ``(shape, rate)`` of the Gamma prior of ``lambda`` (eq. 7).
    hyper_draws
        Posterior draws of the hyperparameter vector ``(chains, draws, d)``.
    hyper_lp
        Log posterior at the draws ``(chains, draws)``.
    hyper_acceptance
        Acceptance rate per chain and coordinate ``(chains, d)``.
    best_draw
        The draw with the highest log-scale posterior density ``(d,)``.
    log_post_best, log_post_map
        Log-scale posterior density (up to a constant) at the best draw and at the MAP.
    seed
        Root seed of the training chains.
    hyper_priors
        Priors of ``tau`` and ``rho``.
    conditional
        The factorised training covariances; computed from the above when
        omitted (given by :func:`bayescal.artefacts.load_emulator`).
    """

    parameter_names: tuple[str, ...]
    input_labels: tuple[str, ...]
    theta_normaliser: Normaliser
    outputs: OutputStack
    basis: Basis
    inputs: InputPCA
    theta: FloatArray
    x: FloatArray
    w: FloatArray
    y_std: FloatArray
    beta: FloatArray
    tau: FloatArray
    lam: float
    lam_prior: tuple[float, float]
    hyper_draws: FloatArray
    hyper_lp: FloatArray
    hyper_acceptance: FloatArray
    best_draw: FloatArray
    log_post_best: float
    log_post_map: float
    seed: int
    hyper_priors: HyperPriors = field(default_factory=HyperPriors)
    conditional: ConditionalPieces | None = field(default=None, repr=False, compare=False)
    _cond: tuple[_Conditional, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        pc = self.conditional
        if pc is None:
            n_runs, n_per = self.theta.shape[0], self.x.shape[0]
            grid = self.w.T.reshape(self.basis.p, n_runs, n_per)
            nug = self.nuggets
            cond = [
                _Conditional.build(k, self.theta, self.x, grid[j], float(nug[j]))
                for j, k in enumerate(self.kernels)
            ]
            pc = ConditionalPieces(
                np.stack([c.q_t for c in cond]),
                np.stack([c.q_x for c in cond]),
                np.stack([c.inv_den for c in cond]),
                np.stack([c.h for c in cond]),
            )
            object.__setattr__(self, "conditional", pc)
        cond_t = tuple(
            _Conditional(k, self.theta, self.x, pc.q_t[j], pc.q_x[j], pc.inv_den[j], pc.h[j])
            for j, k in enumerate(self.kernels)
        )
        object.__setattr__(self, "_cond", cond_t)

    @property
    def pieces(self) -> ConditionalPieces:
        """The factorised training covariances (always set after construction)."""
        if self.conditional is None:  # pragma: no cover - __post_init__ sets it
            raise RuntimeError("emulator was built without its conditional pieces")
        return self.conditional

    @property
    def layout(self) -> HyperLayout:
        """Positions of the hyperparameters in ``hyper_draws``."""
        return HyperLayout(self.basis.p, len(self.input_labels))

    @property
    def hyper_names(self) -> list[str]:
        """Names of the hyperparameter coordinates."""
        return self.layout.names(self.input_labels)

    @property
    def kernels(self) -> tuple[SeparableKernel, ...]:
        """One :class:`SeparableKernel` per basis at the MAP."""
        t = len(self.parameter_names)
        return tuple(
            SeparableKernel.from_beta(self.beta[j], float(self.tau[j]), t)
            for j in range(self.basis.p)
        )

    @property
    def rho(self) -> FloatArray:
        """MAP correlation parameters ``(p, r)``: sensitivity (small = influential)."""
        return np.exp(-0.25 * self.beta)

    @property
    def nuggets(self) -> FloatArray:
        """``(lambda k_j^T k_j)^-1`` per basis ``(p,)``."""
        return 1.0 / (self.lam * self.basis.ktk)

    def hyper_diagnostics(self) -> Diagnostics:
        """R-hat, ESS and warnings of the hyperparameter chains."""
        return diagnose(self.hyper_draws, self.hyper_names, self.hyper_acceptance)

    def _pairs(self, theta_unit: ArrayLike, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        t, s = len(self.parameter_names), self.x.shape[1]
        th = np.atleast_2d(np.asarray(theta_unit, dtype=float))
        xx = np.atleast_2d(np.asarray(x, dtype=float))
        if th.shape[1] != t or xx.shape[1] != s:
            raise DataError(
                f"expected theta with {t} columns and x with {s} columns, "
                f"got shapes {th.shape} and {xx.shape}"
            )
        q = max(th.shape[0], xx.shape[0])
        if th.shape[0] not in (1, q) or xx.shape[0] not in (1, q):
            raise DataError(f"theta has {th.shape[0]} rows and x {xx.shape[0]}; expected equal")
        return np.broadcast_to(th, (q, t)), np.broadcast_to(xx, (q, s))

    def predict_weights(self, theta_unit: ArrayLike, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Predictive mean and variance of the weights ``(q, p)`` at normalised inputs.

        Parameters
        ----------
        theta_unit
            Normalised parameters ``(q, t)`` or ``(t,)``. [-]
        x
            Normalised variable conditions ``(q, s)`` or ``(s,)``. [-]
        """
        th, xx = self._pairs(theta_unit, x)
        parts = [c.predict(th, xx) for c in self._cond]
        return np.column_stack([m for m, _ in parts]), np.column_stack([v for _, v in parts])

    def predict_std(self, theta_unit: ArrayLike, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Mean and variance of standardised output ``(N, q)`` at normalised inputs."""
        mean_w, var_w = self.predict_weights(theta_unit, x)
        k = self.basis.k
        return k @ mean_w.T, (k * k) @ var_w.T + 1.0 / self.lam

    def predict(self, theta_phys: ArrayLike, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Predictive mean and variance of the simulator output in physical units.

        Parameters
        ----------
        theta_phys
            Parameters in physical units, ``(q, t)`` or ``(t,)`` (broadcast
            against ``x``).
        x
            Normalised variable conditions of the periods, ``(q, s)`` or ``(s,)``
            (rows of ``Assembled.x`` or ``inputs.transform(...)``). [-]

        Returns
        -------
        mean, variance
            ``(N, q)`` each: column ``i`` is the period at input pair ``i``,
            outputs stacked along the rows (``outputs.split``), mean in the
            outputs' units, variance in their squares. The variance includes
            the out-of-basis noise ``1 / lambda``.
        """
        th, xx = self._pairs(theta_phys, x)
        mean, var = self.predict_std(self.theta_normaliser.apply(th), xx)
        sd = self.outputs.sd[:, None]
        return self.outputs.invert(mean), var * sd * sd

    def loo_predict(self) -> tuple[FloatArray, FloatArray]:
        """Leave-one-run-out predictions, standardised, hyperparameters at the MAP.

        Each run is predicted from the other ``R - 1`` in closed form
        (:meth:`_Conditional.leave_one_run_out`); equal to refitting without the
        run to rounding (``tests/test_gp.py``).

        Returns
        -------
        mean, variance
            ``(R, N, m*)`` each on the standardised scale; the variance includes
            the out-of-basis noise ``1 / lambda``.
        """
        n_runs, n_per = self.theta.shape[0], self.x.shape[0]
        grid = self.w.T.reshape(self.basis.p, n_runs, n_per)
        parts = [
            cond.leave_one_run_out(grid[j], float(a))
            for j, (cond, a) in enumerate(zip(self._cond, self.nuggets, strict=True))
        ]
        mean_w = np.stack([m for m, _ in parts])  # (p, R, m*)
        var_w = np.stack([v for _, v in parts])
        k = self.basis.k
        mean = np.einsum("np,prm->rnm", k, mean_w)
        var = np.einsum("np,prm->rnm", k * k, var_w) + 1.0 / self.lam
        return mean, var

    def loo_cv(self) -> LooResult:
        """Leave-one-run-out cross-validation (hyperparameters fixed at the MAP)."""
        n_runs, n_per = self.theta.shape[0], self.x.shape[0]
        sd = self.outputs.sd[:, None]
        mean, var = self.loo_predict()
        sim = self.y_std.reshape(-1, n_runs, n_per).transpose(1, 0, 2)
        resid = sim - mean
        z = resid / np.sqrt(var)
        sq = np.mean((resid * sd) ** 2, axis=2)
        slices = self.outputs.slices
        phys = self.outputs.invert(self.y_std)
        return LooResult(
            rmse={n: float(np.sqrt(np.mean(sq[:, sl]))) for n, sl in slices.items()},
            output_sd={n: float(np.std(phys[sl])) for n, sl in slices.items()},
            rmse_run=np.column_stack(
                [np.sqrt(np.mean(sq[:, sl], axis=1)) for sl in slices.values()]
            ),
            z=z,
        )


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


def train(
    assembled: Assembled,
    *,
    n_burn: int = 500,
    n_draws: int = 1000,
    n_chains: int = 2,
    seed: int = 0,
    backend: Backend = "serial",
    priors: HyperPriors | None = None,
    refine: bool = True,
    max_iter: int = 100,
    max_adapt: float = 0.2,
    callback: Callable[[int], None] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
) -> Emulator:
    """Train the emulator: MwG chains over eq. 9, MAP, conditioned GP (method.md section 3).

    Parameters
    ----------
    assembled
        The assembled data (:func:`bayescal.emulator.assemble.assemble`).
    n_burn
        Burn-in sweeps per chain (proposal widths adapted, then frozen).
    n_draws
        Kept sweeps per chain.
    n_chains
        Number of chains (dispersed starts).
    seed
        Root seed of the chains (recorded in the emulator).
    backend
        ``"processes"`` (one worker per chain) or ``"serial"``.
    priors
        Priors of ``tau`` and ``rho`` (default: the paper's).
    refine
        Refine the best draw by L-BFGS-B on the log scale.
    max_iter
        Iterations of the refinement.
    max_adapt
        Cap of the per-batch change of a log proposal width during burn-in.
    callback
        Progress: called with the iterations completed over all chains.
    checkpoint_dir
        Folder for per-chain snapshots; a killed run resumes from them with
        identical draws (see :func:`bayescal.calibration.chains.run_chains`).
    checkpoint_seconds
        Minimum wall time between two snapshots of a chain. [s]

    Returns
    -------
    Emulator
    """
    if backend not in ("processes", "serial"):
        raise ConfigError(f"backend must be 'processes' or 'serial', got {backend!r}")
    hp = HyperPriors() if priors is None else priors
    target = TrainingPosterior(
        assembled.theta, assembled.x, assembled.w, assembled.basis.ktk, assembled.lam_prior, hp
    )
    layout = target.layout
    starts = _starts(layout, assembled.lam_prior, n_chains, np.random.default_rng([seed, 1]))
    sampler = MetropolisWithinGibbs(
        n_burn=n_burn,
        lower=[0.0] * layout.d,
        scales=_initial_scales(layout, assembled.lam_prior[0]).tolist(),
        batch_size=25,
        max_adapt=max_adapt,
    )
    labels = assembled.input_labels
    chains = run_chains(
        sampler,
        target,
        starts,
        n_draws,
        seed=seed,
        names=layout.names(labels),
        parallel=backend == "processes",
        callback=callback,
        checkpoint_dir=checkpoint_dir,
        checkpoint_seconds=checkpoint_seconds,
    )
    best, best_score, v_map, map_score = _map(target, chains, refine, max_iter)
    beta, tau, lam = layout.unpack(v_map)
    return Emulator(
        parameter_names=assembled.parameter_names,
        input_labels=tuple(labels),
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
        hyper_draws=chains.draws,
        hyper_lp=chains.log_density,
        hyper_acceptance=chains.acceptance,
        best_draw=best,
        log_post_best=best_score,
        log_post_map=map_score,
        seed=int(seed),
        hyper_priors=hp,
    )
