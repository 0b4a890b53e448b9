"""The held-out sensors' scores of ``bayescal compare`` against their dense definitions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from bayescal.periods import layout_periods
from bayescal.pipeline.heldscore import (
    HeldOutScore,
    held_out_table,
    held_out_warnings,
    score_held_out,
)

PERIOD, DAYS = 24, 5


@pytest.fixture
def case() -> tuple:
    rng = np.random.default_rng(4)
    n = PERIOD * (DAYS + 2)  # one warm-up day, one test day
    layout = layout_periods(n, PERIOD, PERIOD, PERIOD)
    truth = np.sin(np.arange(n) / 4.0)
    y = truth + rng.normal(0.0, 0.3, n)
    y[PERIOD + 3] = np.nan  # a gap in the first training period
    runs = truth[None] + rng.normal(0.0, 0.2, (7, 1)) + rng.normal(0.0, 0.05, (7, n))
    return layout, y, runs


def test_the_score_is_the_mixture_density_of_each_period(case: tuple) -> None:
    layout, y, runs = case
    sd = 0.25
    got = score_held_out(layout, y, runs, sd)
    assert got.pointwise.shape == (DAYS,)
    assert got.draws == 7
    for i, start in enumerate(layout.train_starts):
        idx = [t for t in range(start, start + PERIOD) if np.isfinite(y[t])]
        dens = [
            math.prod(stats.norm.pdf(y[t], runs[s, t], sd) for t in idx) for s in range(7)
        ]  # the dense product, no logs
        assert got.pointwise[i] == pytest.approx(math.log(np.mean(dens)), rel=1e-10, abs=1e-10)
        pit = [np.mean([stats.norm.cdf(y[t], runs[s, t], sd) for s in range(7)]) for t in idx]
        assert got.inside95[i] == np.mean([0.025 <= u <= 0.975 for u in pit])
        assert got.inside50[i] == np.mean([0.25 <= u <= 0.75 for u in pit])
    train = np.concatenate([np.arange(s, s + PERIOD) for s in layout.train_starts])
    ok = train[np.isfinite(y[train])]
    assert got.rmse == pytest.approx(np.sqrt(np.mean((y[ok] - runs[:, ok].mean(0)) ** 2)))
    # the test window is not read: changing it changes nothing
    y2 = y.copy()
    y2[layout.test_begin :] += 10.0
    assert np.array_equal(score_held_out(layout, y2, runs, sd).pointwise, got.pointwise)


def test_one_run_is_a_single_gaussian(case: tuple) -> None:
    layout, y, runs = case
    got = score_held_out(layout, y, runs[0], 0.3)  # the catalogue's nominal run: 1-D
    start = layout.train_starts[1]
    want = stats.norm.logpdf(y[start : start + PERIOD], runs[0, start : start + PERIOD], 0.3)
    assert got.draws == 1
    assert got.pointwise[1] == pytest.approx(want.sum(), rel=1e-12)


def _score(shift: float, case: tuple) -> HeldOutScore:
    layout, y, runs = case
    return score_held_out(layout, y, runs + shift, 0.3)


def test_the_table_ranks_within_each_sensor_and_the_catalogue_warning(case: tuple) -> None:
    good, off = _score(0.0, case), _score(0.4, case)
    scored = [
        ("off", "calibrated", True, {"T": off}),
        ("good", "calibrated", False, {"T": good}),
        ("catalogue", "catalogue", False, {"T": _score(0.5, case)}),
    ]
    table = held_out_table(scored)
    assert list(table["variant"]) == ["good", "off", "catalogue"]
    assert list(table["rank"]) == [1, 2, 3]
    assert table["lpd_diff"].iloc[0] == 0.0
    assert (table["lpd_diff"].iloc[1:] > 0).all()
    assert table.loc[table["variant"] == "off", "diagnostics"].item() == "failed"
    # the catalogue well behind the best calibrated variant: no warning
    assert held_out_warnings(scored) == []
    # ... but ahead of it: said loudly, naming the sensor
    scored[2] = ("catalogue", "catalogue", False, {"T": _score(-0.02, case)})
    warned = held_out_warnings(scored)
    assert len(warned) == 2, warned
    assert warned[0].startswith("on the held-out sensor T (never calibrated on), the catalogue")
    # ... and the variant whose mean lies further off than the catalogue's, by its RMSE
    assert warned[1].startswith("on the held-out sensor T (never calibrated on), the calibrated")
    assert "RMSE off " in warned[1]
    assert "good" not in warned[1]
    assert all("the parameters absorb model error" in w for w in warned)


def test_a_wide_posterior_can_win_the_density_and_lose_the_rmse(case: tuple) -> None:
    # draws spread widely around a biased mean cover the bias with their spread; the
    # catalogue's single run is closer on average: the density ranks the calibration
    # first, the RMSE rule still warns
    layout, y, runs = case
    rng = np.random.default_rng(9)
    centre = runs.mean(axis=0)
    wide = centre[None] + 0.35 + rng.normal(0.0, 0.5, (40, 1))
    sd = 0.1
    cal = score_held_out(layout, y, wide, sd)
    cat = score_held_out(layout, y, centre + 0.2, sd)
    assert cal.lpd > cat.lpd
    assert cal.rmse > 1.05 * cat.rmse
    warned = held_out_warnings(
        [("wide", "calibrated", False, {"T": cal}), ("catalogue", "catalogue", False, {"T": cat})]
    )
    assert len(warned) == 1
    assert "the calibrated prediction is further off than the catalogue values'" in warned[0]
