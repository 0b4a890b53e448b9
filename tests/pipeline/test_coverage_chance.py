"""How much one window's coverage says: ``n_eff95`` / ``n_eff50`` and the honest range.

:func:`bayescal.metrics.coverage_n_eff` gives the number of independent samples the
coverage of an honest band is worth on a window whose errors are autocorrelated, and
:func:`bayescal.metrics.honest_range` the coverages an honest band shows there 95 % of
the time. The truths here are known: Gaussian AR(1) errors with an honest N(0, 1)
band, whose coverage on each replicate window is one draw of what the range promises.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from scipy.signal import lfilter
from scipy.special import owens_t
from scipy.stats import binom, multivariate_normal, norm, rankdata

from band_data import band_dataset
from bayescal.metrics import band_notes, coverage_n_eff, honest_range
from bayescal.pipeline.predict import metrics_table

REPLICATES = 300


def _ar1(rng: np.random.Generator, phi: float, n: int) -> np.ndarray:
    """Stationary Gaussian AR(1) with unit variance."""
    shocks = rng.normal(size=n + 300) * np.sqrt(1.0 - phi * phi)
    return lfilter([1.0], [1.0, -phi], shocks)[300:]


def _dense_n_eff(z: np.ndarray, positions: np.ndarray, level: float) -> float:
    """The definition, pair by pair (O(n²)): the reference of the FFT route."""
    n = z.size
    x = norm.ppf(rankdata(z) / (n + 1.0))
    var = np.mean(x * x)
    lag = positions[None, :] - positions[:, None]
    product = x[:, None] * x[None, :]
    rho, counts = [1.0], [n]
    for k in range(1, n // 2 + 1):
        at = lag == k
        if at.sum() == 0:
            continue
        rho.append(product[at].sum() / (at.sum() * var))
        counts.append(int(at.sum()))
    used = 0
    for m in range(len(rho) // 2):
        if rho[2 * m] + rho[2 * m + 1] <= 0.0:
            break
        used = 2 * m + 1
    c = norm.ppf(0.5 + 0.5 * level)
    total = n * level * (1 - level)
    for k in range(1, used + 1):
        a = np.sqrt((1 - rho[k]) / (1 + rho[k]))
        both = 1 - 4 * owens_t(c, a) - 4 * owens_t(c, 1 / a)
        total += 2 * counts[k] * max(both - level * level, 0.0)
    return float(np.clip(level * (1 - level) / (total / n**2), 1, n))


@pytest.mark.parametrize("rho", [-0.7, 0.0, 0.3, 0.83, 0.99])
def test_owens_t_square_is_the_bivariate_normal_probability(rho: float) -> None:
    c = norm.ppf(0.975)
    a = np.sqrt((1 - rho) / (1 + rho))
    ours = 1 - 4 * owens_t(c, a) - 4 * owens_t(c, 1 / a)
    cov = [[1.0, rho], [rho, 1.0]]
    genz = multivariate_normal(mean=[0, 0], cov=cov).cdf([c, c], lower_limit=[-c, -c])
    assert ours == pytest.approx(genz, abs=1e-5)  # Genz's integration tolerance


@pytest.mark.parametrize("gap", [False, True])
def test_the_fft_route_equals_the_pairwise_definition(gap: bool) -> None:
    rng = np.random.default_rng(11)
    z = _ar1(rng, 0.7, 240) * 2.5 + 0.3
    positions = np.arange(240)
    if gap:  # two periods with a hole of 37 samples between them
        positions = np.concatenate([np.arange(120), np.arange(157, 277)])
    for level in (0.95, 0.5):
        got = coverage_n_eff(z, positions, level=level)
        assert got == pytest.approx(_dense_n_eff(z, positions, level), rel=1e-10)


def test_independent_errors_are_worth_their_count() -> None:
    rng = np.random.default_rng(12)
    n_eff = [coverage_n_eff(rng.normal(size=500)) for _ in range(50)]
    assert np.median(n_eff) == pytest.approx(500, rel=0.03)
    assert honest_range(0.95, 500) == (binom.ppf(0.025, 500, 0.95) / 500, 0.968)


@pytest.mark.parametrize("level", [0.95, 0.5])
def test_the_honest_range_holds_an_honest_bands_coverage_at_its_rate(level: float) -> None:
    """Three weeks of half-hours with lag-1 correlation 0.8: the window is worth about
    a third of its samples; 95 % of honest windows fall inside the range."""
    rng = np.random.default_rng(13)
    c = norm.ppf(0.5 + 0.5 * level)
    covers, n_effs, inside = [], [], 0
    for _ in range(REPLICATES):
        e = _ar1(rng, 0.8, 336)
        cover = float(np.mean(np.abs(e) < c))
        n_eff = coverage_n_eff(e, level=level)
        low, high = honest_range(level, n_eff)
        covers.append(cover)
        n_effs.append(n_eff)
        inside += low <= cover <= high
    # the spread the formula predicts is the spread of the replicates (the replicates'
    # SD has a relative standard error of 1 / sqrt(2 * 300) = 4 %)
    predicted = np.sqrt(level * (1 - level) / np.median(n_effs))
    assert predicted == pytest.approx(np.std(covers), rel=0.15)
    assert 60 < np.median(n_effs) < 200  # far fewer than 336
    # binomial bounds on 300 replicates at 95 % (the range's binomial rounding can
    # only add to its share)
    assert binom.ppf(0.001, REPLICATES, 0.95) <= inside <= REPLICATES
    # counting the samples as independent would miss far more often
    naive = honest_range(level, 336)
    share_naive = np.mean([naive[0] <= x <= naive[1] for x in covers])
    assert share_naive < 0.8


def test_a_band_too_wide_falls_outside_the_range() -> None:
    rng = np.random.default_rng(14)
    outside = 0
    for _ in range(100):
        e = _ar1(rng, 0.8, 2000) / 1.5  # errors two thirds of what the band allows
        cover = float(np.mean(np.abs(e) < norm.ppf(0.975)))
        _, high = honest_range(0.95, coverage_n_eff(e))
        outside += cover > high
    assert outside >= 95


def _dataset(errors: np.ndarray, band_sd: float) -> xr.Dataset:
    """Half-hours; the last week (336) is the test window."""
    return band_dataset(errors, band_sd, freq="30min", test=336)


def test_metrics_carry_n_eff_and_the_notes_read_it() -> None:
    rng = np.random.default_rng(15)
    # an honest band; the test week's errors strongly autocorrelated
    errors = np.concatenate([rng.normal(size=3000), _ar1(rng, 0.97, 336)])
    table = metrics_table(_dataset(errors, band_sd=1.0))
    calibrated = table[table["model"] == "calibrated"].set_index("window")
    assert calibrated.loc["train", "n_eff95"] == pytest.approx(3000, rel=0.05)
    assert calibrated.loc["test", "n_eff95"] < 60
    assert table[table["model"] == "nominal"]["n_eff95"].isna().all()
    test = calibrated.loc["test"]
    low, high = honest_range(0.95, test["n_eff95"])
    notes = [n for n in band_notes(table) if "honest band covers" in n]
    # this seed's honest test week covers 0.994 (about 24 independent samples): far
    # from 0.95, and within what such a week gives an honest band
    assert abs(test["coverage95"] - 0.95) > 0.02
    assert low <= test["coverage95"] <= high
    assert any("y, calibrated, test: the 95 % band" in n and "cannot tell" in n for n in notes)
    # a band twice as wide on the long training window is named too wide
    narrow = np.concatenate([rng.normal(size=3000) / 2, errors[3000:]])
    notes = [n for n in band_notes(metrics_table(_dataset(narrow, 1.0))) if "honest band" in n]
    for band in ("95 %", "50 %"):
        start = f"y, calibrated, train: the {band} band"
        assert any(n.startswith(start) and "too wide" in n for n in notes)
