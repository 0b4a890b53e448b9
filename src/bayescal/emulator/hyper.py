"""The emulator's hyperparameters: their priors and their place in the sampled vector.

For every basis ``j`` the covariance hyperparameters are the correlation
parameters ``rho_lj`` of the ``r = t + s`` inputs (carried as ``beta = -4 ln
rho``) and the precision ``tau_j``; the simulator precision ``lambda`` is shared
(the paper's eqs. 8 and 9). :class:`HyperLayout` places them in one vector
``[beta_1j .. beta_rj, tau_j]`` for ``j = 1..p``, then ``lambda``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import special

from bayescal.emulator.kernel import FloatArray
from bayescal.errors import ConfigError

__all__ = ["HyperLayout", "HyperPriors", "log_prior_beta"]

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


def log_prior_beta(beta: FloatArray, a: float, b: float) -> float:
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
