"""A study's measured data: read, rename, convert, align, report gaps.

:func:`load_measured` turns ``[data]`` of a validated study into
:class:`MeasuredData`: the boundary conditions as a
:class:`~bayescal.simulators.base.Forcing` on the study clock, the measured
outputs to calibrate on, the clock, the list of gaps and the windows excluded
(``[[data.exclude]]``). Columns listed in
``[outputs].calibrate`` are outputs, those in ``[outputs].held_out`` held-out
outputs; every other mapped column is a boundary condition.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, timedelta, tzinfo
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from bayescal.clock import format_duration, local_to_utc
from bayescal.data.align import Gap, RowLabels, align, fill_gaps
from bayescal.data.meters import replace_interval_columns
from bayescal.data.readers import (
    epw_field,
    read_csv,
    read_epw,
    read_modelica_table,
    read_parquet,
)
from bayescal.errors import DataError
from bayescal.glossary import glossary_quantity
from bayescal.periods import PeriodLayout, layout_periods
from bayescal.simulators.base import Forcing
from bayescal.units import to_internal

if TYPE_CHECKING:
    from bayescal.config import ColumnSpec, DataSection, PeriodsSection, Study


@dataclass(frozen=True)
class Excluded:
    """One ``[[data.exclude]]`` window as applied to the file.

    Attributes
    ----------
    start, end
        The window, local time of the data (end exclusive).
    columns
        Glossary names of the columns whose values were removed.
    values
        Finite values of the file set missing.
    reason
        The study's reason, if it gave one.
    """

    start: pd.Timestamp
    end: pd.Timestamp
    columns: tuple[str, ...]
    values: int
    reason: str = ""

    def describe(self) -> str:
        """``2013-09-06 05:55 to 06:05 local: 2 values of heat_flux_in (sun patch)``."""
        same_day = self.start.date() == self.end.date()
        end = self.end.strftime("%H:%M" if same_day else "%Y-%m-%d %H:%M")
        why = f" ({self.reason})" if self.reason else ""
        return (
            f"{self.start:%Y-%m-%d %H:%M} to {end} local: {self.values} value(s) of "
            f"{', '.join(self.columns)}{why}"
        )


@dataclass(frozen=True)
class MeasuredData:
    """Measured series of a study on its clock, in internal units.

    Attributes
    ----------
    forcing
        Boundary conditions (glossary names), finite everywhere.
    outputs
        Measured outputs to calibrate on, glossary name -> shape ``(n,)``,
        NaN where missing.
    times
        Clock instants, UTC ``datetime64[s]``, shape ``(n,)``.
    step
        Clock step. [s]
    gaps
        Every gap found, interpolated or left missing, in time order.
    layout
        Warm-up, training periods and test window.
    source
        The data file.
    held_out
        Measured outputs that are predicted but never calibrated on
        (``[outputs] held_out``), NaN where missing.
    zone
        The zone of the file's local times (messages show times in it).
    excluded
        The ``[[data.exclude]]`` windows, with the values each removed.
    """

    forcing: Forcing
    outputs: Mapping[str, np.ndarray]
    times: np.ndarray
    step: float
    gaps: tuple[Gap, ...]
    layout: PeriodLayout
    source: Path
    zone: tzinfo = UTC
    held_out: Mapping[str, np.ndarray] = field(default_factory=dict)
    excluded: tuple[Excluded, ...] = ()

    @property
    def n(self) -> int:
        """Number of samples on the clock."""
        return int(self.times.size)

    def missing(self) -> np.ndarray:
        """Samples where any calibrated output is missing, shape ``(n,)``."""
        return _missing(self.outputs, self.n)


def _missing(outputs: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    mask = np.zeros(n, dtype=bool)
    for values in outputs.values():
        mask |= ~np.isfinite(values)
    return mask


def _read(data: DataSection, sources: list[str | int]) -> tuple[pd.DataFrame, tzinfo]:
    """The mapped source columns, and the zone of local times (the EPW file's own);
    ``attrs["rows"]`` keeps the lines and time texts of the rows."""
    zone = data.zone
    if data.format == "csv":
        frame = read_csv(
            data.file,
            str(data.time_column),
            time_format=data.time_format,
            time_zone=zone,
            delimiter=data.delimiter,
            decimal=data.decimal,
            columns=[str(s) for s in sources],
        )
    elif data.format == "parquet":
        frame = read_parquet(
            data.file,
            str(data.time_column),
            time_format=data.time_format,
            time_zone=zone,
            columns=[str(s) for s in sources],
        )
    elif data.format == "epw":
        weather = read_epw(data.file)
        zone = weather.attrs["time_zone"]
        frame = weather[[epw_field(s) for s in sources]].set_axis(sources, axis=1)
        frame.attrs["rows"] = weather.attrs.get("rows")
    elif data.epoch is None:  # pragma: no cover - the config requires it
        raise DataError("data.epoch is required for Modelica tables")
    else:
        columns = [int(s) for s in sources]
        frame = read_modelica_table(
            data.file, data.epoch, time_zone=zone, table=data.table, columns=columns
        )
    return frame, zone


_PLAUSIBLE = {
    # Internal units. Far outside any building measurement, so that a value beyond
    # is a wrong unit or scale (K declared for °C data, kW/m² for W/m²), not weather.
    "temperature": (-100.0, 150.0),  # [°C] Earth's record low is -89 °C
    "heat_flux": (-5000.0, 5000.0),  # [W/m²] the solar constant is 1361 W/m²
    "speed": (-120.0, 120.0),  # [m/s] the strongest gust measured is 113 m/s
    "fraction_percent": (-10.0, 110.0),  # [%] relative humidity, with sensor overshoot
    "pressure": (3.0e4, 1.2e5),  # [Pa] atmospheric pressure, Everest to sea-level records
}


def _check_plausible(name: str, spec: ColumnSpec, values: np.ndarray, source: str) -> None:
    """A converted column far outside the physical range of its quantity is an error."""
    quantity = glossary_quantity(name)
    bounds = _PLAUSIBLE.get(quantity.dimension) if quantity is not None else None
    finite = values[np.isfinite(values)]
    if quantity is None or bounds is None or not finite.size:
        return
    lo, hi = bounds
    worst = float(finite[np.argmax(np.maximum(lo - finite, finite - hi))])
    if lo <= worst <= hi:
        return
    unit, dimension = quantity.unit, quantity.dimension.replace("_", " ")
    scale = f" and scale {spec.scale:g}" if spec.scale != 1.0 else ""
    raise DataError(
        f"data.columns.{name}: values reach {worst:.6g} {unit} once converted from "
        f"{spec.unit!r}{scale}, implausible for a {dimension} (expected within "
        f"[{lo:g}, {hi:g}] {unit})",
        hint=f"check the unit and scale of data.columns.{name} (file column {spec.source!r})",
        source=source,
    )


def _exclude(
    frame: pd.DataFrame, data: DataSection, zone: tzinfo
) -> tuple[pd.DataFrame, tuple[Excluded, ...]]:
    """``frame`` (UTC index, glossary columns) with the ``[[data.exclude]]`` windows
    set missing, and what each window removed."""
    if not data.exclude:
        return frame, ()
    frame = frame.copy()
    index = pd.DatetimeIndex(frame.index)
    done = []
    for i, window in enumerate(data.exclude):
        start, end = pd.Timestamp(window.start), pd.Timestamp(window.end)
        first = local_to_utc(start, zone, f"data.exclude[{i}].start")
        rows = (index >= first) & (index < local_to_utc(end, zone, f"data.exclude[{i}].end"))
        if not rows.any():
            raise DataError(
                f"data.exclude[{i}]: no row of the file lies in [{window.start}, {window.end})",
                hint=f"the file runs from {index[0].tz_convert(zone):%Y-%m-%d %H:%M} to "
                f"{index[-1].tz_convert(zone):%Y-%m-%d %H:%M} local time; check the window's "
                "date and data.time_zone",
                source=str(data.file),
            )
        columns = list(window.columns) or list(frame.columns)
        values = int(np.isfinite(frame.loc[rows, columns].to_numpy(dtype=float)).sum())
        frame.loc[rows, columns] = np.nan
        done.append(Excluded(start, end, tuple(columns), values, window.reason))
    return frame, tuple(done)


def _convert(raw: pd.DataFrame, data: DataSection) -> pd.DataFrame:
    """Rename source columns to glossary names and convert to internal units."""
    out = {}
    for name, spec in data.columns.items():
        values = np.asarray(raw[spec.source], dtype=float) * spec.scale
        try:
            quantity = glossary_quantity(name)
            dimension = None if quantity is None else quantity.dimension
            out[name] = to_internal(values, spec.unit, dimension=dimension) * spec.sign
        except DataError as exc:  # pragma: no cover - the config checks units first
            raise DataError(exc.message, hint=exc.hint, source=f"data.columns.{name}") from None
        _check_plausible(name, spec, out[name], str(data.file))
    return pd.DataFrame(out, index=raw.index)


def _check_outputs(outputs: Mapping[str, np.ndarray], data: DataSection, source: str) -> None:
    """A measured output with no value, or the same value throughout, is an error."""
    for name, values in outputs.items():
        key = f"data.columns.{name}"
        finite = values[np.isfinite(values)]
        if not finite.size:
            raise DataError(
                f"measured output {name} ({key}, file column {data.columns[name].source!r}) "
                "has no measured value on the study clock",
                hint="check the column, and data.start / data.end",
                source=source,
            )
        if np.ptp(finite) <= 1e-9 * np.max(np.abs(finite)):
            quantity = glossary_quantity(name)
            unit = quantity.unit if quantity is not None else ""
            raise DataError(
                f"measured output {name} ({key}) is constant ({finite[0]:g} {unit}) over the "
                "whole record: there is nothing to calibrate on",
                hint=f"a stuck sensor or the wrong column? check {key}.source",
                source=source,
            )


def _samples(value: timedelta | int, step: pd.Timedelta) -> int:
    if isinstance(value, int):
        return value
    return int(pd.Timedelta(value) // step)


def _span(samples: int, step: pd.Timedelta) -> str:
    """``samples * step`` as a short duration, even beyond pandas' range (292 years)."""
    try:
        return format_duration(samples * step)
    except (OverflowError, ValueError):  # pandas' OutOfBoundsTimedelta is a ValueError
        return f"{samples * step.total_seconds() / 86400 / 365.25:.3g} years"


#: Training periods a calibration needs: the emulator's variable conditions are the
#: boundary conditions' principal components between periods (one period has none).
MIN_TRAINING_PERIODS = 2


def layout_for(
    n_samples: int,
    step: pd.Timedelta,
    periods: PeriodsSection,
    missing: np.ndarray | None = None,
    skip: int = 0,
) -> PeriodLayout:
    """Lay out a study's periods on a record of ``n_samples`` samples.

    Parameters
    ----------
    n_samples
        Samples on the clock.
    step
        Clock step.
    periods
        The study's ``[periods]``.
    missing
        Samples whose measured output is missing (their periods are dropped).
    skip
        Samples before ``[periods] train_from``: no training period starts before
        it (a warm-up at least this long), and a ``test_fraction`` counts the
        record from one warm-up before it.

    Raises
    ------
    DataError
        If the record is shorter than warm-up + one period + test window, or fewer
        than :data:`MIN_TRAINING_PERIODS` training periods are left.
    """
    length, warmup = _samples(periods.length, step), _samples(periods.warmup, step)
    before = max(skip - warmup, 0)  # the record before train_from, less one warm-up
    if periods.test_samples is not None:
        test = periods.test_samples
    else:
        test = round(float(periods.test_fraction or 0.0) * (n_samples - before))
    what = "warm-up"
    if skip > warmup:  # [periods] train_from: the record before it is not compared
        warmup, what = skip, "record before [periods] train_from"
    cover = length * (-(-test // length)) if test > 0 else 0
    need = warmup + length + cover
    if n_samples < need:
        raise DataError(
            f"the record is {format_duration(n_samples * step)} ({n_samples} samples) long; it "
            f"must be at least {_span(need, step)} ({need} samples): {what} "
            f"{warmup} + one period {length} + the whole periods covering the test window "
            f"{cover} samples",
            hint="use a longer record, or shorten [periods] warmup, length or the test window"
            + (", or move train_from earlier" if what != "warm-up" else ""),
        )
    layout = layout_periods(n_samples, length, warmup, test, missing)
    if layout.m_star < MIN_TRAINING_PERIODS:
        key = "test_samples" if periods.test_samples is not None else "test_fraction"
        dropped = layout.dropped_starts.size
        more = f" ({dropped} more dropped: missing data)" if dropped else ""
        raise DataError(
            f"[periods] leaves {layout.m_star} training period{more} of {length} samples "
            f"between the {what} ({warmup} samples) and the test window ({test} samples); "
            f"the calibration needs at least {MIN_TRAINING_PERIODS} (the emulator's variable "
            "conditions compare the boundary conditions between periods)",
            hint=f"shorten [periods] {key}, warmup or length, or use a longer record"
            + (" (or fill the gaps: data.max_gap_interpolate)" if dropped else ""),
        )
    return layout


def _where(gap: Gap, raw: pd.DatetimeIndex, labels: RowLabels | None, step: int) -> str:
    """Where a gap lies in the file: the lines of its rows, or the rows around it."""
    if labels is None:
        return ""
    t = raw.asi8
    lo = int(np.searchsorted(t, gap.first.value - step // 2, side="left"))
    hi = int(np.searchsorted(t, gap.last.value + step // 2, side="right"))
    if hi > lo:
        first, last = int(labels.lines[lo]), int(labels.lines[hi - 1])
        return f"file line {first}" if first == last else f"file lines {first}-{last}"
    if lo == 0:
        return f"before {labels.row(0)}"
    if lo >= t.size:
        return f"after {labels.row(t.size - 1)}"
    return f"no rows between {labels.row(lo - 1)} and {labels.row(lo)}"


def _bridge(
    frame: pd.DataFrame, names: tuple[str, ...], gaps: list[Gap], periods: tuple[int, int]
) -> tuple[pd.DataFrame, list[Gap], np.ndarray]:
    """Bridge the boundary conditions over the gaps left missing, for the simulator.

    Each column is interpolated linearly over its missing samples (held at the
    record's ends). The samples of a gap are unusable for calibration, and after
    a gap longer than one period also the warm-up that follows it: the simulator
    forgets the invented inputs as it forgets its initial state.

    Returns
    -------
    frame, gaps, unusable
        The bridged frame, the gaps (the bridged ones marked), and the mask of
        unusable samples, shape ``(n,)``.
    """
    period, warmup = periods
    index = pd.DatetimeIndex(frame.index)
    n = index.size
    unusable = np.zeros(n, dtype=bool)
    out = []
    for gap in gaps:
        if gap.interpolated or not any(c in names for c in gap.columns):
            out.append(gap)
            continue
        a = int(index.searchsorted(gap.first))
        b = a + gap.samples
        unusable[a : b + (warmup if gap.samples > period else 0)] = True
        out.append(dataclasses.replace(gap, bridged=True))
    if not unusable.any():
        return frame, gaps, unusable
    bridged = frame.copy()
    positions = np.arange(n)
    for name in names:
        values = bridged[name].to_numpy(dtype=float)
        good = np.isfinite(values)
        if not good.any():
            raise DataError(f"boundary condition {name} has no value on the study clock")
        bridged[name] = np.interp(positions, positions[good], values[good])
    return bridged, out, unusable


def load_measured(study: Study) -> MeasuredData:
    """Load, convert and align a study's measured data.

    Parameters
    ----------
    study
        A validated study (see :func:`bayescal.config.load_study`).

    Returns
    -------
    MeasuredData

    Notes
    -----
    Gaps of the boundary conditions that are not interpolated
    (``data.max_gap_interpolate``) are bridged linearly for the simulator, and the
    periods they touch are dropped, like periods with a missing measurement
    (after a gap longer than one period, the periods of the warm-up that follows
    it too).

    Raises
    ------
    DataError
        Unreadable file, bad timestamps, data coarser than the step, a record
        too short for warm-up + one period + test window, or fewer than two
        training periods left.
    """
    record = _record(study, study.data, optional_outputs=False)
    frame, step, source = record.frame, record.step, str(study.data.file)
    outputs = {n: frame[n].to_numpy(dtype=float, copy=True) for n in study.outputs.calibrate}
    for values in outputs.values():
        values[record.unusable] = np.nan  # measured, but against invented inputs
    _check_outputs(outputs, study.data, source)
    skip = 0
    if study.periods.train_from is not None:
        first = local_to_utc(study.periods.train_from, record.zone, "periods.train_from")
        skip = int(pd.DatetimeIndex(frame.index).tz_convert("UTC").searchsorted(first))
    try:
        layout = layout_for(len(frame), step, study.periods, _missing(outputs, len(frame)), skip)
    except DataError as exc:  # name the file the record comes from
        raise DataError(exc.message, hint=exc.hint, source=exc.source or source) from None
    return record.measured(study, outputs, layout)


def load_new_record(
    study: Study,
    file: Path,
    anchor: np.datetime64,
    *,
    start: pd.Timestamp | None = None,
    end: pd.Timestamp | None = None,
) -> MeasuredData:
    """Another record read with a study's ``[data]`` mapping: new conditions to predict.

    The file has the study's format, clock step and column names; its
    boundary conditions must all be there, its measured outputs (calibrated
    or held out) may be missing (their series are then NaN: a prediction
    without a check). ``[[data.exclude]]`` and ``data.start``/``end`` of the
    study are not applied (they name the study's own file); ``start`` and
    ``end`` cut this one (local time of the data, end exclusive).

    After the study's warm-up the record is laid out as whole periods in
    the phase of the study's periods (every period starts at the time of
    day of the study's, ``anchor``), all of them "test" periods: no
    training period, test window from the first of them to the end of the
    last whole one (a partial period at the end is cut off).

    Raises
    ------
    DataError
        The file does not exist or lacks a boundary condition, its clock is
        not in step with the study's, or it is shorter than the warm-up and
        one period.
    """
    path = Path(file).expanduser().resolve()
    data = study.data.model_copy(update={"file": path, "start": start, "end": end, "exclude": []})
    source = str(path)
    present = _file_columns(data)
    optional = (*study.outputs.calibrate, *study.outputs.held_out)
    record = _record(study, data, optional_outputs=True, present=present)
    frame, step = record.frame, record.step
    period = _samples(study.periods.length, step)
    warmup = _samples(study.periods.warmup, step)
    index = pd.DatetimeIndex(frame.index).tz_convert("UTC").tz_localize(None)
    lag = float((index[0] - pd.Timestamp(anchor)) / step)
    if abs(lag - round(lag)) > 1e-6:
        raise DataError(
            f"the clock of {path.name} is not in step with the study's: its samples fall "
            f"{format_duration((lag - np.floor(lag)) * step)} after the study's clock instants",
            hint="give a file on the same clock (data.step from the same instant of the day)",
            source=source,
        )
    first = warmup + (-(round(lag) + warmup)) % period
    whole = (len(frame) - first) // period
    if whole < 1:
        raise DataError(
            f"{path.name} holds {len(frame)} samples after alignment; it needs the study's "
            f"warm-up ({warmup} samples) and at least one whole period ({period}) in the "
            "phase of the study's periods",
            hint="give a longer record, or a wider --from/--to",
            source=source,
        )
    n_total = first + whole * period
    record = record.head(n_total)
    outputs = {}
    for name in optional:
        values = (
            record.frame[name].to_numpy(dtype=float, copy=True)
            if name in record.frame
            else np.full(n_total, np.nan)
        )
        values[record.unusable] = np.nan
        outputs[name] = values
    layout = PeriodLayout(
        n_total=n_total,
        period=period,
        warmup=warmup,
        test=n_total - first,
        train_starts=np.zeros(0, dtype=int),
        dropped_starts=np.zeros(0, dtype=int),
        test_starts=first + period * np.arange(whole),
    )
    return record.measured(study, outputs, layout)


def _file_columns(data: DataSection) -> set[str] | None:
    """The column names of a CSV or Parquet file (``None``: every mapped column is there)."""
    try:
        if data.format == "csv":
            header = pd.read_csv(data.file, sep=data.delimiter, nrows=0)
            return {str(c).strip() for c in header.columns}
        if data.format == "parquet":
            import pyarrow.parquet as pq

            return set(pq.read_schema(data.file).names)
    except (OSError, ValueError):  # the reader says what is wrong with the file
        return None
    return None


@dataclass(frozen=True)
class _Record:
    """A data file on the study clock, before the outputs and periods are chosen."""

    frame: pd.DataFrame
    step: pd.Timedelta
    gaps: tuple[Gap, ...]
    unusable: np.ndarray
    zone: tzinfo
    excluded: tuple[Excluded, ...]
    source: Path

    def head(self, n: int) -> _Record:
        """The first ``n`` samples."""
        return dataclasses.replace(self, frame=self.frame.iloc[:n], unusable=self.unusable[:n])

    def measured(
        self, study: Study, outputs: dict[str, np.ndarray], layout: PeriodLayout
    ) -> MeasuredData:
        """The record as :class:`MeasuredData` with ``outputs`` (calibrated and held out)."""
        frame = self.frame
        index = pd.DatetimeIndex(frame.index).tz_convert("UTC").tz_localize(None)
        times = index.to_numpy().astype("datetime64[s]")
        forcing = Forcing(
            step=self.step.total_seconds(),
            series={n: frame[n].to_numpy(dtype=float) for n in study.boundary_conditions},
            start=times[0],
        )
        calibrate = {n: outputs[n] for n in study.outputs.calibrate}
        held_out = {
            n: outputs[n] if n in outputs else frame[n].to_numpy(dtype=float)
            for n in study.outputs.held_out
        }
        return MeasuredData(
            forcing,
            calibrate,
            times,
            self.step.total_seconds(),
            self.gaps,
            layout,
            self.source,
            self.zone,
            held_out,
            self.excluded,
        )


def _record(
    study: Study,
    data: DataSection,
    *,
    optional_outputs: bool,
    present: set[str] | None = None,
) -> _Record:
    """Read, convert, exclude, align and bridge ``data`` (a study's or another file's)."""
    source = str(data.file)
    columns = dict(data.columns)
    if optional_outputs and present is not None:
        outputs = set(study.outputs.calibrate) | set(study.outputs.held_out)
        columns = {
            n: spec for n, spec in columns.items() if n not in outputs or spec.source in present
        }
        data = data.model_copy(update={"columns": columns})
    sources = list(dict.fromkeys(spec.source for spec in columns.values()))
    raw, zone = _read(data, sources)
    labels = raw.attrs.get("rows")
    step = pd.Timedelta(data.step)
    converted, excluded = _exclude(_convert(raw, data), data, zone)
    frame = align(
        converted,
        step,
        zone=zone,
        start=None if data.start is None else pd.Timestamp(data.start),
        end=None if data.end is None else pd.Timestamp(data.end),
        source=source,
        labels=labels,
        resample=data.resample,
    )
    aggregates = {name: spec.aggregate for name, spec in columns.items()}
    frame = replace_interval_columns(frame, converted, aggregates, step, source=source)
    frame, gaps = fill_gaps(frame, pd.Timedelta(data.max_gap_interpolate))
    raw_index = pd.DatetimeIndex(raw.index).as_unit("ns")
    gaps = [dataclasses.replace(g, where=_where(g, raw_index, labels, step.value)) for g in gaps]
    periods = (_samples(study.periods.length, step), _samples(study.periods.warmup, step))
    frame, gaps, unusable = _bridge(frame, study.boundary_conditions, gaps, periods)
    return _Record(frame, step, tuple(gaps), unusable, zone, excluded, Path(source))
