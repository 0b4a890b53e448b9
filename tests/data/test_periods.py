"""Period layout: warm-up, whole training periods ending at the test window, test cover."""

import numpy as np
import pandas as pd
import pytest

from bayescal.config.study import PeriodsSection
from bayescal.data.measured import layout_for
from bayescal.errors import DataError
from bayescal.periods import layout_periods


def test_paper_wall_layout() -> None:
    # The paper's wall: 1500 half-hourly values, last 300 test, daily periods of 48.
    lay = layout_periods(1500, 48, warmup=0, test=300)
    # 300 test samples need 7 periods of 48, ending at the end of the record.
    assert lay.test_starts.size == 7
    assert lay.test_starts[-1] + 48 == 1500
    assert lay.test_starts[0] <= lay.test_begin == 1200
    # Training periods lie on the same grid (same time of day) and end where the
    # first test period starts: 1500 - 7 * 48 = 1164 = 24 * 48 + 12.
    assert lay.m_star == 24
    assert lay.train_starts[-1] + 48 == lay.test_starts[0] == 1164
    assert np.all((lay.train_starts - lay.test_starts[0]) % 48 == 0)


def test_leftover_samples_join_the_warmup() -> None:
    lay = layout_periods(1000, 48, warmup=100, test=200)
    # 5 test periods end at 1000 (start 760); 660 samples after the warm-up before
    # them hold 13 whole periods (624); the 36 left over join the warm-up.
    assert lay.m_star == 13
    assert lay.train_starts[0] == 100 + 36
    assert lay.train_starts[-1] + 48 == 760 == lay.test_starts[0]


def test_test_window_in_whole_periods_keeps_every_training_sample() -> None:
    lay = layout_periods(1000, 50, warmup=100, test=200)
    assert lay.test_starts[0] == lay.test_begin == 800
    assert lay.train_starts[0] == 100
    assert lay.m_star == 14


def test_cut_shapes_and_values() -> None:
    lay = layout_periods(200, 10, warmup=20, test=30)
    series = np.arange(200.0)
    cut = lay.cut(series)
    assert cut.shape == (10, lay.m_star)
    np.testing.assert_array_equal(
        cut[:, 0], np.arange(lay.train_starts[0], lay.train_starts[0] + 10)
    )
    stacked = lay.cut(np.stack([series, -series]))
    assert stacked.shape == (2, 10, lay.m_star)
    np.testing.assert_array_equal(stacked[1], -cut)
    test_cut = lay.cut(series, "test")
    assert test_cut[-1, -1] == 199


def test_periods_with_missing_samples_are_dropped() -> None:
    missing = np.zeros(200, dtype=bool)
    missing[75] = True
    lay = layout_periods(200, 10, warmup=20, test=30, missing=missing)
    assert 70 in lay.dropped_starts
    assert 70 not in lay.train_starts
    assert lay.m_star == 14


def test_too_short_record_is_a_clear_error() -> None:
    with pytest.raises(DataError, match=r"record has 50 samples but .* need 106"):
        layout_periods(50, 48, warmup=10, test=4)


def test_all_periods_missing_is_an_error() -> None:
    with pytest.raises(DataError, match="all 3 training periods contain missing"):
        layout_periods(30, 10, warmup=0, test=0, missing=np.ones(30, dtype=bool))


def test_a_study_needs_two_training_periods() -> None:
    # A day of warm-up, 3 daily periods, no test window; gaps in two of them leave one.
    periods = PeriodsSection(length="1D", warmup="1D", test_samples=0)
    step = pd.Timedelta("30min")
    assert layout_for(4 * 48, step, periods).m_star == 3
    missing = np.zeros(4 * 48, dtype=bool)
    missing[[50, 100]] = True
    with pytest.raises(DataError) as info:
        layout_for(4 * 48, step, periods, missing)
    text = info.value.one_line()
    assert "[periods] leaves 1 training period (2 more dropped: missing data)" in text
    assert "needs at least 2" in text
    assert "data.max_gap_interpolate" in text
    missing[100] = False
    assert layout_for(4 * 48, step, periods, missing).m_star == 2
