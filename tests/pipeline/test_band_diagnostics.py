"""Why a band misses its rate: the band's spread over the errors and the errors' tails.

``metrics.csv`` gains ``band_scale`` (the outer band's spread over the RMSE) and
``excess_kurtosis``; :func:`bayescal.metrics.band_notes` turns them into sentences.
The series here are made with known error distributions, so the right answers are
known: a band matched to Gaussian errors has a spread ratio of 1 and no note; one
twice as wide, 2 and a note; errors that are mostly small with a few large ones
(a contaminated normal, excess kurtosis ~33) make the matched Gaussian band's middle
half hold ~0.80 of them, and the note says they are heavy-tailed.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from scipy.stats import kurtosis, norm

from band_data import band_dataset
from bayescal.metrics import band_notes, fit_metrics
from bayescal.pipeline.predict import metrics_table

N = 20_000


def _dataset(errors: np.ndarray, band_sd: float, level: float = 0.95) -> xr.Dataset:
    """A training window of ``N`` samples: truth 0, measured = errors, Gaussian bands."""
    return band_dataset(errors, band_sd, level=level)


def _calibrated(ds: xr.Dataset) -> pd.Series:
    table = metrics_table(ds)
    return table[table["model"] == "calibrated"].iloc[0]


def test_excess_kurtosis_matches_scipy() -> None:
    rng = np.random.default_rng(1)
    e = rng.standard_t(6, size=500)
    got = fit_metrics(e, np.zeros_like(e)).excess_kurtosis
    assert got == pytest.approx(kurtosis(e), rel=1e-12)
    assert np.isnan(fit_metrics(np.ones(3), np.zeros(3)).excess_kurtosis)


def test_a_band_matched_to_gaussian_errors_has_spread_one_and_no_note() -> None:
    rng = np.random.default_rng(2)
    row = _calibrated(_dataset(rng.normal(0.0, 0.3, N), band_sd=0.3))
    # the RMSE of N Gaussian errors has a relative SE of 1/sqrt(2N) = 0.5 %
    assert row["band_scale"] == pytest.approx(1.0, abs=0.025)
    assert abs(row["excess_kurtosis"]) < 5 * np.sqrt(24 / N)
    assert abs(row["coverage95"] - 0.95) < 4 * np.sqrt(0.95 * 0.05 / N)
    assert band_notes(metrics_table(_dataset(rng.normal(0.0, 0.3, N), band_sd=0.3))) == []


@pytest.mark.parametrize(("factor", "word"), [(2.0, "wider"), (0.5, "narrower")])
def test_a_band_too_wide_or_too_narrow_is_named(factor: float, word: str) -> None:
    rng = np.random.default_rng(3)
    ds = _dataset(rng.normal(0.0, 1.0, N), band_sd=factor)
    row = _calibrated(ds)
    assert row["band_scale"] == pytest.approx(factor, rel=0.025)
    every = band_notes(metrics_table(ds))
    notes = [n for n in every if "honest band" not in n]
    assert len(notes) == 1
    assert f"{row['band_scale']:.2f} times the errors' RMS, {word}" in notes[0]
    assert notes[0].startswith("y, calibrated, train:")
    # both coverages lie far outside what 20 000 independent samples give an honest band
    chance = [n for n in every if "honest band" in n]
    side = "too wide" if factor > 1 else "too narrow"
    assert len(chance) == 2
    assert all(side in n for n in chance)


def test_heavy_tailed_errors_explain_a_middle_band_that_holds_too_much() -> None:
    # 95 % of the errors N(0, 0.5²), 5 % N(0, 4²): variance 1.0375, excess kurtosis
    # 3 (0.95 * 0.5^4 + 0.05 * 4^4) / 1.0375^2 - 3 = 32.9
    rng = np.random.default_rng(4)
    wide = rng.random(N) < 0.05
    e = np.where(wide, rng.normal(0.0, 4.0, N), rng.normal(0.0, 0.5, N))
    ds = _dataset(e, band_sd=np.sqrt(1.0375))
    row = _calibrated(ds)
    # the band matches the errors' variance ...
    assert row["band_scale"] == pytest.approx(1.0, abs=0.1)
    assert row["excess_kurtosis"] > 15.0
    # ... and its middle half holds 0.95 P(|z| < 1.373) + 0.05 P(|z| < 0.172) = 0.795
    expected = 0.95 * (2 * norm.cdf(0.674490 * np.sqrt(1.0375) / 0.5) - 1) + 0.05 * (
        2 * norm.cdf(0.674490 * np.sqrt(1.0375) / 4.0) - 1
    )
    assert abs(row["coverage50"] - expected) < 4 * np.sqrt(expected * (1 - expected) / N)
    every = band_notes(metrics_table(ds))
    notes = [n for n in every if "honest band" not in n]
    assert len(notes) == 1
    assert "heavy-tailed" in notes[0]
    assert any("the 50 % band covers" in n and "too wide" in n for n in every)
    assert f"holds {row['coverage50']:.3f} of them" in notes[0]


def test_older_tables_without_the_columns_give_no_notes() -> None:
    rng = np.random.default_rng(5)
    table = metrics_table(_dataset(rng.normal(size=100), band_sd=1.0))
    assert band_notes(table.drop(columns=["band_scale"])) == []
    assert np.isnan(table[table["model"] == "nominal"]["band_scale"]).all()
