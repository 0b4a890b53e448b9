"""The algebra of eqs. 20–25: empirical moments of ``y* - f`` and generalised least squares.

Everything here works in the **standardised** units of :mod:`bayescal.emulator.assemble`
(the units of ``Y*`` in eqs. 13 and 20–24).

Empirical moments (eq. 25, sign ``Delta = observation - model``)
----------------------------------------------------------------
At a ``theta*`` the emulator gives, for every training period ``i``, the GP
conditional of the weights given the training weights (eq. 17 conditioned on
``W``): mean ``mu_i`` and variance ``v_i`` per basis (the bases are independent,
so per-period marginals are all eq. 25 needs). ``b`` realisations
``w_ik = mu_i + sqrt(v_i) z`` give ``f_ik = K w_ik`` (eq. 1) and

    d_ik = y*_i - f_ik,   Delta_i = mean_k d_ik,   D_i = mean_k d_ik d_ik^T.

The paper's eq. 25 writes ``f - y*``; the outer product ``D_i`` is the same
either way, and ``Delta`` here has the sign of eq. 18
(``y* = f + Delta + eps``). ``D_i`` is the *non-centred* mean outer product, as
in eq. 25: it carries the bias ``Delta_i Delta_i^T`` as well as the model's
spread.

Every ``d_ik`` lies in the span of ``G_i = [y*_i, K]`` (``N x (p + 1)``):
``d_ik = G_i e_k`` with ``e_k = [1, -w_ik]``. Hence ``D_i = G_i S_i G_i^T`` with the
``(p + 1) x (p + 1)`` matrix ``S_i = mean_k e_k e_k^T`` and a factor
``U_i = G_i Q sqrt(L)`` from ``S_i = Q L Q^T``: ``D_i = U_i U_i^T`` of rank
``<= p + 1`` whatever ``b`` and ``N`` are.

The measurement error (eq. 22, per output)
-------------------------------------------
The paper's eq. 22 is ``A_i = lambda*^-1 I + D_i`` for one output with white
noise. With several outputs, each with its own error model
(:mod:`bayescal.emulator.noise`), ``lambda*^-1 I`` becomes the block-diagonal
``Sigma_0 = blockdiag_o(R_o(phi_o) / lambda*_o)`` over the outputs' rows
(``R = I`` for white noise, the AR(1) correlation ``phi^|a - b|`` within a
period otherwise): :class:`ErrorCovariance`. Its whitening map
``W = Sigma_0^-1/2`` (per block ``sqrt(lambda*_o)`` times the AR(1)
prewhitening of :func:`bayescal.emulator.noise.ar1_whiten`) turns ``A_i`` into
``I + (W U_i)(W U_i)^T`` and ``log |A_i| = log |Sigma_0| + log |I + U_w^T U_w|``.

Generalised least squares (eqs. 20–24)
--------------------------------------
With ``K_w = W K``, ``y_w = W y*_i`` and ``U_w = W U_i``, ``A_w = I + U_w U_w^T`` is
handled by the Woodbury identity through the ``r x r`` matrix
``M = I + U_w^T U_w``::

    K^T A^-1 K = K_w^T K_w - K_w^T U_w M^-1 U_w^T K_w,   log |A| = log |Sigma_0| + log |M|,

and likewise for ``K^T A^-1 y*`` and ``y*^T A^-1 y*``: ``O(N p^2)`` per period,
never an ``N x N`` factorisation. Then ``w*_i = H_i^-1 K^T A_i^-1 y*_i`` with
``H_i = K^T A_i^-1 K`` (eq. 20), the per-period observation nuggets
``B_j[i] = 1 / H_i[j, j]`` (eq. 21: the paper keeps the bases independent, so
the coupling of the weights through ``D_i`` -- and, for an AR(1) output,
through ``R`` -- is dropped there, as in the paper), and the extra
log-likelihood term of eqs. 23–24, ``sum_i -(log |A_i| + y*_i^T C_i y*_i) / 2``
with ``y^T C y = y^T A^-1 y - g^T H^-1 g`` (``g = K^T A^-1 y``). The paper prints
``exp{y^T C y}``; the minus one half of a Gaussian exponent is meant. With
``D_i = 0`` and one white output everything reduces to the calibration phase:
``w*`` the least-squares weights of eq. 13 and ``B_j = (lambda* k_j^T k_j)^-1``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.noise import ObservationModel, ar1_whiten
from bayescal.errors import ConfigError

__all__ = [
    "ErrorCovariance",
    "GlsObservations",
    "PeriodMoments",
    "empirical_moments",
    "gls_observations",
]


@dataclass(frozen=True)
class PeriodMoments:
    """Empirical moments of ``y* - f`` per training period (eq. 25), standardised.

    Attributes
    ----------
    delta
        ``Delta_i`` as columns, ``(N, m*)``. [-]
    factor
        ``U_i`` with ``D_i = U_i U_i^T``, ``(m*, N, r)``, ``r <= p + 1``. [-]
    """

    delta: FloatArray
    factor: FloatArray


def empirical_moments(
    k: FloatArray,
    y_star: FloatArray,
    mean_w: FloatArray,
    var_w: FloatArray,
    realisations: int,
    rng: np.random.Generator,
) -> PeriodMoments:
    """``Delta_i`` and a factor of ``D_i`` from ``b`` realisations of the model (eq. 25).

    Parameters
    ----------
    k
        Basis ``K``, ``(N, p)``. [-]
    y_star
        Standardised observed periods ``Y*``, ``(N, m*)``. [-]
    mean_w, var_w
        Conditional mean and variance of the weights at ``[theta*, x_i]``, ``(m*, p)``. [-]
    realisations
        ``b``, the number of realisations per period.
    rng
        Generator of the realisations.
    """
    n_per, p = mean_w.shape
    z = rng.standard_normal((realisations, n_per, p))
    w = mean_w[None] + np.sqrt(np.maximum(var_w, 0.0))[None] * z  # (b, m*, p)
    e = np.concatenate([np.ones((realisations, n_per, 1)), -w], axis=2)  # (b, m*, p+1)
    s = np.einsum("kia,kib->iab", e, e) / realisations  # (m*, p+1, p+1)
    values, vectors = np.linalg.eigh(s)
    root = vectors * np.sqrt(np.maximum(values, 0.0))[:, None, :]  # S_i = root root^T
    g = np.concatenate([y_star.T[:, :, None], np.broadcast_to(k, (n_per, *k.shape))], axis=2)
    factor = g @ root  # (m*, N, p+1)
    delta = y_star - k @ w.mean(axis=0).T
    return PeriodMoments(delta, factor)


@dataclass(frozen=True)
class ErrorCovariance:
    """``Sigma_0 = blockdiag_o(R_o(phi_o) / lambda*_o)``: the measurement error of a period.

    Parameters
    ----------
    rows
        ``(start, stop)`` of every output's rows in the stacked outputs, covering
        ``0 .. N`` without gaps.
    lam_star
        ``lambda*_o`` per output (standardised units), > 0. [-]
    phi
        AR(1) coefficient per output (0 for white noise), ``|phi| < 1``. [-]
    """

    rows: tuple[tuple[int, int], ...]
    lam_star: tuple[float, ...]
    phi: tuple[float, ...]

    def __post_init__(self) -> None:
        n = len(self.rows)
        if not (len(self.lam_star) == len(self.phi) == n) or n == 0:
            raise ConfigError(
                f"got {n} output row ranges, {len(self.lam_star)} lambda* and "
                f"{len(self.phi)} AR(1) coefficients; expected one of each per output"
            )
        if not all(math.isfinite(v) and v > 0.0 for v in self.lam_star):
            raise ConfigError(f"every lambda* must be finite and > 0, got {self.lam_star}")
        if not all(abs(v) < 1.0 for v in self.phi):
            raise ConfigError(f"every AR(1) coefficient must satisfy |phi| < 1, got {self.phi}")

    @classmethod
    def white(cls, n: int, noise: float) -> ErrorCovariance:
        """One white output of ``n`` rows with variance ``noise = 1 / lambda*``."""
        return cls(((0, int(n)),), (1.0 / float(noise),), (0.0,))

    @classmethod
    def of(
        cls, observations: ObservationModel, lam_star: Sequence[float], phi: Sequence[float]
    ) -> ErrorCovariance:
        """From the outputs' error models, ``lambda*`` per output and ``phi`` per AR(1) output.

        Parameters
        ----------
        observations
            The outputs' error models (their rows and white/AR(1)).
        lam_star
            One ``lambda*`` per output. [-]
        phi
            One AR(1) coefficient per output with AR(1) errors, in their order. [-]
        """
        phis = [0.0] * observations.n_outputs
        ar = observations.ar_outputs
        if len(phi) != len(ar):
            raise ConfigError(
                f"got {len(phi)} AR(1) coefficients for {len(ar)} output(s) with AR(1) errors"
            )
        for q, value in zip(ar, phi, strict=True):
            phis[q] = float(value)
        return cls(
            tuple(o.rows for o in observations.outputs),
            tuple(float(v) for v in lam_star),
            tuple(phis),
        )

    @property
    def n(self) -> int:
        """Rows ``N`` of a period."""
        return self.rows[-1][1]

    def whiten(self, arr: FloatArray, axis: int = 0) -> FloatArray:
        """``Sigma_0^-1/2`` applied along ``axis`` (of length ``N``)."""
        moved = np.moveaxis(np.asarray(arr, dtype=float), axis, 0)
        if moved.shape[0] != self.n:
            raise ValueError(f"expected {self.n} rows along axis {axis}, got {moved.shape[0]}")
        out = np.empty_like(moved)
        for (start, stop), lam, phi in zip(self.rows, self.lam_star, self.phi, strict=True):
            out[start:stop] = math.sqrt(lam) * ar1_whiten(moved[start:stop], phi)
        return np.moveaxis(out, 0, axis)

    def logdet(self) -> float:
        """``log |Sigma_0|`` of one period."""
        total = 0.0
        for (start, stop), lam, phi in zip(self.rows, self.lam_star, self.phi, strict=True):
            n = stop - start
            total += -n * math.log(lam) + (n - 1) * math.log1p(-phi * phi)
        return total


@dataclass(frozen=True)
class GlsObservations:
    """Observed weights and nuggets under ``A_i`` (eqs. 20–24), standardised.

    Attributes
    ----------
    w_star
        GLS weights ``w*_i`` (eq. 20), ``(m*, p)``. [-]
    nuggets
        ``B_j[i] = (k_j^T A_i^-1 k_j)^-1`` (eq. 21), ``(p, m*)``. [-]
    extra
        ``sum_i -(log |A_i| + y*_i^T C_i y*_i) / 2`` (eqs. 23–24).
    """

    w_star: FloatArray
    nuggets: FloatArray
    extra: float


def gls_observations(
    k: FloatArray, y_star: FloatArray, factor: FloatArray, noise: float | ErrorCovariance
) -> GlsObservations:
    """Eqs. 20–24 for ``A_i = Sigma_0 + U_i U_i^T`` by the Woodbury identity.

    Parameters
    ----------
    k
        Basis ``K``, ``(N, p)``. [-]
    y_star
        Standardised observed periods, ``(N, m*)``. [-]
    factor
        ``U_i``, ``(m*, N, r)`` (:attr:`PeriodMoments.factor`); zeros give the
        calibration phase back. [-]
    noise
        The measurement error: ``1 / lambda*`` (one white output, the paper's
        eq. 22) or an :class:`ErrorCovariance`. [-]
    """
    cov = noise if isinstance(noise, ErrorCovariance) else ErrorCovariance.white(k.shape[0], noise)
    kw, yw = cov.whiten(k), cov.whiten(y_star)
    uw = cov.whiten(factor, axis=1)  # (m*, N, r)
    r = uw.shape[2]
    ut = np.swapaxes(uw, 1, 2)  # (m*, r, N)
    m = ut @ uw + np.eye(r)  # (m*, r, r)
    ku = kw.T[None] @ uw  # (m*, p, r)
    uy = (ut @ yw.T[:, :, None])[..., 0]  # (m*, r)
    rhs = np.concatenate([np.swapaxes(ku, 1, 2), uy[:, :, None]], axis=2)  # (m*, r, p+1)
    sol = np.linalg.solve(m, rhs)
    h = (kw.T @ kw)[None] - ku @ sol[:, :, :-1]
    g = (kw.T @ yw).T - (ku @ sol[:, :, -1:])[..., 0]
    yy = np.einsum("ni,ni->i", yw, yw) - np.einsum("ir,ir->i", uy, sol[:, :, -1])
    w_star = np.asarray(np.linalg.solve(h, g[:, :, None])[..., 0], dtype=float)  # (m*, p)
    _, logdet_m = np.linalg.slogdet(m)
    logdet_a = cov.logdet() + logdet_m
    quad = yy - np.einsum("ip,ip->i", g, w_star)
    nuggets = 1.0 / np.diagonal(h, axis1=1, axis2=2).T  # (p, m*)
    extra = -0.5 * float(np.sum(logdet_a + quad))
    return GlsObservations(w_star, np.ascontiguousarray(nuggets), extra)
