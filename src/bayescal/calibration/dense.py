"""Dense reference of the calibration likelihood (eqs. 12, 14): the whole covariance by Cholesky.

``O((R m* + m_obs)^3)`` per evaluation: the reference that
:class:`bayescal.calibration.kron.KronCalibrationDensity` is tested against,
for small problems only (see :mod:`bayescal.emulator.dense`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg

from bayescal.calibration.batch import BatchErrors, check_batch_args, logpdf_loop
from bayescal.calibration.orthogonal import constrained_covariance
from bayescal.emulator.dense import (
    GridData,
    broadcast_obs_nuggets,
    calibration_covariance,
    dense_logpdf,
    gaussian_logdensity,
    grid_inputs,
)
from bayescal.emulator.kernel import FloatArray, LogDensity, SeparableKernel

__all__ = ["DenseCalibrationDensity"]


class DenseCalibrationDensity:
    """Calibration log-density (eq. 12) by dense Cholesky: the reference.

    Same interface as :class:`bayescal.calibration.kron.KronCalibrationDensity`.
    Nothing is precomputed: each call builds and factorises every ``Omega_j``.

    Parameters
    ----------
    theta, x, kernels, ktk, w, w_star, obs_index
        As :class:`GridData`; ``w_star`` is required.
    """

    def __init__(
        self,
        theta: ArrayLike,
        x: ArrayLike,
        kernels: Sequence[SeparableKernel],
        ktk: ArrayLike,
        w: ArrayLike,
        w_star: ArrayLike,
        obs_index: ArrayLike | None = None,
    ) -> None:
        self._data = GridData.build(theta, x, kernels, ktk, w, w_star, obs_index)

    @property
    def data(self) -> GridData:
        """The validated fixed inputs."""
        return self._data

    def with_observations(self, w_star: ArrayLike) -> DenseCalibrationDensity:
        """A new density with other observed weights (e.g. re-estimated by eq. 20)."""
        d = self._data
        return type(self)(d.theta, d.x, d.kernels, d.ktk, d.w, w_star, d.obs_index)

    def pieces_nuggets(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity:
        """Log-density summed over bases for explicit nuggets.

        Parameters
        ----------
        theta_star
            Calibration parameters ``(t,)``, scaled to [0, 1]. [-]
        a
            Simulator nuggets, shape ``(p,)``. [-]
        a_star
            Observation nuggets, shape ``(p,)`` or ``(p, m_obs)``. [-]
        delta
            Model-discrepancy variance per basis ``(p,)`` or ``None``. [-]
        constraint
            ``F`` ``(p, m_obs, K)`` of an orthogonal discrepancy: its covariance
            over all bases' observed weights is conditioned on ``F^T delta = 0``
            directly (:func:`~bayescal.calibration.orthogonal.constrained_covariance`). [-]
        """
        d = self._data
        if constraint is not None:
            as_all = broadcast_obs_nuggets(a_star, d.n_bases, d.obs_index.size)
            return self._joint(theta_star, a, as_all, [], delta, constraint)
        if d.w_star is None:
            raise ValueError("no observed weights: build with w_star for calibration")
        ts = np.asarray(theta_star, dtype=float).reshape(-1)
        a_arr = np.broadcast_to(np.asarray(a, dtype=float), (d.n_bases,))
        as_arr = broadcast_obs_nuggets(a_star, d.n_bases, d.obs_index.size)
        dl = (
            np.zeros(d.n_bases)
            if delta is None
            else np.broadcast_to(np.asarray(delta, float), (d.n_bases,))
        )
        total = LogDensity.zero()
        for j, kern in enumerate(d.kernels):
            v = np.concatenate([d.w[:, j], d.w_star[:, j]])
            total = total + dense_logpdf(
                v,
                d.theta,
                d.x,
                kern,
                float(a_arr[j]),
                theta_star=ts,
                obs_index=d.obs_index,
                a_star=as_arr[j],
                delta=float(dl[j]),
            )
        return total

    def pieces(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> LogDensity:
        """Log-density and its pieces for precisions ``lambda`` and ``lambda*``."""
        a, a_star = self._data.nuggets(lam, lam_star)
        return self.pieces_nuggets(theta_star, a, a_star)

    def pieces_grouped(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        groups: Sequence[tuple[Sequence[int], FloatArray]],
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity:
        """Log-density with coupled observation noise within groups of bases (dense).

        One covariance over all bases' ``[w_j; w*_j]``: each basis's eq. 14
        block, and within every period the noise ``groups`` puts between the
        observed weights of a group's bases (``a*_j`` on the diagonal for the
        others). Arguments as
        :meth:`bayescal.calibration.kron.KronCalibrationDensity.pieces_grouped`.
        """
        d = self._data
        as_arr = np.broadcast_to(np.asarray(a_star, dtype=float), (d.n_bases,))
        as_all = np.repeat(as_arr[:, None], d.obs_index.size, axis=1)
        return self._joint(theta_star, a, as_all, groups, delta, constraint)

    def _joint(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        as_arr: FloatArray,
        groups: Sequence[tuple[Sequence[int], FloatArray]],
        delta: ArrayLike | None,
        constraint: ArrayLike | None,
    ) -> LogDensity:
        """One covariance over all bases' ``[w_j; w*_j]`` (``as_arr`` ``(p, m_obs)``)."""
        d = self._data
        if d.w_star is None:
            raise ValueError("no observed weights: build with w_star for calibration")
        ts = np.asarray(theta_star, dtype=float).reshape(-1)
        a_arr = np.broadcast_to(np.asarray(a, dtype=float), (d.n_bases,))
        n_sim, m_obs = d.w.shape[0], d.obs_index.size
        block = n_sim + m_obs
        cov = np.zeros((d.n_bases * block, d.n_bases * block))
        vec = np.empty(d.n_bases * block)
        grouped = {j for members, _ in groups for j in members}
        dl = (
            np.zeros(d.n_bases)
            if delta is None
            else np.broadcast_to(np.asarray(delta, float), (d.n_bases,))
        )
        for j, kern in enumerate(d.kernels):
            rows = slice(j * block, (j + 1) * block)
            nugget = np.zeros(m_obs) if j in grouped else as_arr[j]
            cov[rows, rows] = calibration_covariance(
                d.theta,
                d.x,
                kern,
                float(a_arr[j]),
                theta_star=ts,
                obs_index=d.obs_index,
                a_star=nugget,
                delta=float(dl[j]) if constraint is None else 0.0,
            )
            vec[rows] = np.concatenate([d.w[:, j], d.w_star[:, j]])
        period = np.arange(m_obs)
        if constraint is not None:  # Sigma_perp over every basis's observed rows, directly
            obs_rows = (np.arange(d.n_bases)[:, None] * block + n_sim + period).ravel()
            x_obs = d.x[d.obs_index]
            sigma = linalg.block_diag(*[dl[j] * k.x_corr(x_obs) for j, k in enumerate(d.kernels)])
            f = np.asarray(constraint, float).reshape(d.n_bases * m_obs, -1)
            cov[np.ix_(obs_rows, obs_rows)] += constrained_covariance(sigma, f)
        for members, noise in groups:
            for aj, j in enumerate(members):
                for ak, k in enumerate(members):
                    rj = j * block + n_sim + period
                    rk = k * block + n_sim + period
                    cov[rj, rk] += noise[aj, ak]
        return gaussian_logdensity(cov, vec)

    def mean_gradient(self, theta_star: ArrayLike, a: ArrayLike) -> FloatArray:
        """``d mean / d theta*`` of the emulator's weights at the observed periods,
        ``(p, m_obs, t)``: the dense GP mean ``k(z)^T (S + a I)^-1 w`` differentiated. [-]"""
        d = self._data
        ts = np.asarray(theta_star, dtype=float).reshape(-1)
        a_arr = np.broadcast_to(np.asarray(a, dtype=float), (d.n_bases,))
        z = grid_inputs(d.theta, d.x)
        x_obs = d.x[d.obs_index]
        z_obs = np.hstack([np.tile(ts, (x_obs.shape[0], 1)), x_obs])
        n_t = ts.size
        out = np.empty((d.n_bases, x_obs.shape[0], n_t))
        for j, kern in enumerate(d.kernels):
            cov = kern.full(z)
            cov[np.diag_indices_from(cov)] += a_arr[j]
            alpha = linalg.solve(cov, d.w[:, j], assume_a="pos")
            cross = kern.full(z, z_obs)  # (N, m_obs)
            for k in range(n_t):
                slope = 2.0 * kern.beta_theta[k] * (z[:, k] - ts[k])  # d/d theta*_k
                out[j, :, k] = (cross * slope[:, None]).T @ alpha
        return out

    def stacked_grid(self) -> None:
        """No stacked grid: the dense reference factorises the whole covariance."""
        return None

    def logpdf_batch(
        self,
        theta_star: ArrayLike,
        lam: ArrayLike,
        lam_star: ArrayLike,
        *,
        errors: BatchErrors = "raise",
    ) -> FloatArray:
        """:meth:`logpdf` at ``B`` points, one after another (arguments as the Kronecker one's)."""
        ts, lam_arr, lam_s = check_batch_args(self._data, theta_star, lam, lam_star, errors)
        return logpdf_loop(self, ts, lam_arr, lam_s, errors)

    def batch_session(self, theta_star: ArrayLike, lam: ArrayLike, lam_star: ArrayLike) -> None:
        """No batched form (lockstep chains evaluate each row)."""
        check_batch_args(self._data, theta_star, lam, lam_star)
        return None

    def logpdf(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> float:
        """``sum_j log N(v_j; 0, Omega_j)`` (eq. 12 with its normalising constant)."""
        return self.pieces(theta_star, lam, lam_star).logpdf
