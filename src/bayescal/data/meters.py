"""Interval values on the study clock: meters (totals) and interval means.

A column whose ``[data.columns.<name>] aggregate`` is ``"sum"`` or ``"mean"``
holds *interval* values: the value stamped ``t`` is the total (a meter's
energy) or the mean over the interval ``(t - step, t]`` that ends at ``t``,
the convention of EnergyPlus's reports and of most meter exports. Data on the
study clock are taken as they are (:func:`bayescal.data.align.align` checks
that they lie on it); finer data are brought to it here, by adding up (sum)
or averaging (mean) the readings whose own intervals lie in each clock
interval, where :func:`~bayescal.data.align.align` would take centred means
of point values.

* A reading stamped ``tau`` covers ``(tau - d, tau]``, ``d`` the file's
  sampling interval (the median spacing of its timestamps); the clock step
  must be a multiple of ``d`` and the readings must nest in the clock's
  intervals (readings at :15 and :45 do not nest in hours ending on the hour).
* A total needs every reading of its interval (a partial sum would be wrong
  by the missing share); a mean needs at least half of them. Otherwise the
  clock value is missing (NaN), like any gap.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from bayescal.clock import format_duration
from bayescal.data.align import infer_step
from bayescal.errors import DataError

__all__ = ["INTERVAL_AGGREGATES", "interval_values", "replace_interval_columns"]

INTERVAL_AGGREGATES = ("mean", "sum")
"""Values of ``aggregate`` that mean "over the interval ending at the timestamp"."""


def interval_values(
    series: pd.Series, clock: pd.DatetimeIndex, step: pd.Timedelta, how: str, *, source: str = ""
) -> np.ndarray:
    """Totals or means of finer interval readings over the clock's intervals.

    Parameters
    ----------
    series
        Readings indexed by increasing UTC timestamps, each the value of the
        interval ending at its timestamp (internal units: J for a meter).
    clock
        The study clock (UTC instants, regular).
    step
        Clock step; the intervals are ``(t - step, t]``.
    how
        ``"sum"`` or ``"mean"``.
    source
        File name, for messages.

    Returns
    -------
    numpy.ndarray
        One value per clock instant, NaN where the readings do not cover the
        interval (all of them for a sum, half for a mean).

    Raises
    ------
    DataError
        If the readings are coarser than the step, the step is not a multiple
        of their interval, or they do not nest in the clock's intervals.
    """
    if how not in INTERVAL_AGGREGATES:
        raise ValueError(f"how must be 'sum' or 'mean', got {how!r}")
    index = pd.DatetimeIndex(series.index).as_unit("ns")
    d, ns = infer_step(index).value, pd.Timedelta(step).value
    name = series.name
    if ns % d:
        raise DataError(
            f"{name}: readings every {format_duration(pd.Timedelta(d))} do not add up to the "
            f"study step {format_duration(pd.Timedelta(ns))}",
            hint="set data.step to a multiple of the readings' interval",
            source=source,
        )
    t = index.asi8
    ends = pd.DatetimeIndex(clock).as_unit("ns").asi8
    if ends.size and np.any((t - ends[0]) % d):
        bad = pd.Timestamp(t[np.flatnonzero((t - ends[0]) % d)[0]], tz="UTC")
        raise DataError(
            f"{name}: the reading stamped {bad} does not nest in the clock's intervals "
            f"(intervals of {format_duration(pd.Timedelta(ns))} ending at "
            f"{pd.Timestamp(ends[0], tz='UTC')} + k × step)",
            hint="stamp each reading at the end of its interval, or set data.start on the "
            "end of a reading's interval",
            source=source,
        )
    per = ns // d
    slot = -((ends[0] - t) // ns)  # the clock interval (t_k - step, t_k] holding each reading
    values = np.asarray(series, dtype=float)
    inside = (slot >= 0) & (slot < ends.size) & np.isfinite(values)
    count = np.bincount(slot[inside], minlength=ends.size)
    total = np.bincount(slot[inside], weights=values[inside], minlength=ends.size)
    with np.errstate(invalid="ignore", divide="ignore"):
        if how == "sum":
            return np.where(count == per, total, np.nan)
        return np.where(2 * count >= per, total / count, np.nan)


def replace_interval_columns(
    aligned: pd.DataFrame,
    raw: pd.DataFrame,
    aggregates: Mapping[str, str],
    step: pd.Timedelta,
    *,
    source: str = "",
) -> pd.DataFrame:
    """``aligned`` with the interval columns recomputed from finer readings.

    Parameters
    ----------
    aligned
        The record on the study clock (:func:`~bayescal.data.align.align`).
    raw
        The same columns as read (converted, UTC index).
    aggregates
        Column -> ``"point"``, ``"mean"`` or ``"sum"``.
    step
        Clock step.
    source
        File name, for messages.
    """
    names = [n for n, how in aggregates.items() if how in INTERVAL_AGGREGATES and n in raw]
    if not names or infer_step(pd.DatetimeIndex(raw.index)) >= pd.Timedelta(step):
        return aligned  # readings on the clock: align took them as they are
    out = aligned.copy()
    for name in names:
        readings = raw[name].dropna()
        if readings.size < 2:
            continue
        out[name] = interval_values(
            raw[name], pd.DatetimeIndex(aligned.index), step, aggregates[name], source=source
        )
    return out
