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
Clocks that jitter
    A logger whose intervals wander around the step (30 min ± 4 min) is
    detected and refused with the offer of ``data.resample = "linear"``:
    each clock instant then takes the linear interpolation of the two
    samples around it, and an instant whose two samples lie more than 1.5
    steps apart (a missing row) is missing.
Messages
    A problem with rows of the file names the line and the time as the file
    writes it (:class:`RowLabels`); times on the clock are shown as local
    times of the study's zone.
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
from datetime import timezone, tzinfo

import numpy as np
import pandas as pd

from bayescal.clock import format_duration, local_to_utc, offset_text
from bayescal.errors import DataError

MAX_LISTED = 5
"""How many offending items an error message lists."""

JITTER_SPAN = 1.5
"""With ``resample = "linear"``, samples further apart than this many steps leave the
instants between them missing."""


@dataclass(frozen=True, eq=False)
class RowLabels:
    """Where each row of a record comes from, for messages.

    Attributes
    ----------
    lines
        Line (or row) number of each row in the file, shape ``(n,)``.
    texts
        The row's time as the file writes it (``"2013-10-27 02:30"``), shape ``(n,)``.
    """

    lines: np.ndarray
    texts: np.ndarray

    def __deepcopy__(self, memo: dict[int, object]) -> RowLabels:
        """Itself: pandas deep-copies a frame's ``attrs`` at every step, and these arrays
        are never changed."""
        return self

    def row(self, pos: int) -> str:
        """``"line 42 ('2013-01-16 04:00')"``."""
        return f"line {int(self.lines[pos])} ({str(self.texts[pos])!r})"

    def rows(self, positions: np.ndarray | list[int]) -> str:
        """Several rows, at most :data:`MAX_LISTED` of them."""
        shown = [self.row(int(p)) for p in list(positions)[:MAX_LISTED]]
        more = len(positions) - len(shown)
        return ", ".join(shown) + (f" and {more} more" if more > 0 else "")


def local_text(instant: pd.Timestamp | int, zone: tzinfo) -> str:
    """A UTC instant as a local time of ``zone``: ``"2013-01-16 04:00 (UTC-06:00)"``."""
    utc = pd.Timestamp(instant)
    local = (utc if utc.tz is not None else utc.tz_localize("UTC")).tz_convert(zone)
    seconds = f":{local.second:02d}" if local.second else ""
    return f"{local:%Y-%m-%d %H:%M}{seconds} ({zone_name(zone)})"


def zone_name(zone: tzinfo) -> str:
    """``"Europe/Brussels"``, ``"UTC-06:00"``, ``"UTC"``."""
    if isinstance(zone, timezone):
        offset = zone.utcoffset(None)
        return "UTC" if not offset else offset_text(offset)
    return str(zone)


# --------------------------------------------------------------------------- index checks


def _listed(values: pd.Index | np.ndarray | list[object]) -> str:
    items = [str(v) for v in list(values)[:MAX_LISTED]]
    more = len(values) - len(items)
    return ", ".join(items) + (f" and {more} more" if more > 0 else "")


def localize(
    index: pd.DatetimeIndex, zone: tzinfo, source: str, labels: RowLabels | None = None
) -> pd.DatetimeIndex:
    """Convert timestamps to UTC; naive ones are local times of ``zone``.

    The autumn hour that a daylight-saving zone repeats is resolved from the
    order of the rows where the file holds it twice (02:00, 02:30, 02:00,
    02:30); a local time that stays ambiguous or does not exist is an error.

    Parameters
    ----------
    index
        Timestamps in file order.
    zone
        Zone of naive timestamps.
    source
        File name, for messages.
    labels
        Lines and time texts of the rows (optional, for messages).

    Raises
    ------
    DataError
        For local times that are ambiguous or do not exist (daylight-saving
        changes); the message names the line and the time as the file writes it.
    """
    if index.tz is not None:
        return index.tz_convert("UTC")
    for ambiguous in ("raise", "infer"):
        try:
            local = index.tz_localize(zone, ambiguous=ambiguous, nonexistent="raise")
        except Exception:  # pandas raises ValueError subclasses that moved between versions
            continue
        return local.tz_convert("UTC")
    raise _dst_error(index, zone, source, labels)


def _dst_error(
    index: pd.DatetimeIndex, zone: tzinfo, source: str, labels: RowLabels | None
) -> DataError:
    """The error of the first local time that a daylight-saving change makes ambiguous
    or skips."""
    flagged = index.tz_localize(zone, ambiguous="NaT", nonexistent="NaT")
    bad = np.flatnonzero(pd.isna(flagged) & ~pd.isna(index))
    pos = int(bad[0]) if bad.size else 0
    where = labels.row(pos) if labels is not None else f"row {pos + 1} ({index[pos]})"
    time = index[pos]
    day = f"{time:%Y-%m-%d}"
    try:
        standard = pd.Timestamp(time + pd.Timedelta(days=1)).tz_localize(zone).utcoffset()
        before = pd.Timestamp(time - pd.Timedelta(days=1)).tz_localize(zone).utcoffset()
    except Exception:  # pragma: no cover - a day away from a change is unambiguous
        standard = before = None
    repeated = pd.isna(
        index[pos : pos + 1].tz_localize(zone, ambiguous="NaT", nonexistent="shift_forward")[0]
    )
    if repeated:
        fixed = f", '{offset_text(standard)}'" if standard is not None else ""
        return DataError(
            f"{where}: this local time occurs twice in time zone {zone_name(zone)}, whose "
            f"clocks go back an hour on {day}, and the file holds it once, so which of the "
            "two is meant cannot be told",
            hint="export the data in UTC or with UTC offsets ('2013-10-27T02:30+01:00'), "
            f"or in local standard time all year and set data.time_zone to its offset{fixed}",
            source=source,
        )
    fixed = f", '{offset_text(before)}'" if before is not None else ""
    return DataError(
        f"{where}: this local time does not exist in time zone {zone_name(zone)}, whose "
        f"clocks skip an hour on {day}; the logger probably keeps standard time all year",
        hint=f"set data.time_zone to the logger's fixed offset{fixed}",
        source=source,
    )


def check_index(
    index: pd.DatetimeIndex,
    source: str,
    lines: np.ndarray | None = None,
    texts: np.ndarray | None = None,
) -> None:
    """Check timestamps: no missing values, strictly increasing, no duplicates.

    Parameters
    ----------
    index
        Timestamps in file order.
    source
        File name, for messages.
    lines
        Line number in the file of each timestamp (optional, for messages).
    texts
        Each timestamp as the file writes it (optional, with ``lines``): messages
        then show it instead of the UTC time.
    """
    labels = RowLabels(lines, texts) if lines is not None and texts is not None else None

    def where(pos: np.ndarray) -> str:
        if lines is None:
            return "rows " + _listed([int(p) + 1 for p in pos])
        return "lines " + _listed([int(lines[p]) for p in pos])

    missing = np.flatnonzero(index.isna())
    if missing.size:
        raise DataError(f"missing or unreadable timestamps at {where(missing)}", source=source)
    if index.has_duplicates:
        hint = "remove the repeated rows (or use UTC if they come from a clock change)"
        if labels is None:
            dup = index[index.duplicated()].unique()
            raise DataError(f"duplicated timestamps {_listed(dup)}", hint=hint, source=source)
        _, first, inverse = np.unique(index.asi8, return_index=True, return_inverse=True)
        repeats = np.flatnonzero(index.duplicated())
        shown = [
            f"{labels.row(int(p))} repeats line {int(lines[first[inverse[p]]])}"  # type: ignore[index]
            for p in repeats[:MAX_LISTED]
        ]
        more = f" and {repeats.size - len(shown)} more" if repeats.size > len(shown) else ""
        raise DataError(
            f"duplicated timestamps: {'; '.join(shown)}{more}", hint=hint, source=source
        )
    if index.size > 1:
        back = np.flatnonzero(np.diff(index.asi8) < 0) + 1
        if back.size:
            if labels is None:
                shown = [f"{index[p]} after {index[p - 1]}" for p in back[:MAX_LISTED]]
                text = f"{where(back)}: {'; '.join(shown)}"
            else:
                shown = [f"{labels.row(p)} after {labels.row(p - 1)}" for p in back[:MAX_LISTED]]
                text = "; ".join(shown)
            raise DataError(
                f"timestamps go backwards at {text}", hint="sort the file by time", source=source
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


def align(
    frame: pd.DataFrame,
    step: pd.Timedelta,
    *,
    zone: tzinfo,
    start: pd.Timestamp | None = None,
    end: pd.Timestamp | None = None,
    source: str = "data",
    labels: RowLabels | None = None,
    resample: str = "none",
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
        localises naive ``start``/``end``; messages show local times of it.
    start
        First instant of the clock (optional); it also fixes the grid.
    end
        End of the record, exclusive (optional): the last instant is before it.
    source
        File name, for messages.
    labels
        Lines and time texts of the rows of ``frame`` (optional, for messages).
    resample
        ``"none"``: centred means of finer data, timestamps on the clock for
        data as fine as the step; ``"linear"``: linear interpolation between
        the samples around each instant (for clocks that jitter).

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
    t = index.asi8
    linear = resample == "linear"
    if not linear:
        _check_jitter(t, ns, source, labels)
    if data_step.value > ns * (1 + 1e-9) and not (linear and data_step.value <= 1.25 * ns):
        raise DataError(
            f"the data are sampled every {format_duration(data_step)}, coarser than the "
            f"study step {format_duration(step)}; values are never invented",
            hint=f"set data.step to {format_duration(data_step)} or a multiple of it",
            source=source,
        )
    margin = 0 if linear else (ns - data_step.value) // 2  # half a window beyond the samples
    lo, hi = t[0] + margin, t[-1] - margin
    start_utc = None if start is None else local_to_utc(start, zone, "data.start")
    end_utc = None if end is None else local_to_utc(end, zone, "data.end")
    origin = start_utc if start_utc is not None else _midnight_origin(index[0], zone)
    if start_utc is not None and start_utc.value < lo:
        first_row = f"; {labels.row(0)} is the first row" if labels is not None else ""
        raise DataError(
            f"data.start {local_text(start_utc, zone)} is before the data cover it; the "
            f"earliest start is {local_text(lo, zone)}{first_row}",
            source=source,
        )
    first = origin.value + max(0, -(-(lo - origin.value) // ns)) * ns
    if end_utc is not None:
        if end_utc.value > hi + ns:
            last_row = labels.row(len(t) - 1) if labels is not None else local_text(t[-1], zone)
            raise DataError(
                f"data.end {local_text(end_utc, zone)} is after the end of the data ({last_row})",
                source=source,
            )
        hi = min(hi, end_utc.value - ns)
    if hi < first:
        raise DataError("no clock instant lies inside the (cropped) record", source=source)
    count = int((hi - first) // ns + 1)
    if linear:
        return _interpolate(frame, t, first, ns, count)
    if data_step.value == ns:
        inside = np.flatnonzero((t >= first) & (t <= hi))
        _check_on_grid(t, inside, first, ns, source, zone, labels)
    return _bin_means(frame, t, first, ns, count, ns / data_step.value)


def _check_jitter(t: np.ndarray, ns: int, source: str, labels: RowLabels | None) -> None:
    """Refuse, with the offer of ``data.resample``, a clock that wanders around the step.

    Intervals about as long as the step (between half a step and 1.5 steps, longer
    ones being gaps) of which at least a tenth miss the step by more than a second,
    while the median interval lies within a quarter of a step of it: a logger whose
    clock jitters. A record shifted off the grid or with one misplaced row is not
    that (its intervals are the step), nor data finer than the step.
    """
    if t.size < 3:
        return
    dt = np.diff(t)
    near = dt[(dt > ns // 2) & (dt <= 1.5 * ns)]
    if near.size < 2 or abs(float(np.median(dt)) - ns) > 0.25 * ns:
        return
    off = np.abs(near - ns) > 1_000_000_000
    if off.mean() < 0.1:
        return
    short, long = pd.Timedelta(int(near.min())), pd.Timedelta(int(near.max()))
    worst = int(np.argmax(np.abs(dt - ns))) + 1
    example = f"; e.g. {labels.row(worst)} after {labels.row(worst - 1)}" if labels else ""
    raise DataError(
        f"the timestamps jitter around the study step {format_duration(pd.Timedelta(ns))}: "
        f"{int(off.sum())} of {near.size} intervals between rows differ from it, from "
        f"{format_duration(short)} to {format_duration(long)}{example}",
        hint="set data.resample = 'linear' to interpolate the samples onto the study clock",
        source=source,
    )


def _interpolate(
    frame: pd.DataFrame, t: np.ndarray, first: int, ns: int, count: int
) -> pd.DataFrame:
    """Each clock instant from the two finite samples around it, linearly; missing where
    they lie more than :data:`JITTER_SPAN` steps apart (or an instant is beyond them)."""
    clock_ns = first + np.arange(count, dtype=np.int64) * ns
    out = {}
    for name in frame.columns:
        values = np.asarray(frame[name], dtype=float)
        good = np.isfinite(values)
        times, kept = t[good], values[good]
        result = np.full(count, np.nan)
        if times.size >= 1:
            right = np.clip(np.searchsorted(times, clock_ns, side="left"), 0, times.size - 1)
            exact = times[right] == clock_ns
            left = np.clip(right - 1, 0, times.size - 1)
            span = times[right] - times[left]
            ok = exact | ((clock_ns > times[left]) & (clock_ns < times[right]))
            ok &= exact | (span <= JITTER_SPAN * ns)
            origin = times[0]
            result[ok] = np.interp(
                (clock_ns[ok] - origin).astype(float), (times - origin).astype(float), kept
            )
        out[name] = result
    clock = pd.DatetimeIndex(clock_ns, tz="UTC", name="time")
    return pd.DataFrame(out, index=clock, columns=frame.columns)


def _check_on_grid(
    t: np.ndarray,
    inside: np.ndarray,
    first: int,
    ns: int,
    source: str,
    zone: tzinfo,
    labels: RowLabels | None,
) -> None:
    """Refuse rows between the clock's instants (data sampled at the study step).

    Where most rows share one offset from the clock, the whole record is shifted:
    the message offers ``data.start`` on the data's own instants. Where a few rows
    are off (a stray ``05:45`` in half-hourly data), it names them and offers to
    remove or correct them, or to interpolate (``data.resample``); moving the
    clock would put every other row off it.
    """
    off = inside[(t[inside] - first) % ns != 0]
    if not off.size:
        return
    step = format_duration(pd.Timedelta(ns))
    if labels is not None:
        rows = labels.rows(off)
    else:
        rows = _listed([local_text(v, zone) for v in t[off]])
    one = off.size == 1
    clock = f"on the study clock (instants {local_text(first, zone)} + k × {step})"
    if one:
        text = f"the timestamp {'on ' if labels is not None else ''}{rows} is not {clock}"
    else:
        text = f"the timestamps {'on ' if labels is not None else ''}{rows} are not {clock}"
    phases, counts = np.unique((t[off] - first) % ns, return_counts=True)
    if counts.max() * 2 > inside.size:  # most rows share one offset: the record is shifted
        phase = phases[np.argmax(counts)]
        start = pd.Timestamp(t[off[(t[off] - first) % ns == phase][0]], tz="UTC").tz_convert(zone)
        hint = (
            f"set data.start = '{start:%Y-%m-%dT%H:%M:%S}' to start the clock on the data's "
            "own instants"
        )
    else:
        which = "that row" if one else f"those {off.size} rows"
        hint = (
            f"remove or correct {which} in the file (the other rows are on the clock), or "
            "set data.resample = 'linear' to interpolate the samples onto the study clock"
        )
    raise DataError(text, hint=hint, source=source)


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
    bridged
        Whether a boundary condition was bridged over it for the simulator (and the
        periods it touches dropped): see :func:`bayescal.data.load_measured`.
    where
        Where it lies in the file (``"after line 601 ('2013-01-24 11:00')"``), if known.
    """

    columns: tuple[str, ...]
    first: pd.Timestamp
    last: pd.Timestamp
    samples: int
    length: pd.Timedelta
    interpolated: bool
    bridged: bool = False
    where: str = ""

    def describe(self, zone: tzinfo | None = None) -> str:
        """One line: ``2013-08-22 10:00 – 12:30 UTC (6 samples, 3h, left missing): temp_surf_in``.

        Parameters
        ----------
        zone
            Show local times of this zone instead of UTC.
        """
        if self.interpolated:
            state = "interpolated"
        elif self.bridged:
            state = "bridged for the simulator, its periods dropped"
        else:
            state = "left missing"
        first, last = self.first, self.last
        label = "UTC"
        if zone is not None:
            first, last = first.tz_convert(zone), last.tz_convert(zone)
            label = zone_name(zone)
        where = f"; {self.where}" if self.where else ""
        return (
            f"{first:%Y-%m-%d %H:%M} – {last:%Y-%m-%d %H:%M} {label} "
            f"({self.samples} samples, {format_duration(self.length)}, {state}{where}): "
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
