"""Dense reference algebra for the emulator likelihoods (eqs. 5, 10, 12, 14).

Everything here builds the full covariance matrix from the inputs ``z`` and
factorises it by Cholesky: ``O(N^3)`` for ``N = R m* + m_obs`` rows. It is the
reference that :mod:`bayescal.emulator.kron` (training) and
:mod:`bayescal.calibration.kron` (calibration, through
:class:`bayescal.calibration.dense.DenseCalibrationDensity`) are tested
against, and is meant for small problems only.

Row order (shared with the fast path): simulated period ``i`` of run ``k`` is
row ``k * m* + i`` (run-major), i.e. ``W_hat`` holds the runs one after the
other, each cut into the same ``m*`` periods; observed periods follow, in the
order of ``obs_index``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg

from bayescal.emulator.kernel import FloatArray, LogDensity, SeparableKernel

IntArray = np.ndarray


def gaussian_logdensity(cov: FloatArray, v: FloatArray) -> LogDensity:
    """``log N(v; 0, cov)`` by Cholesky, with ``log |cov|`` and ``v^T cov^-1 v``.

    Parameters
    ----------
    cov
        Symmetric positive-definite covariance, shape ``(N, N)``; overwritten.
    v
        Data vector, shape ``(N,)``.

    Raises
    ------
    numpy.linalg.LinAlgError
        If ``cov`` is not numerically positive definite.
    """
    chol, lower = linalg.cho_factor(cov, lower=True, overwrite_a=True, check_finite=False)
    logdet = 2.0 * float(np.sum(np.log(np.diag(chol))))
    half = linalg.solve_triangular(chol, v, lower=lower, check_finite=False)
    return LogDensity.from_pieces(logdet, float(half @ half), v.size)


def grid_inputs(theta: FloatArray, x: FloatArray) -> FloatArray:
    """Inputs ``z = [theta_k, x_i]`` of the full grid, run-major.

    Parameters
    ----------
    theta
        Design, shape ``(R, t)``, scaled to [0, 1]. [-]
    x
        Variable conditions of the periods, shape ``(m*, s)``, scaled. [-]

    Returns
    -------
    numpy.ndarray
        Shape ``(R m*, t + s)``; row ``k m* + i`` is ``[theta_k, x_i]``.
    """
    n_runs, n_per = theta.shape[0], x.shape[0]
    return np.hstack([np.repeat(theta, n_per, axis=0), np.tile(x, (n_runs, 1))])


def calibration_covariance(
    theta: FloatArray,
    x: FloatArray,
    kernel: SeparableKernel,
    a: float,
    *,
    theta_star: FloatArray | None = None,
    obs_index: IntArray | None = None,
    a_star: ArrayLike = 0.0,
    delta: float = 0.0,
) -> FloatArray:
    """Full covariance of eq. 14 (or of eq. 10 when ``theta_star`` is None).

    Parameters
    ----------
    theta, x
        Design ``(R, t)`` and variable conditions ``(m*, s)``, scaled. [-]
    kernel
        Hyperparameters of this basis.
    a
        Simulator nugget ``(lambda k_j^T k_j)^-1``. [-]
    theta_star
        Calibration parameters of the observations ``(t,)``; no observed rows
        when omitted. [-]
    obs_index
        Periods that were observed (indices into the rows of ``x``); all
        periods when omitted.
    a_star
        Observation nugget ``(lambda* k_j^T k_j)^-1``, a scalar or one value per
        observed period (the difference process's ``B_j``). [-]
    delta
        Variance of a model discrepancy over the observed periods: adds
        ``delta c_x(x_i, x_k)`` to the observed block. [-]
    """
    z = grid_inputs(theta, x)
    nugget = np.full(z.shape[0], float(a))
    if theta_star is not None:
        idx = np.arange(x.shape[0]) if obs_index is None else np.asarray(obs_index)
        z_obs = np.hstack([np.tile(theta_star, (idx.size, 1)), x[idx]])
        z = np.vstack([z, z_obs])
        nugget = np.concatenate([nugget, np.broadcast_to(a_star, idx.shape).astype(float)])
    cov = kernel.full(z)
    cov[np.diag_indices_from(cov)] += nugget
    if theta_star is not None and delta:
        obs = slice(theta.shape[0] * x.shape[0], None)
        cov[obs, obs] += delta * kernel.x_corr(z[obs, theta.shape[1] :])
    return cov


def dense_logpdf(
    v: ArrayLike,
    theta: FloatArray,
    x: FloatArray,
    kernel: SeparableKernel,
    a: float,
    *,
    theta_star: FloatArray | None = None,
    obs_index: IntArray | None = None,
    a_star: ArrayLike = 0.0,
    delta: float = 0.0,
) -> LogDensity:
    """``log N(v; 0, Omega)`` for one basis with the dense covariance.

    Arguments as :func:`calibration_covariance`; ``v`` stacks the simulator
    weights (run-major) and, with ``theta_star``, the observed weights.
    """
    cov = calibration_covariance(
        theta, x, kernel, a, theta_star=theta_star, obs_index=obs_index, a_star=a_star, delta=delta
    )
    vec = np.asarray(v, dtype=float)
    if vec.shape != (cov.shape[0],):
        raise ValueError(f"v must have shape ({cov.shape[0]},), got {vec.shape}")
    return gaussian_logdensity(cov, vec)


@dataclass(frozen=True)
class GridData:
    """Fixed inputs of a calibration likelihood, validated once.

    Parameters
    ----------
    theta
        Latin-hypercube design, shape ``(R, t)``, scaled to [0, 1]. [-]
    x
        Variable conditions of the ``m*`` periods, shape ``(m*, s)``. [-]
    kernels
        Hyperparameters, one :class:`SeparableKernel` per basis (``p``).
    ktk
        ``k_j^T k_j`` of every basis vector, shape ``(p,)``. [-]
    w
        Simulator weights ``W_hat``, shape ``(R m*, p)``, run-major rows. [-]
    w_star
        Observed weights ``W*_hat``, shape ``(m_obs, p)``, or None (training). [-]
    obs_index
        Which periods the rows of ``w_star`` belong to, shape ``(m_obs,)``.
    """

    theta: FloatArray
    x: FloatArray
    kernels: tuple[SeparableKernel, ...]
    ktk: FloatArray
    w: FloatArray
    w_star: FloatArray | None
    obs_index: IntArray

    @classmethod
    def build(
        cls,
        theta: ArrayLike,
        x: ArrayLike,
        kernels: Sequence[SeparableKernel],
        ktk: ArrayLike,
        w: ArrayLike,
        w_star: ArrayLike | None = None,
        obs_index: ArrayLike | None = None,
    ) -> GridData:
        """Check shapes and build; see the class parameters."""
        th = _matrix(theta, "theta")
        xx = _matrix(x, "x")
        ks = tuple(kernels)
        kk = np.asarray(ktk, dtype=float).reshape(-1)
        ww = _matrix(w, "w")
        p = len(ks)
        if ww.shape != (th.shape[0] * xx.shape[0], p) or kk.shape != (p,):
            raise ValueError(
                f"expected w of shape ({th.shape[0]} runs x {xx.shape[0]} periods, {p} bases) "
                f"and ktk of shape ({p},), got w {ww.shape} and ktk {kk.shape}"
            )
        for k in ks:
            if k.rho.size != th.shape[1] + xx.shape[1] or k.n_theta != th.shape[1]:
                raise ValueError(
                    f"kernel has {k.n_theta} theta of {k.rho.size} inputs, "
                    f"data has t={th.shape[1]}, s={xx.shape[1]}"
                )
        idx = np.arange(xx.shape[0]) if obs_index is None else np.asarray(obs_index, dtype=int)
        if idx.ndim != 1 or np.unique(idx).size != idx.size or np.any(idx < 0):
            raise ValueError(f"obs_index must hold distinct period indices, got {idx.tolist()}")
        if idx.size and idx.max() >= xx.shape[0]:
            raise ValueError(f"obs_index {idx.max()} out of range for {xx.shape[0]} periods")
        ws = None if w_star is None else _observed_weights(w_star, idx.size, p)
        return cls(th, xx, ks, kk, ww, ws, idx)

    def with_observations(self, w_star: ArrayLike) -> GridData:
        """The same inputs with other observed weights ``(m_obs, p)`` (only they are checked)."""
        ws = _observed_weights(w_star, self.obs_index.size, self.n_bases)
        return dataclasses.replace(self, w_star=ws)

    @property
    def n_bases(self) -> int:
        """``p``."""
        return len(self.kernels)

    def nuggets(self, lam: float, lam_star: ArrayLike = np.inf) -> tuple[FloatArray, FloatArray]:
        """``a_j = (lambda k_j^T k_j)^-1`` ``(p,)`` and ``a*_j`` ``(p, m_obs)``.

        Parameters
        ----------
        lam
            Simulator precision ``lambda``. [-]
        lam_star
            Observation precision ``lambda*``, a scalar or one per observed
            period. [-]
        """
        lam_s = np.broadcast_to(np.asarray(lam_star, dtype=float), self.obs_index.shape)
        return 1.0 / (float(lam) * self.ktk), 1.0 / np.outer(self.ktk, lam_s)


def _observed_weights(w_star: ArrayLike, m_obs: int, p: int) -> FloatArray:
    """``w_star`` checked: finite, shape ``(m_obs, p)``."""
    ws = _matrix(w_star, "w_star")
    if ws.shape != (m_obs, p):
        raise ValueError(f"expected w_star of shape ({m_obs}, {p}), got {ws.shape}")
    return ws


def _matrix(value: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be 2-D, got ndim = {arr.ndim}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


def broadcast_obs_nuggets(a_star: ArrayLike, p: int, m_obs: int) -> FloatArray:
    """Observation nuggets as a ``(p, m_obs)`` array.

    A scalar applies to every basis and period, shape ``(p,)`` one value per
    basis, shape ``(p, m_obs)`` one per basis and observed period.
    """
    arr = np.asarray(a_star, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    try:
        return np.broadcast_to(arr, (p, m_obs))
    except ValueError:
        raise ValueError(
            f"observation nuggets must be a scalar, ({p},) or ({p}, {m_obs}), "
            f"got shape {np.shape(a_star)}"
        ) from None


def dense_training_logpdf(
    theta: ArrayLike,
    x: ArrayLike,
    kernels: Sequence[SeparableKernel],
    ktk: ArrayLike,
    w: ArrayLike,
    lam: float,
) -> LogDensity:
    """Training log-density (eq. 5 / 10) summed over bases, dense Cholesky.

    Parameters
    ----------
    theta, x
        Design ``(R, t)`` and variable conditions ``(m*, s)``, scaled. [-]
    kernels
        One :class:`SeparableKernel` per basis.
    ktk
        ``k_j^T k_j``, shape ``(p,)``. [-]
    w
        Simulator weights ``(R m*, p)``, run-major. [-]
    lam
        Simulator precision ``lambda``. [-]
    """
    d = GridData.build(theta, x, kernels, ktk, w)
    a, _ = d.nuggets(lam)
    total = LogDensity.zero()
    for j, kern in enumerate(d.kernels):
        total = total + dense_logpdf(d.w[:, j], d.theta, d.x, kern, float(a[j]))
    return total
