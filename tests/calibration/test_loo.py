"""Leave-one-period-out: per-period densities against the dense Gaussian of the samples."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy import linalg, stats

from bayescal.calibration.loo import elpd, period_log_densities, period_predictive
from bayescal.emulator.noise import ObservationModel, OutputNoise


def _ar1_corr(n: int, phi: float) -> np.ndarray:
    i = np.arange(n)
    return phi ** np.abs(i[:, None] - i[None, :])


def _two_outputs(seed: int, m: int, model: str, discrepancy: Any) -> tuple[Any, ...]:
    """Output a (7 samples, 2 bases, the error model and discrepancy given) and output b
    (5 samples, 1 basis, white), random data over ``m`` periods, the emulator's
    prediction ``mean, var`` ``(m, 3)``, ``k_j^T k_j`` and ``1 / tau_j``."""
    rng = np.random.default_rng(seed)
    k = linalg.block_diag(rng.normal(size=(7, 2)), rng.normal(size=(5, 1)))
    y = rng.normal(size=(12, m))
    outputs = (
        OutputNoise("a", (0, 7), (0, 1), model, discrepancy=discrepancy),  # type: ignore[arg-type]
        OutputNoise("b", (7, 12), (2,)),
    )
    obs = ObservationModel(outputs, k, y)
    mean, var = rng.normal(size=(m, 3)), rng.uniform(0.1, 0.5, (m, 3))
    ktk = np.einsum("ij,ij->j", k, k)
    return rng, k, y, obs, mean, var, ktk, rng.uniform(0.5, 2.0, 3)


CASES = [("white", 0.0, False), ("ar1", 0.7, False), ("white", 0.0, True), ("ar1", -0.4, True)]


@pytest.mark.parametrize(("model", "phi", "discrepancy"), CASES)
def test_period_density_is_the_gaussian_of_the_samples(
    model: str, phi: float, discrepancy: bool
) -> None:
    # Two outputs with block-diagonal bases; each period's samples are
    # y = K w + e, w ~ N(mean, diag(var) + r tau^-1), e ~ N(0, R / lambda*).
    m = 4
    _, k, y, obs, mean, var, ktk, variances = _two_outputs(3, m, model, discrepancy)
    values = {"lambda_star_a": 9.0, "lambda_star_b": 4.0}
    if model == "ar1":
        values["phi_a"] = phi
    if discrepancy:
        values["delta_rel_a"] = 0.3
    got = period_log_densities(obs, values, mean, var, ktk, variances, obs.ls_weights())
    # each output's samples alone (what variants calibrating different outputs share)
    alone = [
        period_log_densities(obs, values, mean, var, ktk, variances, obs.ls_weights(), scored=[q])
        for q in (0, 1)
    ]
    for i in range(m):
        want = 0.0
        for q, (rows, bases, lam, ph, rel) in enumerate((
            (slice(0, 7), [0, 1], 9.0, phi, 0.3 if discrepancy else 0.0),
            (slice(7, 12), [2], 4.0, 0.0, 0.0),
        )):  # fmt: skip
            kq = k[rows][:, bases]
            cov_w = np.diag(var[i, bases] + rel * variances[bases])
            cov = kq @ cov_w @ kq.T + _ar1_corr(kq.shape[0], ph) / lam
            part = stats.multivariate_normal(kq @ mean[i, bases], cov).logpdf(y[rows, i])
            assert alone[q][i] == pytest.approx(part, rel=1e-10)
            want += part
        assert got[i] == pytest.approx(want, rel=1e-10)


@pytest.mark.parametrize(
    ("model", "phi", "kind"),
    [("white", 0.0, "conditions"), ("ar1", 0.7, "conditions"), ("ar1", -0.4, "both"),
     ("white", 0.0, "independent")],
)  # fmt: skip
def test_a_discrepancy_over_the_conditions_is_kriged_from_the_other_periods(
    model: str, phi: float, kind: str
) -> None:
    # Output a carries delta_ij with cov r tau_j c_x(x_i, x_k) (+ r0 tau_j [i = k]); each
    # period's density is then that of its samples given every other period's samples
    # (the dense Gaussian conditional of all m* periods' samples); output b's periods
    # stay independent.
    m = 5
    rng, k, y, obs, mean, var, ktk, variances = _two_outputs(5, m, model, kind)
    xs = rng.random((m, 2))
    x_corr = np.stack([np.exp(-((xs[:, None, :] - xs[None, :, :]) ** 2).sum(-1) / (2 * s * s))
                       for s in (0.4, 0.7, 0.3)])  # fmt: skip
    r, r0 = 0.3, 0.2
    values = {"lambda_star_a": 9.0, "lambda_star_b": 4.0, "delta_rel_a": r, "delta_ind_a": r0}
    if model == "ar1":
        values["phi_a"] = phi
    over_x, independent = kind in ("conditions", "both"), kind in ("independent", "both")
    got = period_log_densities(obs, values, mean, var, ktk, variances, obs.ls_weights(), x_corr)
    alone = period_log_densities(
        obs, values, mean, var, ktk, variances, obs.ls_weights(), x_corr, scored=[0]
    )
    # each sample's predictive mean and SD: the same conditional, sample by sample
    p_mu, p_sd = period_predictive(obs, values, mean, var, variances, obs.ls_weights(), x_corr)
    # output a: all periods' samples at once (period-major), conditioned period by period
    ka, n = k[:7, :2], 7
    cov = np.zeros((m * n, m * n))
    for j in range(2):
        c_w = np.diag(var[:, j]) + variances[j] * (
            over_x * r * x_corr[j] + independent * r0 * np.eye(m)
        )
        cov += np.kron(c_w, np.outer(ka[:, j], ka[:, j]))
    cov += np.kron(np.eye(m), _ar1_corr(n, phi) / 9.0)
    mu = (mean[:, :2] @ ka.T).reshape(-1)
    ya = y[:7].T.reshape(-1)
    for i in range(m):
        own = np.arange(i * n, (i + 1) * n)
        rest = np.setdiff1d(np.arange(m * n), np.arange(i * n, (i + 1) * n))
        gain = np.linalg.solve(cov[np.ix_(rest, rest)], cov[np.ix_(rest, own)]).T
        c_mean = mu[own] + gain @ (ya[rest] - mu[rest])
        c_cov = cov[np.ix_(own, own)] - gain @ cov[np.ix_(rest, own)]
        want = stats.multivariate_normal(c_mean, c_cov).logpdf(ya[own])
        assert alone[i] == pytest.approx(want, rel=1e-9)  # output a's samples alone
        kb = k[7:, 2:]
        c_b = kb @ np.diag(var[i, 2:]) @ kb.T + np.eye(5) / 4.0
        want += stats.multivariate_normal(kb @ mean[i, 2:], c_b).logpdf(y[7:, i])
        assert got[i] == pytest.approx(want, rel=1e-9)
        np.testing.assert_allclose(p_mu[:7, i], c_mean, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(p_sd[:7, i] ** 2, np.diagonal(c_cov), rtol=1e-9)
        np.testing.assert_allclose(p_mu[7:, i], kb @ mean[i, 2:], rtol=1e-12)
        np.testing.assert_allclose(p_sd[7:, i] ** 2, np.diagonal(c_b), rtol=1e-12)
    # the other periods moved the score where the discrepancy is correlated (can fail)
    marginal = period_log_densities(obs, values, mean, var, ktk, variances, obs.ls_weights())
    assert np.any(np.abs(got - marginal) > 1e-3) == over_x


def test_psis_loo_of_a_known_normal_model() -> None:
    # y_i ~ N(mu, 1) with mu's posterior from 20 observations: the LOO density of each
    # point is the predictive of the other 19, N(mean_{-i}, 1 + 1/19) (flat prior).
    rng = np.random.default_rng(5)
    y = rng.normal(size=20)
    mu = rng.normal(y.mean(), 1.0 / np.sqrt(20), (4, 4000))
    loglik = stats.norm.logpdf(y[None, None, :], mu[..., None], 1.0)
    result = elpd(loglik)
    exact = sum(
        stats.norm.logpdf(y[i], np.delete(y, i).mean(), np.sqrt(1 + 1 / 19)) for i in range(20)
    )
    assert result.elpd == pytest.approx(exact, abs=0.05)  # importance sampling error
    assert result.unreliable == 0
    assert result.se > 0.0
