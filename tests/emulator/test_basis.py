"""Standardisation, output PCA (GPMSA scaling), eq. 7, input PCA and normalisers."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.emulator.basis import (
    Normaliser,
    input_pca,
    pca_basis,
    stack_outputs,
    standardise,
)
from bayescal.errors import ConfigError, DataError


def _simulated(rng: np.random.Generator, n: int = 40, m: int = 60) -> np.ndarray:
    """Smooth periods with a few modes plus noise, in W/m²-like magnitudes."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    amps = rng.normal(size=(3, m)) * np.array([[5.0], [2.0], [0.5]])
    modes = np.hstack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * t), t])
    return 10.0 + modes @ amps + 0.05 * rng.normal(size=(n, m))


@pytest.fixture
def y_std() -> np.ndarray:
    y = _simulated(np.random.default_rng(0))
    return standardise(y).apply(y)


def test_standardise_gives_zero_mean_unit_sd_and_inverts() -> None:
    y = _simulated(np.random.default_rng(1))
    tr = standardise(y)
    ys = tr.apply(y)
    # Mean and SD of 60 values: rounding only.
    np.testing.assert_allclose(ys.mean(axis=1), 0.0, atol=1e-13)
    np.testing.assert_allclose(ys.std(axis=1), 1.0, rtol=1e-13)
    np.testing.assert_allclose(tr.invert(ys), y, rtol=1e-13)


def test_constant_sample_is_named_in_the_error() -> None:
    y = _simulated(np.random.default_rng(2))
    y[3, :] = 21.5
    with pytest.raises(DataError, match=r"sample\(s\) \[3\] .* same in all 60 simulated periods"):
        standardise(y)


def test_nan_in_output_is_rejected() -> None:
    y = _simulated(np.random.default_rng(3))
    y[5, 7] = np.nan
    with pytest.raises(DataError, match=r"NaN or infinite value\(s\), first at \[5, 7\]"):
        standardise(y)


def test_weights_have_unit_variance_with_gpmsa_scaling(y_std: np.ndarray) -> None:
    basis = pca_basis(y_std, components=3)
    w = basis.weights(y_std)
    assert w.shape == (60, 3)
    # Identities of the SVD evaluated in floating point: rounding only.
    np.testing.assert_allclose(w.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(w.var(axis=0), 1.0, rtol=1e-12)
    np.testing.assert_allclose(w.T @ w / 60, np.eye(3), atol=1e-12)


def test_variance_explained_monotone_and_minimal(y_std: np.ndarray) -> None:
    basis = pca_basis(y_std, variance=0.9)
    explained = basis.explained
    assert np.all(np.diff(explained) <= 0.0)
    assert explained.sum() == pytest.approx(1.0, rel=1e-12)  # fractions of one total
    cumulative = np.cumsum(explained)
    assert cumulative[basis.p - 1] >= 0.9
    assert basis.p == 1 or cumulative[basis.p - 2] < 0.9


def test_reconstruction_error_equals_discarded_variance(y_std: np.ndarray) -> None:
    for p in (1, 2, 3, 5):
        basis = pca_basis(y_std, components=p)
        resid = y_std - basis.reconstruct(basis.weights(y_std))
        discarded = 1.0 - basis.explained_kept.sum()
        # Eckart-Young: exact up to rounding of sums over 2400 entries.
        assert np.sum(resid**2) / np.sum(y_std**2) == pytest.approx(discarded, rel=1e-9, abs=1e-14)


def test_weights_are_the_least_squares_solution(y_std: np.ndarray) -> None:
    basis = pca_basis(y_std, components=2)
    y_obs = y_std[:, :7] + 0.3
    expected, *_ = np.linalg.lstsq(basis.k, y_obs, rcond=None)
    # Normal equations versus QR-based lstsq on a well-conditioned K: rounding.
    np.testing.assert_allclose(basis.weights(y_obs), expected.T, rtol=1e-10, atol=1e-12)


def test_eq7_rate_is_the_residual_sum_of_squares(y_std: np.ndarray) -> None:
    basis = pca_basis(y_std, components=2)
    q, _ = np.linalg.qr(basis.k)
    projector_resid = y_std - q @ (q.T @ y_std)  # (I - K (K^T K)^-1 K^T) y, via QR
    shape, rate = basis.lambda_posterior(y_std)
    n, m = y_std.shape
    assert shape == 5.0 + 0.5 * m * (n - 2)
    # Two ways of forming the same projection: rounding only.
    assert rate == pytest.approx(5.0 + 0.5 * np.sum(projector_resid**2), rel=1e-10)
    shape2, rate2 = basis.lambda_posterior(y_std[:, :10], shape=2.0, rate=1.0)
    assert shape2 == 2.0 + 0.5 * 10 * (n - 2)
    assert rate2 == pytest.approx(1.0 + 0.5 * np.sum(projector_resid[:, :10] ** 2), rel=1e-10)


def test_basis_sign_is_reproducible(y_std: np.ndarray) -> None:
    k1 = pca_basis(y_std, components=2).k
    k2 = pca_basis(y_std[:, ::-1].copy(), components=2).k  # same data, periods reordered
    # Same subspace and sign convention; SVDs of permuted columns differ by rounding.
    np.testing.assert_allclose(k1, k2, rtol=1e-8, atol=1e-10)
    idx = np.argmax(np.abs(k1), axis=0)
    assert np.all(k1[idx, [0, 1]] > 0)


def test_degenerate_inputs_raise() -> None:
    with pytest.raises(DataError, match="no variance"):
        pca_basis(np.zeros((5, 8)))
    with pytest.raises(DataError, match="not centred"):
        pca_basis(np.full((5, 8), 3.0))
    y = _simulated(np.random.default_rng(4))
    with pytest.raises(DataError, match="same in all"):
        standardise(np.ones_like(y))
    ys = standardise(y).apply(y)
    with pytest.raises(ConfigError, match=r"variance fraction must lie in \(0, 1\]"):
        pca_basis(ys, variance=0.0)
    with pytest.raises(ConfigError, match="asked for 100 components"):
        pca_basis(ys, components=100)


def test_stack_outputs() -> None:
    a, b = np.ones((3, 5)), np.zeros((2, 5))
    stacked = stack_outputs([a, b])
    assert stacked.shape == (5, 5)
    np.testing.assert_array_equal(np.split(stacked, [3])[1], b)
    with pytest.raises(DataError, match=r"different numbers of periods \[5, 4\]"):
        stack_outputs([a, np.zeros((2, 4))])


def test_normaliser_from_bounds() -> None:
    norm = Normaliser.from_bounds([0.02, 500.0], [0.05, 1200.0])
    vals = np.array([[0.02, 1200.0], [0.035, 850.0]])
    np.testing.assert_allclose(norm.apply(vals), [[0.0, 1.0], [0.5, 0.5]], atol=1e-14)
    np.testing.assert_allclose(norm.invert(norm.apply(vals)), vals, rtol=1e-14)
    with pytest.raises(ConfigError, match="upper > lower"):
        Normaliser.from_bounds([1.0], [1.0])


def _bc_periods(rng: np.random.Generator, m: int, n: int = 48) -> dict[str, np.ndarray]:
    """Outdoor temperature: a daily mean times a flat profile plus an amplitude
    times a sine; solar: an amplitude times a fixed day shape (zero at night);
    heating: the same every period."""
    hours = np.arange(n) / 2.0
    sine = np.sin(2 * np.pi * (hours - 9.0) / 24.0)
    day = np.clip(np.sin(np.pi * (hours - 6.0) / 12.0), 0.0, None)
    mean_t, amp_t, amp_s = rng.uniform(-5, 10, m), rng.uniform(2, 6, m), rng.uniform(50, 600, m)
    return {
        "temp_air": mean_t[:, None] + amp_t[:, None] * sine,
        "ghi": amp_s[:, None] * day,
        "heating_power": np.full((m, n), 500.0),
    }


def test_input_pca_recovers_the_period_structure() -> None:
    rng = np.random.default_rng(5)
    periods = _bc_periods(rng, m=20)
    result = input_pca(periods, variance=0.999)
    # temp_air has exactly two modes, ghi one, heating none (constant).
    assert result.labels == ["temp_air:pc1", "temp_air:pc2", "ghi:pc1"]
    assert result.x.shape == (20, 3)
    # Min/max normalisation over the training periods: exact up to rounding.
    np.testing.assert_allclose(result.x.min(axis=0), 0.0, atol=1e-14)
    np.testing.assert_allclose(result.x.max(axis=0), 1.0, rtol=1e-14)
    # A rank-one series: its weight is an affine function of the amplitude.
    amp = periods["ghi"][:, 24]
    corr = np.corrcoef(result.x[:, 2], amp)[0, 1]
    assert abs(corr) == pytest.approx(1.0, abs=1e-12)  # exactly linear, rounding only
    # The transform reproduces the training x.
    np.testing.assert_allclose(result.transform(periods), result.x, atol=1e-13)


def test_input_pca_transforms_new_periods_the_same_way() -> None:
    rng = np.random.default_rng(6)
    train = _bc_periods(rng, m=15)
    result = input_pca({"ghi": train["ghi"]})
    amp_train = train["ghi"][:, 24]
    lo, hi = amp_train.min(), amp_train.max()
    new_amp = np.array([lo, hi, 2 * hi - lo])
    new = {"ghi": new_amp[:, None] * (train["ghi"][0] / amp_train[0])}
    x_new = result.transform(new)[:, 0]
    # The scaling is affine in the amplitude, with either sign of the direction.
    expected = (new_amp - lo) / (hi - lo)
    if x_new[1] < x_new[0]:
        expected = 1.0 - expected
    np.testing.assert_allclose(x_new, expected, atol=1e-10)  # rounding of the projections
    assert x_new.max() > 1.5  # conditions outside training fall outside [0, 1]


def test_input_pca_errors() -> None:
    with pytest.raises(DataError, match="none of the series"):
        input_pca({"heating_power": np.full((6, 10), 200.0)})
    with pytest.raises(DataError, match=r"different numbers of periods \[5, 6\]"):
        input_pca({"a": np.random.default_rng(0).random((5, 4)), "b": np.ones((6, 4))})
    result = input_pca({"a": np.random.default_rng(1).random((5, 4))})
    with pytest.raises(DataError, match="expected 4"):
        result.transform({"a": np.ones((2, 3))})
    with pytest.raises(DataError, match=r"series \['a'\] missing"):
        result.transform({"b": np.ones((2, 4))})
