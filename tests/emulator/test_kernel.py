"""The eq. 8 covariance: parameterisation, separability, positive definiteness."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.emulator.kernel import (
    LogDensity,
    SeparableKernel,
    beta_to_rho,
    correlation,
    rho_to_beta,
)


def _eq8_by_loops(z1: np.ndarray, z2: np.ndarray, rho: np.ndarray, tau: float) -> np.ndarray:
    """Eq. 8 written literally: tau^-1 prod_l rho_l^(4 (z_il - z_kl)^2)."""
    out = np.empty((z1.shape[0], z2.shape[0]))
    for i in range(z1.shape[0]):
        for k in range(z2.shape[0]):
            out[i, k] = np.prod(rho ** (4.0 * (z1[i] - z2[k]) ** 2)) / tau
    return out


def test_rho_beta_round_trip() -> None:
    rho = np.array([1e-6, 0.2, 0.5, 1.0])
    # Round trip through log and exp: a few ulps.
    np.testing.assert_allclose(beta_to_rho(rho_to_beta(rho)), rho, rtol=1e-14)
    assert rho_to_beta(1.0) == 0.0  # rho = 1 switches the input off exactly


@pytest.mark.parametrize("bad", [0.0, -0.1, 1.5, np.nan])
def test_rho_out_of_range_rejected(bad: float) -> None:
    with pytest.raises(ValueError, match=r"rho must lie in \(0, 1\]"):
        rho_to_beta([0.5, bad])


def test_full_matches_eq8_written_literally() -> None:
    rng = np.random.default_rng(0)
    rho = rng.uniform(0.05, 1.0, 5)
    kern = SeparableKernel(rho, 2.5, n_theta=2)
    z1, z2 = rng.random((7, 5)), rng.random((4, 5))
    # exp(sum) versus prod(power): rounding only.
    np.testing.assert_allclose(kern.full(z1, z2), _eq8_by_loops(z1, z2, rho, 2.5), rtol=1e-13)


def test_grid_covariance_is_kronecker_of_theta_and_x_factors() -> None:
    rng = np.random.default_rng(1)
    n_runs, n_per, t, s = 4, 3, 2, 3
    theta, x = rng.random((n_runs, t)), rng.random((n_per, s))
    kern = SeparableKernel(rng.uniform(0.05, 1.0, t + s), 0.7, n_theta=t)
    z = np.hstack([np.repeat(theta, n_per, axis=0), np.tile(x, (n_runs, 1))])  # run-major
    expected = np.kron(kern.theta_cov(theta), kern.x_corr(x))
    # Same exponentials grouped differently: rounding only.
    np.testing.assert_allclose(kern.full(z), expected, rtol=1e-13)
    # The variance is carried by the theta factor, S_x has a unit diagonal.
    np.testing.assert_allclose(np.diag(kern.x_corr(x)), 1.0)
    np.testing.assert_allclose(np.diag(kern.theta_cov(theta)), 1.0 / 0.7)


def test_covariance_symmetric_positive_semidefinite() -> None:
    rng = np.random.default_rng(2)
    kern = SeparableKernel(rng.uniform(0.01, 0.99, 4), 1.3, n_theta=1)
    cov = kern.full(rng.random((30, 4)))
    np.testing.assert_array_equal(cov, cov.T)
    # Eigenvalues of a PSD matrix computed in double precision: >= -eps * n * ||cov||.
    assert np.linalg.eigvalsh(cov).min() > -1e-12 * np.abs(cov).sum(axis=1).max()


def test_rho_one_switches_an_input_off() -> None:
    rng = np.random.default_rng(3)
    a, b = rng.random((5, 3)), rng.random((6, 3))
    beta = np.array([0.7, 0.0, 2.0])
    moved = b.copy()
    moved[:, 1] = rng.random(6)
    np.testing.assert_array_equal(correlation(a, b, beta), correlation(a, moved, beta))


def test_kernel_validates_its_hyperparameters() -> None:
    with pytest.raises(ValueError, match="tau must be finite and > 0"):
        SeparableKernel(np.array([0.5]), 0.0, n_theta=1)
    with pytest.raises(ValueError, match="n_theta"):
        SeparableKernel(np.array([0.5, 0.5]), 1.0, n_theta=3)
    with pytest.raises(ValueError, match="beta has 2 entries"):
        correlation(np.zeros((2, 3)), np.zeros((2, 3)), [1.0, 1.0])


def test_from_beta_matches_from_rho() -> None:
    beta = np.array([0.0, 0.3, 5.0])
    kern = SeparableKernel.from_beta(beta, 2.0, n_theta=1)
    # exp(-beta/4) then -4 log: a few ulps.
    np.testing.assert_allclose(kern.beta, beta, atol=1e-14)
    np.testing.assert_allclose(kern.beta_x, beta[1:], atol=1e-14)


def test_log_density_pieces_add() -> None:
    one = LogDensity.from_pieces(2.0, 3.0, 4)
    two = LogDensity.from_pieces(-1.0, 0.5, 2)
    both = one + two
    assert both.size == 6
    # The normalising constant is additive in N: exact up to rounding.
    assert both.logpdf == pytest.approx(LogDensity.from_pieces(1.0, 3.5, 6).logpdf, rel=1e-15)
