"""Leave-one-period-out: per-period densities against the dense Gaussian of the samples."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg, stats

from bayescal.calibration.loo import elpd, period_log_densities
from bayescal.emulator.noise import ObservationModel, OutputNoise


def _ar1_corr(n: int, phi: float) -> np.ndarray:
    i = np.arange(n)
    return phi ** np.abs(i[:, None] - i[None, :])


CASES = [("white", 0.0, False), ("ar1", 0.7, False), ("white", 0.0, True), ("ar1", -0.4, True)]


@pytest.mark.parametrize(("model", "phi", "discrepancy"), CASES)
def test_period_density_is_the_gaussian_of_the_samples(
    model: str, phi: float, discrepancy: bool
) -> None:
    # Two outputs with block-diagonal bases; each period's samples are
    # y = K w + e, w ~ N(mean, diag(var) + r tau^-1), e ~ N(0, R / lambda*).
    rng = np.random.default_rng(3)
    k = linalg.block_diag(rng.normal(size=(7, 2)), rng.normal(size=(5, 1)))
    m = 4
    y = rng.normal(size=(12, m))
    outputs = (
        OutputNoise("a", (0, 7), (0, 1), model, discrepancy=discrepancy),  # type: ignore[arg-type]
        OutputNoise("b", (7, 12), (2,)),
    )
    obs = ObservationModel(outputs, k, y)
    mean, var = rng.normal(size=(m, 3)), rng.uniform(0.1, 0.5, (m, 3))
    ktk = np.einsum("ij,ij->j", k, k)
    variances = rng.uniform(0.5, 2.0, 3)
    values = {"lambda_star_a": 9.0, "lambda_star_b": 4.0}
    if model == "ar1":
        values["phi_a"] = phi
    if discrepancy:
        values["delta_rel_a"] = 0.3
    got = period_log_densities(obs, values, mean, var, ktk, variances, obs.ls_weights())
    for i in range(m):
        want = 0.0
        for rows, bases, lam, ph, rel in (
            (slice(0, 7), [0, 1], 9.0, phi, 0.3 if discrepancy else 0.0),
            (slice(7, 12), [2], 4.0, 0.0, 0.0),
        ):
            kq = k[rows][:, bases]
            cov_w = np.diag(var[i, bases] + rel * variances[bases])
            cov = kq @ cov_w @ kq.T + _ar1_corr(kq.shape[0], ph) / lam
            want += stats.multivariate_normal(kq @ mean[i, bases], cov).logpdf(y[rows, i])
        assert got[i] == pytest.approx(want, rel=1e-10)


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
