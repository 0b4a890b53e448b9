"""Leave-one-period-out predictive accuracy of a calibration (choices without the test window).

To compare parameter sets, priors, error models or the discrepancy on the
training data alone, each training period ``i`` is scored by its pointwise log
predictive density under the posterior: for every retained draw ``s``

    l_is = log p(y*_i | theta*_s, lambda*_s, phi_s, r_s; simulations),

the density of the period's measurements given the draw and the simulator
runs, predicted the way bayescal predicts a test period: in the weights' space,
``w_hat_i ~ N(mu_i, diag(v_i) + r_0 tau^-1 + N_obs)`` with ``mu_i, v_i`` the
emulator's prediction at ``(theta*_s, x_i)``, ``r_0 tau^-1`` a model discrepancy
independent between periods where one is used, ``N_obs`` the noise of the
observed weights (white: ``1 / (lambda* k_j^T k_j)``; AR(1): ``H0^-1 /
lambda*``), plus the out-of-basis remainder of :mod:`bayescal.emulator.noise`
(so the density is that of the measured samples, comparable across error models
and bases). A discrepancy over the periods' conditions, ``GP(0, r tau^-1 c_x)``,
is kriged from the other training periods' residuals, as the predictions
condition it on the training residuals (:func:`loo_conditional`); the other
measured periods enter nowhere else.

:func:`elpd` estimates the expected log predictive density of a left-out period
by Pareto-smoothed importance sampling (ArviZ's ``loo``), with its standard
error and the Pareto ``k`` of each period (above 0.7 the estimate of that
period is unreliable: the report says so).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import special

from bayescal.calibration.orthogonal import Sensitivity, constrained_prior
from bayescal.calibration.posterior import Posterior
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import LOG_2PI
from bayescal.emulator.noise import ObservationModel, ar1_whiten
from bayescal.mcmc.diagnostics import import_arviz

__all__ = [
    "Elpd",
    "elpd",
    "loo_conditional",
    "loo_pit",
    "period_log_densities",
    "period_predictive",
    "pointwise_log_likelihood",
    "pointwise_scores",
]

FloatArray = NDArray[np.float64]
#: Pareto k above which PSIS-LOO is unreliable for a period (Vehtari et al. 2017).
PARETO_K_MAX = 0.7


def _thin(n_total: int, n: int) -> NDArray[np.intp]:
    return np.unique(np.linspace(0, n_total - 1, min(n, n_total)).astype(int))


def pointwise_log_likelihood(
    emulator: Emulator,
    observations: ObservationModel,
    posterior: Posterior,
    draws_per_chain: int = 250,
) -> FloatArray:
    """``l_is`` of the module docstring, ``(chains, draws, m*)``.

    Parameters
    ----------
    emulator
        The trained emulator.
    observations
        The outputs' error models and the measured training periods.
    posterior
        The calibration posterior (theta*, lambda*, phi, discrepancy r).
    draws_per_chain
        Draws per chain used (thinned evenly).
    """
    return pointwise_scores(emulator, observations, posterior, draws_per_chain)[0]


def pointwise_scores(
    emulator: Emulator,
    observations: ObservationModel,
    posterior: Posterior,
    draws_per_chain: int = 250,
    scored: Sequence[int] | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``l_is`` ``(chains, draws, m*)`` and every sample's left-out predictive mean and
    SD at every draw ``(chains, draws, n, m*)`` each (:func:`period_predictive`;
    standardised units).

    ``scored``: the indices of the outputs (``observations.outputs``) whose
    samples ``l_is`` is the density of (``None``: all). Given a draw the outputs'
    left-out predictions are independent (each has its own basis vectors, error
    model and discrepancy), so the density of some outputs' samples is the sum of
    their terms: what a variant that calibrates more outputs is scored on, beside
    one that calibrates fewer (``bayescal compare`` across output sets).
    """
    chains, n_draws = posterior.unit_draws.shape[:2]
    pick = _thin(n_draws, draws_per_chain)
    unit = posterior.unit_draws[:, pick]
    aux = posterior.aux[:, pick]
    names = posterior.aux_names
    obs = observations
    n, m = obs.y_star.shape
    x = emulator.x
    out = np.empty((chains, pick.size, m))
    mus = np.empty((chains, pick.size, n, m))
    sds = np.empty((chains, pick.size, n, m))
    kernels = emulator.kernels
    variances = np.array([k.variance for k in kernels])
    ls_weights = obs.ls_weights()
    x_corr = np.stack([k.x_corr(x[:m]) for k in kernels]) if obs.delta_over_conditions else None
    orthogonal = [obs.outputs[q].bases for q in obs.orthogonal_outputs]
    sensitivity = Sensitivity(emulator, m, orthogonal) if orthogonal else None
    for c in range(chains):
        for s in range(pick.size):
            mean, var = emulator.predict_weights(np.broadcast_to(unit[c, s], (m, unit.shape[2])), x)
            values = dict(zip(names, aux[c, s], strict=True))
            f = None if sensitivity is None else sensitivity(unit[c, s], values["lambda"])
            parts = _left_out(obs, values, mean, var, variances, ls_weights, x_corr, f)
            out[c, s] = _densities(obs, parts, scored)  # period_log_densities, once per draw
            mus[c, s], sds[c, s] = _predictive(obs, mean, parts)  # period_predictive
    return out, mus, sds


def loo_pit(
    y: FloatArray, mu: FloatArray, sd: FloatArray, log_weights: FloatArray | None = None
) -> FloatArray:
    """Probability integral transform of every left-out sample ``(n, m*)``.

    ``PIT_ti = sum_s w_is Phi((y_ti - mu_sti) / sd_sti)``: the predictive
    distribution of sample ``t`` of period ``i`` is the mixture over the draws
    ``s`` of their Gaussians, weighted by the period's normalised importance
    weights ``w_is`` (``log_weights`` ``(m*, S)``, PSIS) or equally (``None``:
    draws of a refit without the period). A sample lies inside the central
    band of level ``L`` exactly when ``|PIT - 1/2| < L/2``.

    Parameters
    ----------
    y
        The measured samples ``(n, m*)``.
    mu, sd
        Predictive means and SDs per draw ``(S, n, m*)``.
    log_weights
        Log importance weights per period ``(m*, S)``, normalised, or ``None``.
    """
    cdf = special.ndtr((np.asarray(y)[None] - mu) / sd)  # (S, n, m*)
    if log_weights is None:
        out: FloatArray = cdf.mean(axis=0)
        return out
    w = np.exp(np.asarray(log_weights) - special.logsumexp(log_weights, axis=1, keepdims=True))
    return np.asarray(np.einsum("is,sti->ti", w, cdf))


def period_log_densities(
    obs: ObservationModel,
    values: dict[str, float],
    mean: FloatArray,
    var: FloatArray,
    ktk: FloatArray,
    variances: FloatArray,
    ls_weights: FloatArray,
    x_corr: FloatArray | None = None,
    constraint: FloatArray | None = None,
    scored: Sequence[int] | None = None,
) -> FloatArray:
    """Log density of every period's measurements ``(m*,)`` at one draw.

    Parameters
    ----------
    obs
        Error models and measured periods.
    values
        The draw's aux coordinates by name (``lambda_star..``, ``phi..``, ``delta_rel..``).
    mean, var
        The emulator's predictive mean and variance of the weights at the draw's
        theta* and every period's ``x``, ``(m*, p)``. [-]
    ktk
        ``k_j^T k_j`` ``(p,)``. [-]
    variances
        ``1 / tau_j`` ``(p,)`` (scale of a discrepancy). [-]
    ls_weights
        Least-squares weights of the measured periods ``(m*, p)``. [-]
    x_corr
        ``c_x`` of every basis over the training periods ``(p, m*, m*)``: a
        discrepancy over the conditions is then kriged from the other periods'
        residuals, as the predictions do (:func:`loo_conditional`); ``None``:
        its marginal. [-]
    constraint
        ``F`` ``(p, m*, K)`` of the orthogonal discrepancies at the draw
        (:class:`~bayescal.calibration.orthogonal.Sensitivity`); needs ``x_corr``. [-]
    scored
        The indices of the outputs whose samples are scored (``None``: all; the
        others are predicted all the same, and left out of the sum).
    """
    parts = _left_out(obs, values, mean, var, variances, ls_weights, x_corr, constraint)
    return _densities(obs, parts, scored)


def _left_out(
    obs: ObservationModel,
    values: dict[str, float],
    mean: FloatArray,
    var: FloatArray,
    variances: FloatArray,
    ls_weights: FloatArray,
    x_corr: FloatArray | None,
    constraint: FloatArray | None = None,
) -> list[tuple[_OutputPart, FloatArray, FloatArray]]:
    """Each output's pieces and its periods' left-out residual weights and covariance."""
    out = []
    for q in range(obs.n_outputs):
        part = _OutputPart.of(obs, q, values, mean, var, variances, ls_weights, x_corr)
        if q in obs.orthogonal_outputs:
            part = part.orthogonal(obs, q, constraint)
        out.append((part, *part.left_out()))
    return out


def _densities(
    obs: ObservationModel,
    parts: list[tuple[_OutputPart, FloatArray, FloatArray]],
    scored: Sequence[int] | None = None,
) -> FloatArray:
    total = np.zeros(obs.y_star.shape[1])
    for q, (part, resid, cov) in enumerate(parts):
        if scored is not None and q not in scored:
            continue
        chol = np.linalg.cholesky(cov)
        half = np.linalg.solve(chol, resid[:, :, None])[:, :, 0]
        in_basis = -0.5 * (
            part.p * LOG_2PI
            + 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
            + np.sum(half * half, axis=1)
        )
        total += in_basis + part.remainder()
    return total


def period_predictive(
    obs: ObservationModel,
    values: dict[str, float],
    mean: FloatArray,
    var: FloatArray,
    variances: FloatArray,
    ls_weights: FloatArray,
    x_corr: FloatArray | None = None,
    constraint: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Each left-out period's predictive mean and SD of every measured sample at one draw.

    The same prediction as :func:`period_log_densities`, sample by sample: the
    weights ``z_i`` of the left-out period (the emulator's prediction, a
    discrepancy kriged from the other periods where one is over the
    conditions), mapped by the basis, plus the observation noise ``1 / lambda*``
    (its marginal variance: an AR(1) correlation has a unit diagonal). This is
    the emulator route's band of section 6 of docs/method.md for a period the
    calibration did not see.

    Parameters
    ----------
    obs, values, mean, var, variances, ls_weights, x_corr, constraint
        As :func:`period_log_densities`.

    Returns
    -------
    mu, sd
        ``(n, m*)`` each, in the standardised units of ``obs.y_star``. [-]
    """
    parts = _left_out(obs, values, mean, var, variances, ls_weights, x_corr, constraint)
    return _predictive(obs, mean, parts)


def _predictive(
    obs: ObservationModel,
    mean: FloatArray,
    parts: list[tuple[_OutputPart, FloatArray, FloatArray]],
) -> tuple[FloatArray, FloatArray]:
    mu = np.empty_like(obs.y_star)
    sd = np.empty_like(obs.y_star)
    for o, (part, resid, cov) in zip(obs.outputs, parts, strict=True):
        weights = mean[:, list(o.bases)] + part.diff - resid  # E[z_i | the other periods]
        cov_z = cov - part.noise[None]
        rows = slice(*o.rows)
        mu[rows] = part.kq @ weights.T
        spread = np.einsum("ta,iab,tb->ti", part.kq, cov_z, part.kq)
        sd[rows] = np.sqrt(np.maximum(spread, 0.0) + 1.0 / part.lam)
    return mu, sd


@dataclass(frozen=True)
class _OutputPart:
    """One output's pieces of a left-out period's prediction at one draw."""

    kq: FloatArray  # K_o (n_o, p_o)
    diff: FloatArray  # measured minus predicted weights (m*, p_o)
    own: FloatArray  # covariance of a period's true weights alone (m*, p_o, p_o)
    noise: FloatArray  # the observed weights' noise (p_o, p_o)
    kriged: FloatArray | None  # r tau^-1 c_x per basis (p_o, m*, m*) [orthogonal:
    # the constrained covariance (p_o, m*, p_o, m*)], or None
    lam: float
    rss: FloatArray  # out-of-basis sum of squares per period (m*,)
    logdets: tuple[float, float]  # log|R|, log|H0|
    n: int

    @property
    def p(self) -> int:
        return int(self.kq.shape[1])

    @classmethod
    def of(
        cls,
        obs: ObservationModel,
        q: int,
        values: dict[str, float],
        mean: FloatArray,
        var: FloatArray,
        variances: FloatArray,
        ls_weights: FloatArray,
        x_corr: FloatArray | None,
    ) -> _OutputPart:
        o = obs.outputs[q]
        lam = float(values[obs.names()[q]])
        bases = list(o.bases)
        m = obs.y_star.shape[1]
        own = np.zeros((m, o.p, o.p))
        own[:, np.arange(o.p), np.arange(o.p)] = var[:, bases]
        kriged = None
        for kind in o.delta_parts:
            r = values[obs.coordinate(kind, q)]
            if kind == "delta_rel" and x_corr is not None:
                kriged = (r * variances[bases])[:, None, None] * x_corr[bases]
            else:  # independent between periods, or no correlation given: its marginal
                own[:, np.arange(o.p), np.arange(o.p)] += r * variances[bases]
        kq, yq = obs.block(q)
        if o.model == "ar1":
            phi = values[obs.coordinate("phi", q)]
            piece = obs.gls(q, phi)
            w_hat, noise = piece.w_hat, piece.h0_inv / lam
            logdets = (piece.logdet_r, piece.logdet_h0)
            resid = ar1_whiten(yq, phi) - ar1_whiten(kq, phi) @ w_hat.T
        else:  # H0 = K^T K (diagonal for the GPMSA basis, whose vectors are orthogonal)
            w_hat = ls_weights[:, bases]
            gram = kq.T @ kq
            noise = np.asarray(np.linalg.inv(gram) / lam, dtype=float)
            logdets = (0.0, float(np.linalg.slogdet(gram)[1]))
            resid = yq - kq @ w_hat.T
        rss = np.sum(resid * resid, axis=0)  # per period
        return cls(kq, w_hat - mean[:, bases], own, noise, kriged, lam, rss, logdets, o.n)

    def orthogonal(self, obs: ObservationModel, q: int, f: FloatArray | None) -> _OutputPart:
        """The same with the discrepancy over the conditions constrained orthogonal to the
        model's sensitivities (``f``: ``F`` of every orthogonal output, ``(p, m*, K)``)."""
        if self.kriged is None or f is None:
            raise ValueError("an orthogonal discrepancy needs x_corr and its constraint")
        bases = list(obs.outputs[q].bases)
        cols = np.flatnonzero(np.any(f[bases] != 0.0, axis=(0, 1)))
        return replace(self, kriged=constrained_prior(self.kriged, f[bases][:, :, cols]))

    def left_out(self) -> tuple[FloatArray, FloatArray]:
        """Each period's measured weights minus their prediction from the others, and its
        covariance: ``(m*, p_o)``, ``(m*, p_o, p_o)``."""
        blocks = self.own + self.noise[None]
        if self.kriged is None:
            return self.diff, blocks
        return loo_conditional(self.diff, self.kriged, blocks)

    def remainder(self) -> FloatArray:
        """The out-of-basis term of each period (eq. 7 with the error correlation)."""
        dof = self.n - self.p
        logdet_r, logdet_h0 = self.logdets
        return -0.5 * (
            dof * (LOG_2PI - math.log(self.lam)) + logdet_r + logdet_h0 + self.lam * self.rss
        )


def loo_conditional(
    diff: FloatArray, prior: FloatArray, blocks: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Each period's residual weights given every other period's.

    The residual weights ``e = w_hat - mu`` ``(m*, p_o)`` are Gaussian with
    covariance ``Sigma = G + blockdiag_i(B_i)``: ``G`` the discrepancy over the
    conditions, ``prior[j] = r tau_j^-1 c_x`` ``(p_o, m*, m*)`` per basis (or one
    ``(p_o, m*, p_o, m*)`` with the bases correlated), ``B_i``
    ``(m*, p_o, p_o)`` what belongs to period ``i`` alone (the emulator's
    variance, the observed weights' noise, a discrepancy independent between
    periods). Period ``i`` given the others is ``N(e_i - P_ii^-1 u_i, P_ii^-1)``
    with ``P = Sigma^-1`` and ``u = P e`` (the Gaussian leave-one-out identity).

    Returns
    -------
    resid, cov
        ``P_ii^-1 u_i`` (``e_i`` minus its prediction from the others) ``(m*, p_o)``
        and ``P_ii^-1`` ``(m*, p_o, p_o)``.
    """
    m, p = diff.shape
    sigma = np.zeros((m, p, m, p))  # period-major
    if prior.ndim == 4:  # bases correlated a priori (basis-major, the orthogonal discrepancy)
        sigma += prior.transpose(1, 0, 3, 2)
    for j in range(p if prior.ndim == 3 else 0):
        sigma[:, j, :, j] = prior[j]
    sigma[np.arange(m), :, np.arange(m), :] += blocks
    flat = sigma.reshape(m * p, m * p)
    precision = np.linalg.inv(0.5 * (flat + flat.T)).reshape(m, p, m, p)
    u = np.einsum("iajb,jb->ia", precision, diff)
    own = precision[np.arange(m), :, np.arange(m), :]
    cov = np.linalg.inv(0.5 * (own + np.swapaxes(own, 1, 2)))
    resid = np.einsum("iab,ib->ia", cov, u)
    return resid, cov


@dataclass(frozen=True)
class Elpd:
    """Leave-one-period-out expected log predictive density.

    Attributes
    ----------
    elpd
        Sum over the training periods of the estimated log predictive density
        of each period left out.
    se
        Its standard error.
    pointwise
        Per period ``(m*,)``.
    pareto_k
        Pareto ``k`` of each period's importance weights ``(m*,)``.
    """

    elpd: float
    se: float
    pointwise: FloatArray
    pareto_k: FloatArray

    @property
    def unreliable(self) -> int:
        """Periods whose Pareto ``k`` exceeds :data:`PARETO_K_MAX`."""
        return int(np.sum(self.pareto_k > PARETO_K_MAX))


def elpd(log_likelihood: FloatArray) -> Elpd:
    """PSIS-LOO of ``(chains, draws, m*)`` pointwise log-likelihoods (ArviZ)."""
    import warnings

    az = import_arviz()
    idata = az.from_dict(
        posterior={"dummy": np.zeros(log_likelihood.shape[:2])},
        log_likelihood={"y": log_likelihood},
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ArviZ warns about high k; we report it per period
        result = az.loo(idata, pointwise=True)
    return Elpd(
        float(result.elpd_loo),
        float(result.se),
        np.asarray(result.loo_i.values, dtype=float),
        np.asarray(result.pareto_k.values, dtype=float),
    )
