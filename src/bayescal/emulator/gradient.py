"""The hyperparameter posterior (eq. 9) on the log scale with its exact gradient.

The emulator's MAP is sought on the scale the chains sample:
``u = (ln beta, ln tau, ln lambda)``, where the density is the posterior of eq. 9
times the Jacobian ``prod exp(u)``; its mode exists (see
:mod:`bayescal.emulator.training`). :class:`LogScalePosterior` returns that log
density and its gradient, so that a quasi-Newton search (L-BFGS-B,
:mod:`bayescal.emulator.mapfit`) needs a few dozen evaluations instead of the
thousands of coordinate moves of Metropolis-within-Gibbs.

Gradient of one basis
---------------------
With ``A = tau^-1 R_theta ⊗ R_x + a I`` (``a = 1 / (lambda k_j^T k_j)``), the
eigen-decompositions ``R_theta = Q_t diag(m_t) Q_t^T`` and ``R_x = Q_x diag(m_x)
Q_x^T``, ``den_ki = m_t,k m_x,i / tau + a``, the rotated weights ``rot = Q_t^T
W Q_x`` and ``B = rot / den`` (so that ``A^-1 w = vec(Q_t B Q_x^T)``):

* ``d log|A| / d beta_theta,l = tr(A^-1 dA) = -tau^-1 sum(D_l ∘ R_theta ∘ P_t)``
  with ``P_t = Q_t diag(c) Q_t^T``, ``c_k = sum_i m_x,i / den_ki``;
* ``d (w^T A^-1 w) / d beta_theta,l = -(A^-1 w)^T dA (A^-1 w)
  = tau^-1 sum(D_l ∘ R_theta ∘ V_t)`` with ``V_t = Q_t B diag(m_x) B^T Q_t^T``;

``D_l`` being the squared differences of input ``l``. The ``x`` inputs are the
same with the roles of the factors exchanged (``P_x = Q_x diag(c') Q_x^T``,
``c'_i = sum_k m_t,k / (tau den_ki)``, ``V_x = Q_x B^T diag(m_t / tau) B
Q_x^T``). On the log scale, with ``s = m_t m_x / tau``:
``d/d ln tau = sum s / den (1 - rot^2 / den) / 2`` and
``d/d ln lambda = a sum (1 - rot^2 / den) / den / 2``. Each evaluation costs the
two eigen-decompositions and ``O(R^3 + R^2 m* + R m*^2 + m*^3)`` products per
basis; ``tests/emulator/test_mapfit.py`` checks the gradient against finite
differences and the value against :class:`~bayescal.emulator.training.TrainingPosterior`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from bayescal.design import log_gamma, log_gamma_of_log
from bayescal.emulator.hyper import HyperLayout, HyperPriors, log_prior_beta
from bayescal.emulator.kernel import LOG_2PI, FloatArray
from bayescal.emulator.kron import Lru, SymEig
from bayescal.errors import DataError

__all__ = ["BasisTerm", "Eq9Data", "LogScalePosterior", "squared_distances"]


def squared_distances(a: FloatArray) -> FloatArray:
    """``(d, N, N)``: ``(a_il - a_kl)^2`` for every column ``l`` of ``a`` ``(N, d)``."""
    diff = a.T[:, :, None] - a.T[:, None, :]
    return diff * diff


@dataclass(frozen=True)
class _Eig:
    """A correlation matrix and its eigen-decomposition."""

    corr: FloatArray
    values: FloatArray
    vectors: FloatArray

    @classmethod
    def of(cls, dist: FloatArray, beta: FloatArray) -> _Eig:
        corr = np.exp(-np.tensordot(beta, dist, axes=1))
        eig = SymEig.of(corr)
        return cls(corr, eig.values, eig.vectors)


@dataclass(frozen=True)
class BasisTerm:
    """Log-scale density of one basis and its gradient.

    Attributes
    ----------
    value
        ``log N(w_j; 0, A_j)`` + the priors of ``beta_j`` and ``tau_j`` + their
        log-scale Jacobian ``sum ln beta_j + ln tau_j`` (``-inf`` outside the support).
    grad
        Derivatives with respect to ``(ln beta_1j .. ln beta_rj, ln tau_j)``, ``(r + 1,)``.
    grad_lam
        Derivative of the likelihood of basis ``j`` with respect to ``ln lambda``.
    """

    value: float
    grad: FloatArray
    grad_lam: float


class Eq9Data:
    """The arrays of eq. 9 that every form of the hyperparameters' posterior shares.

    The design and conditions (normalised), the simulator weights laid out per
    basis on the runs x periods grid, ``k_j^T k_j``, the priors and the squared
    distances of the design and of the conditions. Subclasses keep their own
    caches (:meth:`_reset_caches`), dropped when pickled.

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

    #: Names of the cache attributes (dropped when pickled).
    CACHES: tuple[str, ...] = ()

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
        self.d_theta = squared_distances(self.theta)
        self.d_x = squared_distances(self.x)
        self._reset_caches()

    def _reset_caches(self) -> None:
        """Create empty caches (none here)."""

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        for key in self.CACHES:
            state.pop(key, None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._reset_caches()


class LogScalePosterior(Eq9Data):
    """Eq. 9 on the log scale ``u = ln [beta, tau, lambda]`` with its gradient; picklable.

    ``value(u)`` equals ``TrainingPosterior(exp(u)) + sum(u)`` (the density the
    MAP search of :func:`bayescal.emulator.training.train` maximises).

    Built from the arrays of :class:`~bayescal.emulator.gradient.Eq9Data` (same
    parameters).
    """

    CACHES = ("_eig_t", "_eig_x", "_rot")

    def _reset_caches(self) -> None:
        self._eig_t = [Lru(3) for _ in range(self.p)]
        self._eig_x = [Lru(3) for _ in range(self.p)]
        self._rot = [Lru(2) for _ in range(self.p)]
        self.evaluations = 0

    def subset(self, runs: ArrayLike) -> LogScalePosterior:
        """The same posterior on the design rows ``runs`` only (all periods)."""
        idx = np.asarray(runs, dtype=int)
        w = self.w_grid[:, idx, :].reshape(self.p, -1).T
        return LogScalePosterior(self.theta[idx], self.x, w, self.ktk, self.lam_prior, self.priors)

    @property
    def n_runs(self) -> int:
        """Number of design rows ``R``."""
        return int(self.theta.shape[0])

    @property
    def d(self) -> int:
        """Number of coordinates ``p (r + 1) + 1``."""
        return self.layout.d

    def basis(self, j: int, u_block: FloatArray, lam: float, grad: bool = True) -> BasisTerm:
        """The log-scale term of basis ``j`` at ``u_block = ln [beta_j, tau_j]``.

        Parameters
        ----------
        j
            Basis index.
        u_block
            ``(r + 1,)``: ``ln beta_1j .. ln beta_rj, ln tau_j``.
        lam
            ``lambda`` (not its log). [-]
        grad
            Compute the gradient (else it is returned as zeros).
        """
        r = self.layout.r
        with np.errstate(over="ignore"):
            block = np.exp(u_block)
        beta, tau = block[:r], float(block[r])
        pr = self.priors
        zero = np.zeros(r + 1)
        if not (np.all(np.isfinite(block)) and tau > 0.0):
            return BasisTerm(-math.inf, zero, 0.0)
        prior = log_prior_beta(beta, pr.rho_a, pr.rho_b)
        prior += log_gamma(tau, pr.tau_shape, pr.tau_rate)
        if prior == -math.inf:
            return BasisTerm(-math.inf, zero, 0.0)
        bt, bx = beta[: self.t], beta[self.t :]
        eig_t = self._eig_t[j].get(bt.tobytes(), lambda: _Eig.of(self.d_theta, bt))
        eig_x = self._eig_x[j].get(bx.tobytes(), lambda: _Eig.of(self.d_x, bx))
        self.evaluations += 1
        a = 1.0 / (lam * float(self.ktk[j]))
        mt, mx = eig_t.values / tau, eig_x.values
        s = np.multiply.outer(mt, mx)
        den = s + a
        if not den.min() > 0.0:
            return BasisTerm(-math.inf, zero, 0.0)
        key = bt.tobytes() + bx.tobytes()
        rot = self._rot[j].get(key, lambda: eig_t.vectors.T @ self.w_grid[j] @ eig_x.vectors)
        b = rot / den
        quad = float(np.sum(rot * b))
        loglik = -0.5 * (den.size * LOG_2PI + float(np.sum(np.log(den))) + quad)
        value = loglik + prior + float(np.sum(u_block))
        if not grad:
            return BasisTerm(value, zero, 0.0)
        inv = 1.0 / den
        resid = inv - b * b  # (1 - rot^2 / den) / den
        g = np.empty(r + 1)
        # theta inputs: E_t = R_theta ∘ (P_t - V_t) / tau
        c_t = inv @ mx
        pt = (eig_t.vectors * c_t) @ eig_t.vectors.T
        qb = eig_t.vectors @ b
        e_t = eig_t.corr * (pt - (qb * mx) @ qb.T)
        g[: self.t] = 0.5 / tau * np.tensordot(self.d_theta, e_t, axes=([1, 2], [0, 1]))
        # x inputs: E_x = R_x ∘ (P_x - V_x)
        c_x = mt @ inv
        px = (eig_x.vectors * c_x) @ eig_x.vectors.T
        bq = b @ eig_x.vectors.T
        e_x = eig_x.corr * (px - bq.T @ (bq * mt[:, None]))
        g[self.t : r] = 0.5 * np.tensordot(self.d_x, e_x, axes=([1, 2], [0, 1]))
        g[r] = 0.5 * float(np.sum(s * resid))
        grad_lam = 0.5 * a * float(np.sum(resid))
        # priors and the Jacobian, on the log scale
        g[:r] *= beta
        with np.errstate(over="ignore"):
            g[:r] += beta * (-0.25 * pr.rho_a + 0.25 * (pr.rho_b - 1.0) / np.expm1(0.25 * beta))
        g[:r] += 1.0
        g[r] += (pr.tau_shape - 1.0) - pr.tau_rate * tau + 1.0
        return BasisTerm(value, g, grad_lam)

    def lam_term(self, u_lam: float) -> tuple[float, float]:
        """Prior of ``lambda`` plus its Jacobian on the log scale, and its derivative."""
        shape, rate = self.lam_prior
        return log_gamma_of_log(u_lam, shape, rate) + u_lam, shape - rate * math.exp(u_lam)

    def value_and_grad(self, u: ArrayLike) -> tuple[float, FloatArray]:
        """Log-scale log posterior and its gradient ``(d,)`` at ``u``."""
        arr = np.asarray(u, dtype=float)
        layout = self.layout
        g = np.zeros(layout.d)
        if not math.isfinite(float(arr[layout.lam_index])) or arr[layout.lam_index] > 700.0:
            return -math.inf, g
        total, g[layout.lam_index] = self.lam_term(float(arr[layout.lam_index]))
        lam = math.exp(float(arr[layout.lam_index]))
        for j in range(self.p):
            term = self.basis(j, arr[layout.block(j)], lam)
            if term.value == -math.inf:
                return -math.inf, np.zeros(layout.d)
            total += term.value
            g[layout.block(j)] = term.grad
            g[layout.lam_index] += term.grad_lam
        return total, g

    def value(self, u: ArrayLike) -> float:
        """Log-scale log posterior at ``u`` (no gradient)."""
        arr = np.asarray(u, dtype=float)
        layout = self.layout
        u_lam = float(arr[layout.lam_index])
        if not (math.isfinite(u_lam) and u_lam < 700.0):
            return -math.inf
        total = self.lam_term(u_lam)[0]
        lam = math.exp(u_lam)
        for j in range(self.p):
            total += self.basis(j, arr[layout.block(j)], lam, grad=False).value
            if total == -math.inf:
                return total
        return total
