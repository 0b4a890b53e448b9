"""A Gaussian process of the discrepancy over the variable conditions ``x``.

The estimated ``Delta_i`` (standardised, ``N x m*``) is reduced by its own PCA
and each kept component gets an independent GP over ``x`` (the variable
inputs only), so that ``Delta`` can be predicted on new periods (the test
window) from their ``x``.

Basis
-----
Thin SVD ``Delta = U S V^T`` without centring (a constant bias is a component
like any other), scaled as the emulator's basis: ``K_d = U_c S_c / sqrt(m*)`` and
weights ``sqrt(m*) V_c`` of unit mean square. Components are kept by the optimal
hard threshold of Gavish & Donoho (2014, "The optimal hard threshold for
singular values is 4/sqrt(3)", IEEE Trans. Inf. Theory 60, 5040–5053) for white
noise: ``lambda(b) sqrt(n) sigma`` with ``n = max(N, m*)``, ``b = min(N, m*) / n``
and ``lambda(b) = sqrt(2 (b + 1) + 8 b / (b + 1 + sqrt(b^2 + 14 b + 1)))``.
The noise level ``sigma`` is estimated from the data (their "unknown noise"
rule, threshold ``omega(b) median(S)``, ``omega(b) ~ 0.56 b^3 - 0.95 b^2 +
1.82 b + 1.43``) unless given: the calibrated ``1 / lambda*`` is not used by
default because a systematic error inflates it (the calibration phase had no
other place to put it) and would hide the very components sought. At most
``max_components`` and ``m* - q - 1`` (``q`` trend terms) are kept.
Components under the threshold are indistinguishable from white noise and are
left to the noise term; with none kept ``Delta`` predicts as zero with zero
variance.

One component
-------------
``w = H b + g(x) + e`` with a trend ``H`` (``trend="constant"``: ``H = 1``;
``"linear"``: ``H = [1, x]``, which extrapolates a discrepancy driven by a
boundary condition beyond the training conditions), ``g ~ GP(0, tau^-1 R_x)``
with ``R_x`` the squared exponential of eq. 8 over ``x``
(:func:`bayescal.emulator.kernel.correlation`, ``beta = -4 ln rho``) and
``e ~ N(0, nu I)``. The coefficients ``b`` have a flat prior and are integrated
out (restricted likelihood; ``b`` is their GLS estimate). Hyperparameters at
their MAP on the log scale (L-BFGS-B, two starts) under the priors
``rho ~ Beta(1, 0.1)`` (ARD, as the emulator), ``tau ~ Gamma(5, 5)`` (unit-scale
weights, as eq. 8), and ``1 / nu ~ Gamma(5, 5 nu0)`` centred on the white-noise
level of the component, ``nu0 = sigma^2 m* / s_k^2``. The prediction at ``x0``
is the universal-kriging mean and the variance of the latent ``h(x0)^T b +
g(x0)`` (the GP variance reduced by the data plus the uncertainty of ``b``);
the noise ``e`` is not part of ``Delta``'s variance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg, optimize

from bayescal.emulator.hyper import log_prior_beta
from bayescal.emulator.kernel import FloatArray, correlation
from bayescal.errors import ConfigError, DataError

__all__ = ["MAX_COMPONENTS", "DeltaGP", "Trend", "fit_delta_gp", "hard_threshold"]

#: Most components of Delta that get a GP.
MAX_COMPONENTS = 5
Trend = Literal["constant", "linear"]
_RHO_A, _RHO_B = 1.0, 0.1  # Beta prior of rho (the emulator's)
_TAU_SHAPE, _TAU_RATE = 5.0, 5.0  # Gamma prior of tau
_NU_SHAPE = 5.0  # shape of the Gamma prior of 1 / nu (rate: shape * nu0)
_BAD = 1e300  # objective value of an impossible point


def trend_matrix(x: FloatArray, trend: str) -> FloatArray:
    """Regressors ``H`` of the trend at inputs ``x`` ``(P, s)``: ``(P, 1)`` or ``(P, 1 + s)``."""
    ones = np.ones((x.shape[0], 1))
    return ones if trend == "constant" else np.hstack([ones, x])


@dataclass(frozen=True)
class DeltaGP:
    """Independent GPs over ``x`` of the principal components of ``Delta``.

    Attributes
    ----------
    trend
        ``"constant"`` or ``"linear"`` (the regressors ``H``).
    basis
        ``K_d``, ``(N, c)`` (``c`` may be 0). [-]
    weights
        Training weights, ``(m*, c)``. [-]
    x
        Normalised variable conditions of the training periods, ``(m*, s)``. [-]
    beta
        ``-4 ln rho`` per component and input, ``(c, s)``. [-]
    tau
        GP precisions, ``(c,)``. [-]
    nugget
        Noise variances ``nu``, ``(c,)``. [-]
    coef
        GLS trend coefficients ``b``, ``(c, q)``. [-]
    chol
        Lower Cholesky factors of ``C = tau^-1 R_x + nu I``, ``(c, m*, m*)``.
    alpha
        ``C^-1 (w - H b)``, ``(c, m*)``.
    cinv_h
        ``C^-1 H``, ``(c, m*, q)``.
    hch_chol
        Lower Cholesky factors of ``H^T C^-1 H``, ``(c, q, q)``.
    """

    trend: str
    basis: FloatArray
    weights: FloatArray
    x: FloatArray
    beta: FloatArray
    tau: FloatArray
    nugget: FloatArray
    coef: FloatArray
    chol: FloatArray
    alpha: FloatArray
    cinv_h: FloatArray
    hch_chol: FloatArray

    @property
    def n_components(self) -> int:
        """``c``, the number of components with a GP."""
        return int(self.basis.shape[1])

    def predict_weights(self, x_new: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Mean and variance of the component weights at new periods, ``(P, c)`` each.

        Parameters
        ----------
        x_new
            Normalised variable conditions, ``(P, s)``. [-]
        """
        xx = np.atleast_2d(np.asarray(x_new, dtype=float))
        if xx.shape[1] != self.x.shape[1]:
            raise DataError(
                f"x_new has {xx.shape[1]} columns, the discrepancy was fitted on {self.x.shape[1]}"
            )
        h_new = trend_matrix(xx, self.trend)
        mean = np.zeros((xx.shape[0], self.n_components))
        var = np.zeros_like(mean)
        for j in range(self.n_components):
            cross = correlation(xx, self.x, self.beta[j]) / self.tau[j]  # (P, m*)
            mean[:, j] = h_new @ self.coef[j] + cross @ self.alpha[j]
            half = linalg.solve_triangular(self.chol[j], cross.T, lower=True, check_finite=False)
            gap = h_new - cross @ self.cinv_h[j]  # (P, q)
            gap_half = linalg.solve_triangular(self.hch_chol[j], gap.T, lower=True)
            reduction = np.sum(half * half, axis=0) - np.sum(gap_half * gap_half, axis=0)
            var[:, j] = 1.0 / self.tau[j] - reduction
        return mean, np.maximum(var, 0.0)

    def predict_std(self, x_new: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Mean and variance of standardised ``Delta``, ``(N, P)`` each."""
        mean_w, var_w = self.predict_weights(x_new)
        k = self.basis
        return k @ mean_w.T, (k * k) @ var_w.T


@dataclass(frozen=True)
class _Factors:
    """The restricted-likelihood pieces of one component at fixed hyperparameters."""

    chol: FloatArray
    alpha: FloatArray
    cinv_h: FloatArray
    hch_chol: FloatArray
    coef: FloatArray


@dataclass(frozen=True)
class _Component:
    """Restricted log posterior of one component on the log scale (for the optimiser)."""

    w: FloatArray
    x: FloatArray
    h: FloatArray
    nu0: float

    def factors(self, phi: FloatArray) -> _Factors:
        """Cholesky of ``C``, ``C^-1 (w - H b)``, ``C^-1 H``, ``chol(H^T C^-1 H)`` and ``b``."""
        s = self.x.shape[1]
        cov = correlation(self.x, self.x, np.exp(phi[:s])) / math.exp(phi[s])
        cov[np.diag_indices_from(cov)] += math.exp(phi[s + 1])
        chol = linalg.cholesky(cov, lower=True, check_finite=False)
        sol = linalg.cho_solve((chol, True), np.column_stack([self.w, self.h]))
        cinv_h = sol[:, 1:]
        hch_chol = linalg.cholesky(self.h.T @ cinv_h, lower=True, check_finite=False)
        coef = linalg.cho_solve((hch_chol, True), self.h.T @ sol[:, 0])
        return _Factors(chol, sol[:, 0] - cinv_h @ coef, cinv_h, hch_chol, coef)

    def __call__(self, phi: FloatArray) -> float:
        """Negative log posterior density of ``phi = [ln beta, ln tau, ln nu]``."""
        s = self.x.shape[1]
        with np.errstate(over="ignore"):
            beta, tau, nu = np.exp(phi[:s]), math.exp(phi[s]), math.exp(phi[s + 1])
        prior = log_prior_beta(beta, _RHO_A, _RHO_B) + float(np.sum(phi[:s]))
        prior += _TAU_SHAPE * math.log(tau) - _TAU_RATE * tau
        prior += -_NU_SHAPE * phi[s + 1] - _NU_SHAPE * self.nu0 / nu
        if not math.isfinite(prior):
            return _BAD
        try:
            f = self.factors(phi)
        except np.linalg.LinAlgError:
            return _BAD
        quad = float(np.dot(self.w, f.alpha))  # (w - H b)^T C^-1 (w - H b), as H^T alpha = 0
        logdet = 2.0 * float(np.sum(np.log(np.diag(f.chol))))
        logdet += 2.0 * float(np.sum(np.log(np.diag(f.hch_chol))))
        return 0.5 * (logdet + quad) - prior


def _fit_component(target: _Component) -> FloatArray:
    """MAP ``[ln beta, ln tau, ln nu]`` of one component from two starts."""
    s, nu0 = target.x.shape[1], target.nu0
    signal = max(float(np.var(target.w)) - nu0, 0.1)
    bounds = [(-8.0, 6.0)] * s + [(-8.0, 8.0), (math.log(nu0) - 8.0, math.log(nu0) + 8.0)]
    best, best_value = None, math.inf
    for log_beta in (math.log(0.3), math.log(3.0)):
        start = np.array([log_beta] * s + [-math.log(signal), math.log(nu0)])
        res = optimize.minimize(target, start, method="L-BFGS-B", bounds=bounds)
        if res.fun < best_value:
            best, best_value = np.asarray(res.x, dtype=float), float(res.fun)
    if best is None or best_value >= _BAD:
        raise DataError("the discrepancy GP found no positive-definite covariance")
    return best


def hard_threshold(
    singular_values: ArrayLike, shape: tuple[int, int], noise: float | None = None
) -> tuple[float, float]:
    """Gavish–Donoho optimal hard threshold and the white-noise variance behind it.

    Parameters
    ----------
    singular_values
        All ``min(shape)`` singular values of the matrix. [-]
    shape
        ``(N, m*)`` of the matrix.
    noise
        Known noise variance per entry; estimated from the median singular
        value when omitted. [-]

    Returns
    -------
    threshold, noise
        Singular values above ``threshold`` are signal; ``noise`` is the
        (given or estimated) variance per entry. [-]
    """
    n = max(shape)
    b = min(shape) / n
    lam = math.sqrt(2.0 * (b + 1.0) + 8.0 * b / (b + 1.0 + math.sqrt(b * b + 14.0 * b + 1.0)))
    if noise is None:
        omega = 0.56 * b**3 - 0.95 * b**2 + 1.82 * b + 1.43
        threshold = omega * float(np.median(np.asarray(singular_values, dtype=float)))
        return threshold, (threshold / (lam * math.sqrt(n))) ** 2
    return lam * math.sqrt(n * noise), float(noise)


def fit_delta_gp(
    delta_std: ArrayLike,
    x: ArrayLike,
    *,
    noise: float | None = None,
    max_components: int = MAX_COMPONENTS,
    trend: Trend = "constant",
) -> DeltaGP:
    """PCA of standardised ``Delta`` and one MAP GP over ``x`` per kept component.

    Parameters
    ----------
    delta_std
        Standardised discrepancy of the training periods, ``(N, m*)``. [-]
    x
        Normalised variable conditions of those periods, ``(m*, s)``. [-]
    noise
        White-noise variance per sample, if known; estimated otherwise. [-]
    max_components
        Most components kept.
    trend
        ``"constant"`` or ``"linear"`` (in ``x``) mean of each component.
    """
    if trend not in ("constant", "linear"):
        raise ConfigError(f"trend must be 'constant' or 'linear', got {trend!r}")
    d = np.asarray(delta_std, dtype=float)
    xx = np.asarray(x, dtype=float)
    m = d.shape[1]
    if d.ndim != 2 or xx.ndim != 2 or xx.shape[0] != m:
        raise DataError(f"expected Delta (N, m*) and x (m*, s), got {d.shape} and {xx.shape}")
    h = trend_matrix(xx, trend)
    u, sv, vt = linalg.svd(d, full_matrices=False)
    threshold, noise = hard_threshold(sv, d.shape, noise)
    c = int(min(np.sum(sv > threshold), max_components, max(m - h.shape[1] - 1, 0)))
    basis, weights = u[:, :c] * sv[:c] / math.sqrt(m), math.sqrt(m) * vt[:c].T
    comps = [_Component(weights[:, j], xx, h, noise * m / sv[j] ** 2) for j in range(c)]
    phis = [_fit_component(comp) for comp in comps]
    facts = [comp.factors(phi) for comp, phi in zip(comps, phis, strict=True)]
    s, q = xx.shape[1], h.shape[1]
    return DeltaGP(
        trend=trend,
        basis=basis,
        weights=weights,
        x=xx,
        beta=np.array([np.exp(p[:s]) for p in phis]).reshape(c, s),
        tau=np.array([math.exp(p[s]) for p in phis]),
        nugget=np.array([math.exp(p[s + 1]) for p in phis]),
        coef=np.array([f.coef for f in facts]).reshape(c, q),
        chol=np.array([f.chol for f in facts]).reshape(c, m, m),
        alpha=np.array([f.alpha for f in facts]).reshape(c, m),
        cinv_h=np.array([f.cinv_h for f in facts]).reshape(c, m, q),
        hch_chol=np.array([f.hch_chol for f in facts]).reshape(c, q, q),
    )
