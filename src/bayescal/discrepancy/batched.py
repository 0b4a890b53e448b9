"""Eq. 19 for ``B`` chains at once, each with its own observed weights and nuggets.

Between two updates of the difference process every chain ``b`` has its own
GLS weights ``w*_b`` (eq. 20) and per-period observation nuggets ``B_b`` (eq. 21),
estimated at its own ``theta*``; the simulator block (``lambda`` fixed) and the
kernels are common. :class:`BatchedDelta` evaluates the log-likelihood of
eq. 19 at ``B`` points, one per chain, on the fixed arrays of
:class:`~bayescal.calibration.grid.StackedGrid` (full grid: every training
period observed, as in the discrepancy phase).

Per basis ``j`` (``kron`` module docstring of :mod:`bayescal.calibration.kron`):
the simulator block ``A = S_theta ⊗ S_x + a I`` gives ``log |A|`` and
``w^T A^-1 w`` once (``a`` is fixed); with ``c_hat = Q_t^T c(theta*)``,
``u = l_x (c_hat^T Wt / den)`` and ``g = l_x^2 (c_hat^2 / den)``, the Schur
complement of the observed block in the ``Q_x`` basis is

    S'_bj = diag(l_x / tau_j (1 + r) - g) + Q_x^T diag(B_bj) Q_x,     resid = Q_x^T w*_bj - u,

an ``m* x m*`` matrix per chain and basis (not diagonal: the per-period
nuggets break the Kronecker structure). ``Q_x^T diag(B_bj) Q_x`` and
``Q_x^T w*_bj`` move only at an update (:meth:`BatchedDelta.segment`); a
proposal costs ``B p`` Cholesky factorisations of ``m* x m*`` matrices in one
batched numpy call. ``r`` is the relative variance of an in-likelihood
discrepancy (:mod:`bayescal.emulator.noise`), fixed here, 0 without one.

The value equals :meth:`~bayescal.calibration.kron.KronCalibrationDensity.pieces_nuggets`
of the same point to rounding (``tests/discrepancy``): the Schur complement is
the same matrix rotated by the orthogonal ``Q_x``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.calibration.grid import StackedGrid
from bayescal.emulator.kernel import LOG_2PI, FloatArray
from bayescal.errors import ConfigError

__all__ = ["BatchedDelta", "Segment"]

BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Segment:
    """What stays fixed per chain between two updates, in the ``Q_x`` basis.

    Attributes
    ----------
    obs_rot
        ``Q_x^T w*_bj`` ``(B, p, m*)``. [-]
    nug_rot
        ``Q_x^T diag(B_bj) Q_x`` ``(B, p, m*, m*)``. [-]
    """

    obs_rot: FloatArray
    nug_rot: FloatArray

    @property
    def n_chains(self) -> int:
        """``B``."""
        return int(self.obs_rot.shape[0])

    def rows(self, index: ArrayLike) -> Segment:
        """The chains ``index`` only."""
        idx = np.asarray(index)
        return Segment(self.obs_rot[idx], self.nug_rot[idx])


class BatchedDelta:
    """Log-likelihood of eq. 19 at one ``theta*`` per chain, each with its own ``w*`` and ``B``.

    Parameters
    ----------
    grid
        The fixed arrays of eq. 16 (full grid).
    a
        Simulator nuggets ``(lambda k_j^T k_j)^-1`` ``(p,)``, > 0. [-]
    delta
        Variance of an in-likelihood model discrepancy per basis ``(p,)``
        (``r_o tau_j^-1``), or ``None``. [-]
    """

    def __init__(self, grid: StackedGrid, a: ArrayLike, delta: ArrayLike | None = None) -> None:
        if not grid.full_grid:
            raise ConfigError("the discrepancy phase needs every training period observed")
        a_arr = np.broadcast_to(np.asarray(a, dtype=float), (grid.n_bases,))
        den = grid.outer + a_arr[:, None, None]  # (p, R, m*)
        if not den.min() > 0.0:
            raise np.linalg.LinAlgError("simulator covariance is not positive definite")
        self.grid = grid
        self.inv_den = 1.0 / den
        self.h = grid.w_rot * self.inv_den
        sim_logdet = float(np.sum(np.log(den)))
        sim_quad = float(np.sum(self.h * grid.w_rot))
        self.q_x = np.stack([b.eig_x.vectors for b in grid.bases])  # (p, m*, m*)
        variance = grid.variance.copy()
        if delta is not None:
            variance = variance + np.broadcast_to(np.asarray(delta, dtype=float), variance.shape)
        self.var_lx = variance[:, None] * grid.l_x  # (p, m*)
        self.constant = grid.size * LOG_2PI + sim_logdet + sim_quad

    @property
    def n_bases(self) -> int:
        """``p``."""
        return self.grid.n_bases

    def segment(self, w_star: ArrayLike, nuggets: ArrayLike) -> Segment:
        """The per-chain pieces of observed weights ``(B, m*, p)`` and nuggets ``(B, p, m*)``."""
        w = np.asarray(w_star, dtype=float)
        nug = np.asarray(nuggets, dtype=float)
        if not np.all(nug > 0.0):
            raise ValueError("observation nuggets must be > 0")
        obs_rot = np.einsum("jmk,bmj->bjk", self.q_x, w)
        nug_rot = np.einsum("jmk,bjm,jml->bjkl", self.q_x, nug, self.q_x)
        return Segment(obs_rot, nug_rot)

    def __call__(self, theta_star: ArrayLike, segment: Segment) -> FloatArray:
        """Log-likelihood ``(B,)`` at ``theta*`` ``(B, t)`` (normalised); ``-inf`` where the
        covariance is not positive definite."""
        th = np.asarray(theta_star, dtype=float)
        grid = self.grid
        diff = grid.theta[None, :, :] - th[:, None, :]  # (B, R, t)
        c = np.exp(-((diff * diff) @ grid.beta_theta)) * grid.variance  # (B, R, p)
        c_hat = np.einsum("jkr,brj->bjk", grid.q_t_trans, c)  # (B, p, R)
        u = grid.l_x * np.einsum("bjr,jrm->bjm", c_hat, self.h)
        g = grid.l_x2 * np.einsum("bjr,jrm->bjm", c_hat * c_hat, self.inv_den)
        schur = segment.nug_rot.copy()
        diag = np.einsum("...ii->...i", schur)  # a writable view of the diagonals
        diag += self.var_lx - g
        resid = segment.obs_rot - u
        logdet, quad, ok = _factor(schur, resid)
        out: FloatArray = np.where(ok, -0.5 * (self.constant + logdet + quad), -math.inf)
        return out


def _factor(schur: FloatArray, resid: FloatArray) -> tuple[FloatArray, FloatArray, BoolArray]:
    """``log |S|`` and ``r^T S^-1 r`` summed over bases ``(B,)``, and which chains are PD."""
    n = schur.shape[0]
    try:
        chol = np.linalg.cholesky(schur)
    except np.linalg.LinAlgError:
        if n == 1:
            return np.zeros(1), np.zeros(1), np.zeros(1, dtype=bool)
        parts = [_factor(schur[b : b + 1], resid[b : b + 1]) for b in range(n)]
        logdet, quad, ok = (np.concatenate(column) for column in zip(*parts, strict=True))
        return logdet, quad, ok
    half = np.linalg.solve(chol, resid[..., None])[..., 0]
    logdet = 2.0 * np.log(np.einsum("...ii->...i", chol)).sum(axis=(1, 2))
    quad = np.einsum("bjm,bjm->b", half, half)
    return logdet, quad, np.ones(n, dtype=bool)
