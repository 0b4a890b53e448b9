"""The study clock: alignment, gaps and periods (durations and time zones as a study
writes them are read by :mod:`bayescal.clock`).

Conventions
-----------
Internal clock
    UTC. Naive timestamps in data files are local times of the study's time
    zone and are converted to UTC as they are read.
Clock grid
    Instants ``t_i = origin + i * step``. The origin is ``[data].start`` when
    given; otherwise the grid is anchored at local midnight of the first day
    of the record, so that with a step dividing a day the instants fall on
    round local times (and daily periods start at local midnight).
Resampling (data finer than the step)
    The value at ``t_i`` is the mean of the finite samples in the *centred*
    window ``[t_i - step/2, t_i + step/2]``, a sample lying exactly on the
    boundary of two windows counting half in each (a trapezoidal mean, so
    30 min data on a 1 h clock give ``(x(t-30)/2 + x(t) + x(t+30)/2) / 2``).
    Simulators treat series as point values at ``t_i`` interpolated linearly
    in between, and a centred mean is the estimate of such a point value that
    introduces no time shift: it is exact for linear trends, whereas a window
    ``[t_i, t_i + step)`` would delay every series by half a step. A window
    whose finite samples weigh less than half of what it should hold is
    missing. The clock starts at the first instant whose window lies inside
    the record.
Data as fine as the step
    Timestamps must lie on the grid; a record offset from it (samples at :15
    and :45 with a 30 min step) is an error rather than a silent shift.
Data coarser than the step
    An error: values are never invented.
Gaps
    Runs of missing values (rows absent from the file or NaN cells) on the
    clock, per column. A gap no longer than ``max_gap_interpolate`` (its
    length is its number of missing samples times the step) and with valid
    values on both sides is filled by linear interpolation; longer gaps stay
    NaN and the pipeline drops the periods that touch them.
Periods
    Laid out by :func:`bayescal.periods.layout_periods`;
    :func:`periods_with_gaps` tells which periods touch a gap.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import tzinfo

import numpy as np
import pandas as pd

from bayescal.clock import format_duration
from bayescal.errors import DataError

MAX_LISTED = 5
"""How many offending items an error message lists."""


# --------------------------------------------------------------------------- index checks


def _listed(values: pd.Index | np.ndarray | list[object]) -> str:
    items = [str(v) for v in list(values)[:MAX_LISTED]]
    more = len(values) - len(items)
    return ", ".join(items) + (f" and {more} more" if more > 0 else "")


def localize(index: pd.DatetimeIndex, zone: tzinfo, source: str) -> pd.DatetimeIndex:
    """Convert timestamps to UTC; naive ones are local times of ``zone``.

    Raises
    ------
    DataError
        For local times that are ambiguous or do not exist (daylight-saving
        changes); the message names the first such time.
    """
    if index.tz is not None:
        return index.tz_convert("UTC")
    try:
        local = index.tz_localize(zone, ambiguous="raise", nonexistent="raise")
    except Exception as exc:  # pandas raises ValueError subclasses that moved between versions
        kind = "ambiguous" if "ambiguous" in type(exc).__name__.lower() + str(exc) else "invalid"
        raise DataError(
            f"local time {exc} is {kind} in time zone {zone} (a daylight-saving change)",
            hint="export the data in UTC or a fixed offset and set data.time_zone "
            "to it, e.g. 'UTC+01:00'",
            source=source,
        ) from None
    return local.tz_convert("UTC")


def check_index(index: pd.DatetimeIndex, source: str, lines: np.ndarray | None = None) -> None:
    """Check timestamps: no missing values, strictly increasing, no duplicates.

    Parameters
    ----------
    index
        Timestamps in file order.
    source
        File name, for messages.
    lines
        Line number in the file of each timestamp (optional, for messages).
    """

    def where(pos: np.ndarray) -> str:
        if lines is None:
            return "rows " + _listed([int(p) + 1 for p in pos])
        return "lines " + _listed([int(lines[p]) for p in pos])

    missing = np.flatnonzero(index.isna())
    if missing.size:
        raise DataError(f"missing or unreadable timestamps at {where(missing)}", source=source)
    if index.has_duplicates:
        dup = index[index.duplicated()].unique()
        raise DataError(
            f"duplicated timestamps {_listed(dup)}",
            hint="remove the repeated rows (or use UTC if they come from a clock change)",
            source=source,
        )
    if index.size > 1:
        back = np.flatnonzero(np.diff(index.asi8) < 0) + 1
        if back.size:
            shown = [f"{index[p]} after {index[p - 1]}" for p in back[:MAX_LISTED]]
            raise DataError(
                f"timestamps go backwards at {where(back)}: {'; '.join(shown)}",
                hint="sort the file by time",
                source=source,
            )


def infer_step(index: pd.DatetimeIndex) -> pd.Timedelta:
    """Typical sampling interval of a record: the median of its time differences."""
    if index.size < 2:
        raise DataError(f"a record needs at least two samples, got {index.size}")
    return pd.Timedelta(int(np.median(np.diff(index.as_unit("ns").asi8))), unit="ns")


# --------------------------------------------------------------------------- alignment


def _midnight_origin(first: pd.Timestamp, zone: tzinfo) -> pd.Timestamp:
    local = first.tz_convert(zone)
    midnight = pd.Timestamp(local.date()).tz_localize(
        zone, ambiguous=False, nonexistent="shift_forward"
    )
    return midnight.tz_convert("UTC")


def _to_utc(value: pd.Timestamp | None, zone: tzinfo) -> pd.Timestamp | None:
    if value is None:
        return None
    ts = pd.Timestamp(value)
    return ts.tz_convert("UTC") if ts.tz is not None else ts.tz_localize(zone).tz_convert("UTC")


def align(
    frame: pd.DataFrame,
    step: pd.Timedelta,
    *,
    zone: tzinfo,
    start: pd.Timestamp | None = None,
    end: pd.Timestamp | None = None,
    source: str = "data",
) -> pd.DataFrame:
    """Put a record on the regular study clock (see the module conventions).

    Parameters
    ----------
    frame
        Numeric columns indexed by increasing UTC timestamps.
    step
        Clock step.
    zone
        The study's time zone: anchors the default grid at local midnight and
        localises naive ``start``/``end``.
    start
        First instant of the clock (optional); it also fixes the grid.
    end
        End of the record, exclusive (optional): the last instant is before it.
    source
        File name, for messages.

    Returns
    -------
    pandas.DataFrame
        Same columns on ``origin + i * step``, NaN where data are missing.
    """
    index = pd.DatetimeIndex(frame.index).as_unit("ns")
    if index.tz is None:
        raise DataError("align needs a tz-aware (UTC) time index", source=source)
    data_step = infer_step(index)
    ns = step.value
    if data_step.value > ns * (1 + 1e-9):
        raise DataError(
            f"the data are sampled every {format_duration(data_step)}, coarser than the "
            f"study step {format_duration(step)}; values are never invented",
            hint=f"set data.step to {format_duration(data_step)} or a multiple of it",
            source=source,
        )
    t = index.asi8
    margin = (ns - data_step.value) // 2  # half a window beyond the samples' own half-step
    lo, hi = t[0] + margin, t[-1] - margin
    start_utc, end_utc = _to_utc(start, zone), _to_utc(end, zone)
    origin = start_utc if start_utc is not None else _midnight_origin(index[0], zone)
    if start_utc is not None and start_utc.value < lo:
        raise DataError(
            f"data.start {start_utc} is before the data cover it; the earliest start is "
            f"{pd.Timestamp(lo, tz='UTC')}",
            source=source,
        )
    first = origin.value + max(0, -(-(lo - origin.value) // ns)) * ns
    if end_utc is not None:
        if end_utc.value > hi + ns:
            raise DataError(
                f"data.end {end_utc} is after the end of the data "
                f"({pd.Timestamp(t[-1], tz='UTC')})",
                source=source,
            )
        hi = min(hi, end_utc.value - ns)
    if hi < first:
        raise DataError("no clock instant lies inside the (cropped) record", source=source)
    count = (hi - first) // ns + 1
    if data_step.value == ns:
        _check_on_grid(t[(t >= first) & (t <= hi)], first, ns, source)
    return _bin_means(frame, t, first, ns, int(count), ns / data_step.value)


def _check_on_grid(t: np.ndarray, first: int, ns: int, source: str) -> None:
    off = np.flatnonzero((t - first) % ns != 0)
    if off.size:
        bad = pd.DatetimeIndex(t[off], tz="UTC")
        raise DataError(
            f"timestamps {_listed(bad)} are not on the study clock "
            f"(instants {pd.Timestamp(first, tz='UTC')} + k × {format_duration(pd.Timedelta(ns))})",
            hint=f"set data.start = '{bad[0].isoformat()}' to start the clock on the data's "
            "own instants",
            source=source,
        )


def _bin_means(
    frame: pd.DataFrame, t: np.ndarray, first: int, ns: int, count: int, expected: float
) -> pd.DataFrame:
    """Centred-window means (edge samples split half and half between the two windows).

    Windows whose weight of finite samples is under half of ``expected`` are NaN.
    """
    pos = t - first + ns // 2
    k = pos // ns
    edge = pos % ns == 0  # on the boundary between windows k - 1 and k
    slots = np.concatenate((k, k[edge] - 1))
    weights = np.concatenate((np.where(edge, 0.5, 1.0), np.full(int(edge.sum()), 0.5)))
    inside = (slots >= 0) & (slots < count)
    out = {}
    for name in frame.columns:
        raw = np.asarray(frame[name], dtype=float)
        values = np.concatenate((raw, raw[edge]))[inside]
        ok = np.isfinite(values)
        slot, weight = slots[inside][ok], weights[inside][ok]
        n = np.bincount(slot, weights=weight, minlength=count)
        total = np.bincount(slot, weights=weight * values[ok], minlength=count)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = total / n
        mean[n < 0.5 * expected] = np.nan
        out[name] = mean
    clock = pd.DatetimeIndex(first + np.arange(count, dtype=np.int64) * ns, tz="UTC", name="time")
    return pd.DataFrame(out, index=clock, columns=frame.columns)


# --------------------------------------------------------------------------- gaps


@dataclass(frozen=True)
class Gap:
    """A run of missing samples on the study clock.

    Attributes
    ----------
    columns
        Columns (glossary names) missing over this run.
    first, last
        First and last missing instants (UTC).
    samples
        Number of missing samples.
    length
        ``samples * step``.
    interpolated
        Whether the run was filled by linear interpolation.
    """

    columns: tuple[str, ...]
    first: pd.Timestamp
    last: pd.Timestamp
    samples: int
    length: pd.Timedelta
    interpolated: bool

    def describe(self) -> str:
        """One line: ``2013-08-22 10:00 – 12:30 UTC (6 samples, 3h): temp_surf_in``."""
        state = "interpolated" if self.interpolated else "left missing"
        return (
            f"{self.first:%Y-%m-%d %H:%M} – {self.last:%Y-%m-%d %H:%M} UTC "
            f"({self.samples} samples, {format_duration(self.length)}, {state}): "
            + ", ".join(self.columns)
        )


def _runs(missing: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the True runs of a boolean array."""
    edges = np.diff(np.concatenate(([0], missing.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def fill_gaps(frame: pd.DataFrame, max_interpolate: pd.Timedelta) -> tuple[pd.DataFrame, list[Gap]]:
    """Find the gaps of each column, interpolate the short ones.

    Parameters
    ----------
    frame
        Columns on a regular UTC clock (output of :func:`align`).
    max_interpolate
        Longest gap filled by linear interpolation; gaps at the start or end
        of the record are never filled (nothing to interpolate from).

    Returns
    -------
    frame
        A copy with the short gaps filled.
    gaps
        Every gap, identical runs of several columns merged, in time order.
    """
    index = pd.DatetimeIndex(frame.index)
    step = index[1] - index[0] if index.size > 1 else pd.Timedelta(0)
    n = index.size
    filled: dict[str, np.ndarray] = {}
    found: dict[tuple[int, int, bool], list[str]] = {}
    for name in frame.columns:
        values = np.asarray(frame[name], dtype=float).copy()
        good = np.isfinite(values)
        for a, b in _runs(~good):
            fill = a > 0 and b < n and (b - a) * step <= max_interpolate
            if fill:
                values[a:b] = np.interp(np.arange(a, b), [a - 1, b], values[[a - 1, b]])
            found.setdefault((int(a), int(b), bool(fill)), []).append(str(name))
        filled[name] = values
    gaps = [
        Gap(tuple(cols), index[a], index[b - 1], b - a, (b - a) * step, fill)
        for (a, b, fill), cols in sorted(found.items())
    ]
    return pd.DataFrame(filled, index=index, columns=frame.columns), gaps


# --------------------------------------------------------------------------- periods


def periods_with_gaps(missing: np.ndarray, starts: np.ndarray, length: int) -> np.ndarray:
    """Which periods contain at least one missing sample.

    Parameters
    ----------
    missing
        Missing-sample mask on the clock, shape ``(n_samples,)``.
    starts
        First sample of each period, shape ``(m,)``.
    length
        Samples per period.

    Returns
    -------
    numpy.ndarray
        Boolean, shape ``(m,)``: True for a period that must be dropped.
    """
    missing = np.asarray(missing, dtype=bool)
    cumulative = np.concatenate(([0], np.cumsum(missing)))
    starts = np.asarray(starts, dtype=np.int64)
    return np.asarray(cumulative[starts + length] - cumulative[starts] > 0)
