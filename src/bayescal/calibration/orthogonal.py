"""The orthogonal discrepancy (Plumlee 2017): a discrepancy that cannot stand in for theta.

``[outputs.errors.NAME] discrepancy = "orthogonal"`` keeps the discrepancy over
the periods' conditions of method.md section 4a, ``delta_j ~ GP(0, r tau_j^-1
c_x)`` on the basis weights, but conditions it on being orthogonal to the
model's sensitivities at theta* over the training periods: with ``G_j`` the
derivative of the emulator's mean of basis ``j`` at ``(theta*, x_i)``
(``m_obs x t``, analytic, :func:`rotated_gradient`) and ``F_j = k_j^T k_j G_j``
(the Euclidean inner product of the standardised output: ``K^T K`` is
diagonal), the constraint is ``sum_j F_j^T delta_j = 0``, one row per
parameter and output. The discrepancy's covariance over the training periods
becomes

    Sigma_perp = Sigma - Sigma F (F^T Sigma F)^-1 F^T Sigma,
    Sigma = blockdiag_j(r tau_j^-1 C_x,j[O, O]),

Plumlee's discrete version over the training periods (his integral over the
input space, here a sum over the measured periods and their samples).

The covariance of all the weights is then ``Omega - U M^-1 U^T`` with ``Omega``
today's (block-diagonal over bases), ``U = [0; Sigma F]`` (only observed rows)
and ``M = F^T Sigma F``. By Woodbury and the matrix determinant lemma,

    log |Omega - U M^-1 U^T| = log |Omega| + log |M - C| - log |M|,
    v^T (Omega - U M^-1 U^T)^-1 v = v^T Omega^-1 v + b^T (M - C)^-1 b,

with ``C = U^T Omega^-1 U`` and ``b = U^T Omega^-1 v``. As ``U`` lives on the
observed rows only, both need only the observed block's Schur complement ``S``
of the fast path (:mod:`bayescal.calibration.kron`): ``C = sum (Sigma F)^T S^-1
(Sigma F)``, ``b = sum (Sigma F)^T S^-1 r`` with ``r`` the Schur residual. On a
full grid with white noise ``S`` is diagonal in the rotated bases; elsewhere its
Cholesky factor is at hand. :class:`Woodbury` gathers ``C``, ``b`` and ``M``
while the fast path factorises, and adds the rank-``K`` correction at the end
(``K = t`` per orthogonal output).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import linalg
from scipy.linalg import lapack

from bayescal.calibration.grid import StackedGrid
from bayescal.emulator.dense import GridData
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import LogDensity

__all__ = [
    "Sensitivity",
    "Woodbury",
    "constrained_covariance",
    "constrained_prior",
    "constraint_matrix",
    "observed_gradient",
    "rotated_gradient",
]

FloatArray = NDArray[np.float64]


def rotated_gradient(
    grid: StackedGrid, theta_star: FloatArray, hs: Sequence[FloatArray]
) -> FloatArray:
    """``d mean / d theta*`` of every basis in its rotated periods, ``(p, m*, t)``.

    The emulator's mean of basis ``j`` at ``(theta*, x_O)`` is ``P u`` with
    ``u_i = l_x,i sum_k c_hat_k h_ki`` (:mod:`bayescal.calibration.kron`), and
    ``c`` depends on theta* through ``c_k = tau^-1 exp(-sum_l beta_l (theta_kl
    - theta*_l)^2)``: ``dc_k / d theta*_l = 2 beta_l (theta_kl - theta*_l) c_k``.
    The observed rows are ``P G_rot`` (``P = Q_x[O, :]``).

    Parameters
    ----------
    grid
        The fixed arrays of the calibration.
    theta_star
        ``(t,)`` or ``(1, t)``, scaled to [0, 1]. [-]
    hs
        ``Wt / (l_k l_i + a)`` of every basis at the current simulator nugget,
        ``(R, m*)`` each.
    """
    ts = np.asarray(theta_star, dtype=float).reshape(1, -1)
    diff = grid.theta - ts  # (R, t)
    c = grid.kernel_vector(ts)  # (R, p)
    out = np.empty((grid.n_bases, grid.l_x.shape[1], ts.shape[1]))
    for j, h in enumerate(hs):
        dc = 2.0 * diff * grid.beta_theta[:, j] * c[:, j : j + 1]  # (R, t)
        dc_hat = grid.q_t_trans[j] @ dc  # (R, t)
        out[j] = grid.l_x[j][:, None] * (h.T @ dc_hat)
    return out


def observed_gradient(grid: StackedGrid, theta_star: FloatArray, a: FloatArray) -> FloatArray:
    """``d mean / d theta*`` of every basis at the observed periods ``(p, m_obs, t)``.

    ``a``: the simulator nuggets ``(p,)`` (the mean depends on ``lambda``). [-]
    """
    hs = [
        grid.w_rot[j] / (np.multiply.outer(grid.l_t[j], grid.l_x[j]) + a[j])
        for j in range(grid.n_bases)
    ]
    out: FloatArray = grid.p_obs @ rotated_gradient(grid, theta_star, hs)
    return out


class Sensitivity:
    """``F`` of the orthogonal outputs at any draw, as the calibration computed it.

    For predictions and leave-one-period-out scores: the emulator's mean over
    the training periods only (an emulator extended to a test window,
    :meth:`~bayescal.emulator.gp.Emulator.extended`, is cut back to them), so
    that the constraint is the calibration's.

    Parameters
    ----------
    emulator
        The trained emulator (possibly extended; its first ``m`` periods are the
        training periods).
    m
        Training periods ``m*``.
    outputs
        The bases of every output whose discrepancy is orthogonal.
    """

    def __init__(self, emulator: Emulator, m: int, outputs: Sequence[Sequence[int]]) -> None:
        n_runs, p = emulator.theta.shape[0], emulator.w.shape[1]
        w = emulator.w.reshape(n_runs, -1, p)[:, :m].reshape(n_runs * m, p)
        data = GridData.build(
            emulator.theta,
            emulator.x[:m],
            emulator.kernels,
            emulator.basis.ktk,
            w,
            np.zeros((m, p)),
        )
        self.grid = StackedGrid.of(data)
        self.outputs = tuple(tuple(b) for b in outputs)

    def __call__(self, theta_star: FloatArray, lam: float) -> FloatArray:
        """``F`` ``(p, m*, K)`` at the draw's theta* (unit scale) and ``lambda``."""
        ktk = self.grid.ktk
        gradient = observed_gradient(self.grid, theta_star, 1.0 / (float(lam) * ktk))
        return constraint_matrix(gradient, ktk, self.outputs)


def constrained_prior(blocks: FloatArray, f: FloatArray) -> FloatArray:
    """The orthogonal discrepancy's covariance over training and other periods.

    Parameters
    ----------
    blocks
        The unconstrained covariance of each basis ``(p_o, M, M)``, the ``m``
        training periods first. [-]
    f
        The constraint on the training periods ``(p_o, m, K)``. [-]

    Returns
    -------
    numpy.ndarray
        ``(p_o, M, p_o, M)``, basis-major. [-]
    """
    p, big, _ = blocks.shape
    m = f.shape[1]
    # rows: the training periods of every basis first, then the others
    start = np.arange(p)[:, None] * big
    order = np.concatenate([(start + np.arange(m)).ravel(), (start + np.arange(m, big)).ravel()])
    sigma = linalg.block_diag(*blocks)[np.ix_(order, order)]
    perp = constrained_covariance(sigma, f.reshape(p * m, -1))
    out = np.empty_like(perp)
    out[np.ix_(order, order)] = perp
    return out.reshape(p, big, p, big)


def constraint_matrix(
    gradient: FloatArray, ktk: FloatArray, outputs: Sequence[Sequence[int]]
) -> FloatArray:
    """``F`` per basis ``(p, m_obs, K)``: each orthogonal output's ``k^T k G`` in its columns.

    Parameters
    ----------
    gradient
        ``G`` per basis over the observed periods ``(p, m_obs, t)``. [-]
    ktk
        ``k_j^T k_j`` ``(p,)``. [-]
    outputs
        The bases of every output whose discrepancy is orthogonal: ``t``
        constraints each, zero on the other bases. A parameter whose column is zero
        (its input switched off, ``rho = 1``, in every basis of the output) has none.
    """
    p, m, t = gradient.shape
    f = np.zeros((p, m, t * len(outputs)))
    for q, bases in enumerate(outputs):
        idx = list(bases)
        f[idx, :, q * t : (q + 1) * t] = ktk[idx, None, None] * gradient[idx]
    # the constraint depends on the columns' span only: scale each to unit norm; a
    # parameter the output does not see at all (its input switched off, rho = 1) has
    # no column: nothing to be orthogonal to
    norm = np.sqrt(np.sum(f * f, axis=(0, 1)))
    keep = norm > 0.0
    out: FloatArray = f[:, :, keep] / norm[keep]
    return out


def constrained_covariance(sigma: FloatArray, f: FloatArray) -> FloatArray:
    """``Sigma - Sigma F (F^T Sigma F)^-1 F^T Sigma`` for a covariance over stacked rows.

    Parameters
    ----------
    sigma
        ``(N, N)`` covariance of the discrepancy (rows basis-major). [-]
    f
        ``(n, K)`` constraint on the first ``n <= N`` rows (the training
        periods; the others are predicted). [-]
    """
    n = f.shape[0]
    if f.shape[1] == 0:
        return np.array(sigma, dtype=float, copy=True)
    sf = sigma[:, :n] @ f  # (N, K)
    m = f.T @ sf[:n]
    chol = linalg.cholesky(0.5 * (m + m.T), lower=True, check_finite=False)
    half = linalg.solve_triangular(chol, sf.T, lower=True, check_finite=False)
    out: FloatArray = sigma - half.T @ half
    return out


class Woodbury:
    """The rank-``K`` correction of the orthogonal constraint, gathered basis by basis.

    Parameters
    ----------
    grid
        The fixed arrays of the calibration (``Q_x``, ``l_x``, ``C_x[O, O]``).
    f
        ``F`` per basis ``(p, m_obs, K)`` (:func:`constraint_matrix`). [-]
    delta
        The discrepancy's variance ``r tau_j^-1`` per basis ``(p,)``. [-]
    """

    def __init__(self, grid: StackedGrid, f: FloatArray, delta: FloatArray) -> None:
        self.grid = grid
        self.f = np.asarray(f, dtype=float)
        self.delta = np.asarray(delta, dtype=float)
        self.sigma_f = self.delta[:, None, None] * (grid.sx_obs @ self.f)  # (p, m_obs, K)
        self.m = np.einsum("jik,jil->kl", self.f, self.sigma_f)
        k = self.f.shape[2]
        self.c = np.zeros((k, k))
        self.b = np.zeros(k)

    def _rotated(self, bases: Sequence[int]) -> FloatArray:
        """``Q_x^T Sigma_j F_j`` of ``bases`` (full grid) ``(q, m*, K)``."""
        idx = list(bases)
        grid = self.grid
        f_rot = np.swapaxes(grid.p_obs[idx], 1, 2) @ self.f[idx]
        out: FloatArray = (self.delta[idx, None] * grid.l_x[idx])[:, :, None] * f_rot
        return out

    def diagonal(self, bases: Sequence[int], schur: FloatArray, resid: FloatArray) -> None:
        """Bases whose Schur complement is diagonal in their rotated periods.

        ``schur`` and ``resid`` ``(len(bases), m*)``: the diagonal and ``z - u``.
        """
        u = self._rotated(bases)
        scaled = u / schur[:, :, None]
        self.c += np.einsum("jik,jil->kl", u, scaled)
        self.b += np.einsum("jik,ji->k", scaled, resid)

    def factored(
        self, bases: Sequence[int], chol: FloatArray, half: FloatArray, rotated: bool
    ) -> None:
        """Bases whose joint Schur complement has the lower Cholesky factor ``chol``.

        ``half = chol^-1 r`` (rows basis-major); ``rotated``: the rows are the
        bases' rotated periods (full grid), else their observed periods.
        """
        u = self._rotated(bases) if rotated else self.sigma_f[list(bases)]
        half_u = lapack.dtrtrs(chol, u.reshape(-1, u.shape[2]), lower=1)[0]
        self.c += half_u.T @ half_u
        self.b += half_u.T @ half

    def finish(self) -> LogDensity:
        """``log |M - C| - log |M|`` and ``b^T (M - C)^-1 b`` (no rows of its own)."""
        try:
            chol_m = np.linalg.cholesky(self.m)
            chol_d = np.linalg.cholesky(self.m - self.c)
        except np.linalg.LinAlgError as exc:
            raise np.linalg.LinAlgError(
                "the orthogonal discrepancy's constraint is degenerate"
            ) from exc
        half = np.linalg.solve(chol_d, self.b)
        logdet = 2.0 * float(np.sum(np.log(np.diag(chol_d))) - np.sum(np.log(np.diag(chol_m))))
        quad = float(half @ half)
        return LogDensity(-0.5 * (logdet + quad), logdet, quad, 0)
