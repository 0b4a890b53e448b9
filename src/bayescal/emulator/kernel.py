"""The separable squared-exponential covariance of the paper's eq. 8.

For inputs ``z = [theta, x]`` (``t`` calibration parameters then ``s``
variable conditions, all scaled to [0, 1]) the covariance of basis ``j`` is

    c(z, z') = tau^-1 prod_l rho_l^(4 (z_l - z'_l)^2)
             = tau^-1 exp(-sum_l beta_l (z_l - z'_l)^2),   beta_l = -4 ln rho_l.

Internally the correlation lengths are carried as ``beta`` (the GPMSA
parameterisation): ``rho in (0, 1]`` maps one-to-one onto ``beta in [0, inf)``,
``rho = 1`` (``beta = 0``) switches an input off, and ``exp`` of a sum is cheaper
and better conditioned than a product of powers.

The product separates into a theta part and an x part,
``c(z, z') = c_theta(theta, theta') * c_x(x, x')``. By convention the variance
``tau^-1`` is carried by the theta factor: ``S_theta = tau^-1 R_theta`` and
``S_x = R_x`` is a pure correlation matrix (unit diagonal). On the full grid
of runs x periods the simulator covariance is then ``S_theta ⊗ S_x``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True, slots=True)
class LogDensity:
    """A Gaussian log-density ``log N(v; 0, Omega)`` and its two pieces.

    Attributes
    ----------
    logpdf
        ``-(N log(2 pi) + logdet + quad) / 2``.
    logdet
        ``log |Omega|``.
    quad
        ``v^T Omega^-1 v``.
    size
        ``N``, the length of ``v`` (summed over bases where several are added).
    """

    logpdf: float
    logdet: float
    quad: float
    size: int

    @classmethod
    def from_pieces(cls, logdet: float, quad: float, size: int) -> LogDensity:
        """Assemble the log-density from ``log |Omega|`` and ``v^T Omega^-1 v``."""
        return cls(-0.5 * (size * LOG_2PI + logdet + quad), logdet, quad, size)

    @classmethod
    def zero(cls) -> LogDensity:
        """The empty sum (no rows)."""
        return cls(0.0, 0.0, 0.0, 0)

    def __add__(self, other: object) -> LogDensity:
        """Sum of independent blocks (bases): every field adds."""
        if not isinstance(other, LogDensity):
            return NotImplemented
        return LogDensity(
            self.logpdf + other.logpdf,
            self.logdet + other.logdet,
            self.quad + other.quad,
            self.size + other.size,
        )


def rho_to_beta(rho: ArrayLike) -> FloatArray:
    """Map correlation parameters ``rho in (0, 1]`` to ``beta = -4 ln rho >= 0``.

    Parameters
    ----------
    rho
        Correlation parameters, one per input. [-]

    Returns
    -------
    numpy.ndarray
        ``beta``, same shape as ``rho``. [-]
    """
    r = np.asarray(rho, dtype=float)
    if not np.all((r > 0.0) & (r <= 1.0)):
        raise ValueError(f"rho must lie in (0, 1], got {r.tolist()}")
    return -4.0 * np.log(r)


def beta_to_rho(beta: ArrayLike) -> FloatArray:
    """Inverse of :func:`rho_to_beta`: ``rho = exp(-beta / 4)``."""
    b = np.asarray(beta, dtype=float)
    if not np.all(np.isfinite(b) & (b >= 0.0)):
        raise ValueError(f"beta must be finite and >= 0, got {b.tolist()}")
    return np.exp(-0.25 * b)


def correlation(a: ArrayLike, b: ArrayLike, beta: ArrayLike) -> FloatArray:
    """Squared-exponential correlation ``exp(-sum_l beta_l (a_il - b_kl)^2)``.

    Parameters
    ----------
    a
        First set of inputs, shape ``(N, d)``, scaled to [0, 1]. [-]
    b
        Second set of inputs, shape ``(M, d)``. [-]
    beta
        Inverse squared length scales ``-4 ln rho``, shape ``(d,)``. [-]

    Returns
    -------
    numpy.ndarray
        Correlation matrix, shape ``(N, M)``.
    """
    a2 = np.atleast_2d(np.asarray(a, dtype=float))
    b2 = np.atleast_2d(np.asarray(b, dtype=float))
    w = np.asarray(beta, dtype=float).reshape(-1)
    if a2.shape[1] != w.size or b2.shape[1] != w.size:
        raise ValueError(
            f"inputs have {a2.shape[1]} and {b2.shape[1]} columns, beta has {w.size} entries"
        )
    out = np.zeros((a2.shape[0], b2.shape[0]))
    diff = np.empty_like(out)
    # One input at a time keeps the memory at two N x M buffers (matters for the
    # dense reference at thousands of rows).
    for col in range(w.size):
        if w[col] == 0.0:
            continue
        np.subtract.outer(a2[:, col], b2[:, col], out=diff)
        np.multiply(diff, diff, out=diff)
        diff *= w[col]
        out += diff
    np.negative(out, out=out)
    return np.exp(out, out=out)


@dataclass(frozen=True)
class SeparableKernel:
    """Covariance hyperparameters of one basis: ``rho`` (``t + s``) and ``tau``.

    Parameters
    ----------
    rho
        Correlation parameters in (0, 1], the ``t`` theta inputs first, then
        the ``s`` x inputs. [-]
    tau
        Precision of the GP (the marginal variance is ``1 / tau``). [-]
    n_theta
        ``t``, the number of calibration-parameter inputs.
    """

    rho: FloatArray
    tau: float
    n_theta: int

    def __post_init__(self) -> None:
        rho = np.array(self.rho, dtype=float).reshape(-1)
        rho.setflags(write=False)
        object.__setattr__(self, "rho", rho)
        rho_to_beta(rho)
        if not (np.isfinite(self.tau) and self.tau > 0.0):
            raise ValueError(f"tau must be finite and > 0, got {self.tau!r}")
        if not 0 <= self.n_theta <= rho.size:
            raise ValueError(f"n_theta must lie in [0, {rho.size}], got {self.n_theta}")

    @classmethod
    def from_beta(cls, beta: ArrayLike, tau: float, n_theta: int) -> SeparableKernel:
        """Build from ``beta = -4 ln rho`` instead of ``rho``."""
        return cls(beta_to_rho(beta), float(tau), n_theta)

    @property
    def beta(self) -> FloatArray:
        """``-4 ln rho`` for every input."""
        return rho_to_beta(self.rho)

    @property
    def beta_theta(self) -> FloatArray:
        """``beta`` of the ``t`` calibration-parameter inputs."""
        return self.beta[: self.n_theta]

    @property
    def beta_x(self) -> FloatArray:
        """``beta`` of the ``s`` variable-condition inputs."""
        return self.beta[self.n_theta :]

    @property
    def variance(self) -> float:
        """Marginal variance ``1 / tau``."""
        return 1.0 / self.tau

    def theta_cov(self, a: ArrayLike, b: ArrayLike | None = None) -> FloatArray:
        """Theta factor ``tau^-1 R_theta`` between rows of ``a`` and ``b``.

        Parameters
        ----------
        a
            Calibration parameters, shape ``(N, t)``, scaled to [0, 1]. [-]
        b
            Second set, shape ``(M, t)``; ``a`` when omitted. [-]
        """
        other = a if b is None else b
        return self.variance * correlation(a, other, self.beta_theta)

    def x_corr(self, a: ArrayLike, b: ArrayLike | None = None) -> FloatArray:
        """X factor ``R_x`` (unit diagonal) between rows of ``a`` and ``b``.

        Parameters
        ----------
        a
            Variable conditions, shape ``(N, s)``, scaled to [0, 1]. [-]
        b
            Second set, shape ``(M, s)``; ``a`` when omitted. [-]
        """
        other = a if b is None else b
        return correlation(a, other, self.beta_x)

    def full(self, a: ArrayLike, b: ArrayLike | None = None) -> FloatArray:
        """Covariance of eq. 8 between full inputs ``z = [theta, x]``.

        Parameters
        ----------
        a
            Inputs, shape ``(N, t + s)``, scaled to [0, 1]. [-]
        b
            Second set, shape ``(M, t + s)``; ``a`` when omitted. [-]
        """
        other = a if b is None else b
        return self.variance * correlation(a, other, self.beta)
