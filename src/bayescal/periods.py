"""Cutting a record into warm-up, training periods and a test window.

The record of ``n_total`` samples on the study clock is laid out as::

    | warm-up (+ leftover) | period 1 | period 2 | ... | period m* | test window |

The test window is the last ``test`` samples. All periods lie on one grid
anchored at the end of the record, so every period starts at the same time of
day (or phase of whatever cycle the period length follows): the test window is
covered by the last ``ceil(test / period)`` periods, the first of which may
reach back into the training window (its overlap is predicted but neither
trained on nor scored); the training periods are the whole periods of the grid
before it, after the warm-up. Samples before the first training period join
the warm-up (simulated, never used). Periods that contain missing
measurements are dropped and listed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayescal.errors import DataError


@dataclass(frozen=True)
class PeriodLayout:
    """Where each period lies in the record (sample indices on the study clock).

    Attributes
    ----------
    n_total
        Samples in the record.
    period
        Samples per period ``n``.
    warmup
        Samples requested as warm-up (the actual first period may start later).
    test
        Samples in the test window (the last ``test`` samples).
    train_starts
        First sample of each kept training period, shape ``(m*,)``.
    dropped_starts
        First sample of each training period dropped because of missing data.
    test_starts
        First sample of each period covering the test window.
    """

    n_total: int
    period: int
    warmup: int
    test: int
    train_starts: np.ndarray
    dropped_starts: np.ndarray
    test_starts: np.ndarray

    @property
    def m_star(self) -> int:
        """Number of training periods kept."""
        return int(self.train_starts.size)

    @property
    def test_begin(self) -> int:
        """First sample of the test window."""
        return self.n_total - self.test

    def cut(self, series: np.ndarray, which: str = "train") -> np.ndarray:
        """Cut series into periods.

        Parameters
        ----------
        series
            Shape ``(..., n_total)``: one series or a stack of them (runs first).
        which
            ``"train"`` or ``"test"``.

        Returns
        -------
        numpy.ndarray
            Shape ``(..., period, n_periods)``: column ``i`` is period ``i``.
        """
        series = np.asarray(series)
        if series.shape[-1] != self.n_total:
            raise DataError(
                f"series has {series.shape[-1]} samples, the period layout expects {self.n_total}"
            )
        starts = self.train_starts if which == "train" else self.test_starts
        idx = starts[None, :] + np.arange(self.period)[:, None]  # (period, n_periods)
        return series[..., idx]


def layout_periods(
    n_total: int,
    period: int,
    warmup: int,
    test: int,
    missing: np.ndarray | None = None,
) -> PeriodLayout:
    """Lay out warm-up, training periods and test window.

    Parameters
    ----------
    n_total
        Samples in the record.
    period
        Samples per period (``n`` of the paper), > 1.
    warmup
        Samples at the start that are simulated but not used, >= 0.
    test
        Samples held out at the end, >= 0.
    missing
        Optional boolean mask, shape ``(n_total,)``: samples whose measured
        output is missing. Training periods containing any are dropped.

    Returns
    -------
    PeriodLayout

    Raises
    ------
    DataError
        If the record is too short for the warm-up, one period and the test
        window, or if every period has missing data.
    """
    if period < 2:
        raise DataError(f"a period must hold at least 2 samples, got {period}")
    if warmup < 0 or test < 0:
        raise DataError(f"warm-up and test window must be >= 0 samples, got {warmup} and {test}")
    n_test_periods = -(-test // period) if test > 0 else 0
    needed = warmup + period * (1 + n_test_periods)
    if n_total < needed:
        raise DataError(
            f"the record has {n_total} samples but warm-up ({warmup}) + one period ({period}) "
            f"+ the {n_test_periods} whole period(s) covering the test window ({test}) "
            f"need {needed}",
            hint="use a longer record, a shorter warm-up or period, or a smaller test window",
        )
    # One grid of periods anchored at the end of the record, so that the periods
    # covering the test window have the same phase (time of day) as the
    # training periods; training periods end before the first of them.
    end_train = n_total - period * n_test_periods
    n_periods = (end_train - warmup) // period
    first = end_train - n_periods * period
    starts = first + period * np.arange(n_periods)
    if missing is not None:
        missing = np.asarray(missing, dtype=bool)
        if missing.shape != (n_total,):
            raise DataError(f"missing mask has shape {missing.shape}, expected ({n_total},)")
        bad = np.array([missing[s : s + period].any() for s in starts], dtype=bool)
    else:
        bad = np.zeros(n_periods, dtype=bool)
    if bad.all():
        raise DataError(
            f"all {n_periods} training periods contain missing measurements",
            hint="allow interpolation of short gaps (data.max_gap_interpolate) or fix the data",
        )
    test_starts = n_total - period * np.arange(n_test_periods, 0, -1)
    return PeriodLayout(
        n_total=n_total,
        period=period,
        warmup=warmup,
        test=test,
        train_starts=starts[~bad],
        dropped_starts=starts[bad],
        test_starts=test_starts,
    )
