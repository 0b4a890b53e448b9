"""The ``[data]`` section of the study file: the measured-data file, its clock and its columns.

Each ``[data.columns.<glossary name>]`` entry is checked here, before any file
is read (:func:`column_problems`): a glossary name, a unit of its dimension
and a source that suits the file format. Reading the data is
:func:`bayescal.data.load_measured`'s job.
"""

from __future__ import annotations

import difflib
from datetime import timedelta, tzinfo
from pathlib import Path
from typing import Any, Literal

import pandas as pd
from pydantic import ValidationInfo, field_validator, model_validator

from bayescal.clock import format_duration, local_to_utc, parse_time_zone
from bayescal.config.base import (
    Duration,
    Instant,
    Section,
    field_doc,
    local_time_problems,
    raise_problems,
    resolve_path,
    suggestion,
)
from bayescal.errors import DataError
from bayescal.glossary import GLOSSARY, glossary_quantity
from bayescal.simulators.epw_format import EPW_FIELDS
from bayescal.units import dimension_of

__all__ = ["FORMATS", "ColumnSpec", "DataSection", "column_problems"]

FORMATS = ("csv", "parquet", "epw", "modelica")
_EXTENSIONS = {".csv": "csv", ".tsv": "csv", ".parquet": "parquet", ".pq": "parquet"}
_EXTENSIONS |= {".epw": "epw", ".txt": "modelica", ".mos": "modelica"}


class ColumnSpec(Section):
    """``[data.columns.<glossary name>]``: where a series comes from and its unit."""

    source: str | int = field_doc(
        "Column name (CSV, Parquet, EPW field name) or integer index (Modelica: 1..COLS-1, "
        "column 0 being time; EPW: field number).",
        "T_in",
        14,
    )
    unit: str = field_doc(
        "Unit in the file; of the glossary quantity's dimension (°F for a temperature is "
        "fine, kW is not). See bayescal.units.",
        "degC",
        "W/m2",
    )
    scale: float = field_doc(
        "Factor applied before unit conversion. [-]", 0.98, default=1.0, allow_inf_nan=False
    )
    sign: Literal[1, -1] = field_doc(
        "-1 flips the sign after conversion (a flux measured with the opposite convention).",
        -1,
        default=1,
    )
    aggregate: Literal["point", "mean", "sum"] = field_doc(
        "What a value stands for on the study clock, and so how finer data and the "
        "simulated series are brought to it: 'point' (the value at the instant; finer data "
        "are averaged over centred windows), 'mean' (the mean over the interval (t - step, "
        "t] ending at the timestamp) or 'sum' (the total over that interval: a meter; for "
        "energies, J, kWh, Wh, therm...). 'mean' and 'sum' ask the simulator for interval "
        "values (EnergyPlus sums or averages its time steps; the built-in wall and box "
        "average over [simulator] substeps fine steps and give no sums).",
        "sum",
        "mean",
        default="point",
    )

    @field_validator("source", mode="before")
    @classmethod
    def _source(cls, value: object) -> object:
        if isinstance(value, bool) or not isinstance(value, str | int):
            raise ValueError(f"expected a column name or an integer index, got {value!r}")
        return value


class ExcludeWindow(Section):
    """One ``[[data.exclude]]`` window: samples of the file that are not measurements."""

    start: Instant = field_doc(
        "First instant excluded (local time of the data, as data.start).",
        "2013-09-06T05:55:00",
    )
    end: Instant = field_doc(
        "End of the window, exclusive.",
        "2013-09-06T06:05:00",
    )
    columns: list[str] = field_doc(
        "Glossary names of the columns excluded (names of [data.columns]); empty: every column.",
        ["heat_flux_in", "temp_surf_in"],
        default_factory=list,
    )
    reason: str = field_doc(
        "Why, for the run's summary and the record.",
        "sun patch on the heat-flux plate",
        default="",
    )


class DataSection(Section):
    """``[data]``: the measured-data file, its clock and its columns."""

    file: Path = field_doc(
        "Data file, relative to the study folder (or absolute).", "data/wall.csv"
    )
    format: Literal["csv", "parquet", "epw", "modelica"] = field_doc(
        "File format; by default from the extension (.csv/.tsv, .parquet/.pq, .epw, "
        ".txt/.mos = Modelica CombiTimeTable).",
        "csv",
    )
    time_column: str | None = field_doc(
        "Timestamp column (csv, parquet: required).", "time", default=None
    )
    time_format: str | None = field_doc(
        "strftime format of the timestamps (csv, parquet); 'epoch' for Unix times (seconds "
        "since 1970-01-01 UTC), 'epoch_ms' for milliseconds; ISO 8601 if omitted.",
        "%d/%m/%Y %H:%M",
        "epoch",
        default=None,
    )
    time_zone: str = field_doc(
        "Zone of naive timestamps and of start, end, epoch: IANA name or fixed offset. The "
        "clock inside is UTC. Not for EPW (the file has its own). A time of the study "
        "file in the hour that a daylight-saving change repeats or skips is an error; "
        "give it with its UTC offset ('2013-10-27T02:30:00+01:00').",
        "UTC+01:00",
        "Europe/Brussels",
        default="UTC",
    )
    epoch: Instant | None = field_doc(
        "Modelica tables: the instant of t = 0 (column 0 is seconds since it).",
        "2013-01-01T00:00:00",
        default=None,
    )
    table: str | None = field_doc(
        "Modelica: table name in a file with several.", "data", default=None
    )
    delimiter: str = field_doc("CSV field separator.", ";", default=",", min_length=1, max_length=1)
    decimal: Literal[".", ","] = field_doc("CSV decimal mark.", ",", default=".")
    step: Duration = field_doc(
        "Step of the study clock. Finer data are averaged over centred windows "
        "[t - step/2, t + step/2); coarser data are an error.",
        "30min",
        "10min",
    )
    max_gap_interpolate: Duration = field_doc(
        "Gaps up to this length are interpolated linearly; longer ones are reported and "
        "the periods they touch dropped (a boundary condition is bridged linearly for the "
        "simulator over them, and after a gap longer than one period the warm-up that "
        "follows is dropped too). Default: never interpolate.",
        "1h",
        default=timedelta(0),
    )
    resample: Literal["none", "linear"] = field_doc(
        "'none': data finer than the step are averaged, data as fine must lie on the "
        "clock. 'linear': each clock instant is interpolated linearly between the two "
        "samples around it (for a logger whose clock jitters, e.g. 30 min ± 4 min); "
        "samples more than 1.5 steps apart leave the instants between them missing.",
        "linear",
        default="none",
    )
    start: Instant | None = field_doc(
        "First clock instant: crops the record and fixes the grid (default: the grid is "
        "anchored at local midnight).",
        "2013-08-21T00:00:00",
        default=None,
    )
    end: Instant | None = field_doc(
        "End of the record, exclusive.", "2013-09-30T00:00:00", default=None
    )
    exclude: list[ExcludeWindow] = field_doc(
        "Time windows whose samples are not measurements (a sensor event, a visit, a "
        "sun patch on a plate): their values in the file are treated as missing before "
        "the data are brought to the clock, so a clock value averaged from finer data "
        "keeps its other samples (if at least half of its window is left) and a value on "
        "the clock becomes a gap (data.max_gap_interpolate). Decide them from the "
        "records, not from a fit to the test window.",
        [{"start": "2013-09-06T05:55:00", "end": "2013-09-06T06:05:00"}],
        default_factory=list,
    )
    columns: dict[str, ColumnSpec] = field_doc(
        "Glossary name -> file column. Outputs in [outputs].calibrate are measurements, "
        "every other column a boundary condition.",
        {"heat_flux_in": {"source": "q_in", "unit": "W/m2"}},
        min_length=1,
    )

    @model_validator(mode="before")
    @classmethod
    def _infer_format(cls, data: Any, info: ValidationInfo) -> Any:
        if isinstance(data, dict) and isinstance(data.get("file"), str):
            try:  # a path that leaves the study folder is refused as such, before its format
                resolve_path(Path(data["file"]), info, "a file name")
            except ValueError as exc:
                raise_problems([f"data.file: {exc}"])
        if isinstance(data, dict) and "format" not in data and isinstance(data.get("file"), str):
            suffix = Path(data["file"]).suffix.lower()
            if suffix not in _EXTENSIONS:
                raise ValueError(
                    f"cannot tell the format of {data['file']!r} from its extension; set "
                    f"data.format to one of {', '.join(map(repr, FORMATS))}"
                )
            return {**data, "format": _EXTENSIONS[suffix]}
        return data

    @field_validator("file")
    @classmethod
    def _file(cls, value: Path, info: ValidationInfo) -> Path:
        return resolve_path(value, info, "a file name")

    @field_validator("time_zone")
    @classmethod
    def _zone(cls, value: str) -> str:
        parse_time_zone(value)
        return value

    @field_validator("step", "max_gap_interpolate")
    @classmethod
    def _not_negative(cls, value: timedelta, info: ValidationInfo) -> timedelta:
        if value < timedelta(0) or (info.field_name == "step" and not value):
            raise ValueError(
                f"must be {'positive' if info.field_name == 'step' else '>= 0'}, "
                f"got {format_duration(value)}"
            )
        return value

    @model_validator(mode="after")
    def _consistent(self) -> DataSection:
        problems = self._format_problems()
        for name, spec in self.columns.items():
            problems += column_problems(f"data.columns.{name}", name, spec, self.format)
        raise_problems(problems)
        return self

    def _format_problems(self) -> list[str]:
        fmt, given = self.format, self.model_fields_set
        problems = []
        if fmt in ("csv", "parquet") and self.time_column is None:
            problems.append(f"data.time_column: required for format {fmt!r}")
        if fmt == "modelica" and self.epoch is None:
            problems.append("data.epoch: required for Modelica tables (the instant of t = 0)")
        only = {"time_column": "csv parquet", "time_format": "csv parquet", "delimiter": "csv"}
        only |= {"decimal": "csv", "epoch": "modelica", "table": "modelica"}
        for key, formats in only.items():
            if key in given and fmt not in formats.split():
                problems.append(
                    f"data.{key}: only applies to format {formats.replace(' ', ' or ')}"
                )
        if fmt == "epw" and "time_zone" in given:
            problems.append("data.time_zone: EPW files carry their own time zone; remove it")
        times = {"data.start": self.start, "data.end": self.end, "data.epoch": self.epoch}
        for i, window in enumerate(self.exclude):
            times |= {f"data.exclude[{i}].{k}": getattr(window, k) for k in ("start", "end")}
        unplaced = local_time_problems(times, self.zone)  # then their order is not checked
        problems += unplaced

        def utc(key: str) -> pd.Timestamp:
            value = times[key]
            assert value is not None
            return local_to_utc(value, self.zone, key)

        if not unplaced and self.start and self.end and utc("data.start") >= utc("data.end"):
            problems.append(f"data.end: {self.end} is not after data.start {self.start}")
        for i, window in enumerate(self.exclude):
            key = f"data.exclude[{i}]"
            if not unplaced and utc(f"{key}.start") >= utc(f"{key}.end"):
                problems.append(f"{key}.end: {window.end} is not after its start {window.start}")
            for name in window.columns:
                if name not in self.columns:
                    problems.append(
                        f"{key}.columns: {name!r} is not a column of [data.columns]"
                        + suggestion(name, list(self.columns))
                    )
        if self.delimiter == self.decimal:
            problems.append(f"data.decimal: {self.decimal!r} is also the delimiter")
        return problems

    @property
    def zone(self) -> tzinfo:
        """The parsed time zone."""
        return parse_time_zone(self.time_zone)


def column_problems(key: str, name: str, spec: ColumnSpec, fmt: str) -> list[str]:
    """Problems of one ``[data.columns.<name>]`` entry, each prefixed with its key path.

    Checks that ``name`` is a glossary name, that the unit is of its dimension
    and that the source suits the file format.
    """
    quantity = glossary_quantity(name)
    if quantity is None:
        close = difflib.get_close_matches(name, list(GLOSSARY), n=1)
        hint = f"did you mean {close[0]!r}?" if close else "see bayescal.glossary"
        return [f"{key}: {name!r} is not a glossary name; {hint}"]
    problems = []
    try:
        found = dimension_of(spec.unit)
    except DataError as exc:
        found = None
        problems.append(f"{key}.unit: {exc.one_line()}")
    if found is not None and found != quantity.dimension:
        problems.append(
            f"{key}.unit: {spec.unit!r} is a {found.replace('_', ' ')} unit, {name} is a "
            f"{quantity.dimension.replace('_', ' ')}"
        )
    if spec.sign == -1 and quantity.dimension == "temperature":
        problems.append(f"{key}.sign: -1 on a temperature makes no sense (fluxes, powers only)")
    if quantity.dimension == "energy" and spec.aggregate != "sum":
        problems.append(
            f"{key}.aggregate: {name} is an energy over each clock interval (a meter); "
            f"set aggregate = 'sum', got {spec.aggregate!r}"
        )
    elif spec.aggregate == "sum" and quantity.dimension != "energy":
        problems.append(
            f"{key}.aggregate: 'sum' adds up energies over each interval, {name} is a "
            f"{quantity.dimension.replace('_', ' ')}; use 'mean' (or an energy quantity "
            "such as 'electricity' with unit 'kWh')"
        )
    return problems + _source_problems(key, spec.source, fmt)


def _source_problems(key: str, source: str | int, fmt: str) -> list[str]:
    if fmt == "modelica" and (not isinstance(source, int) or source < 1):
        return [
            f"{key}.source: Modelica tables need a column index >= 1 (0 is time), got {source!r}"
        ]
    if fmt in ("csv", "parquet") and not isinstance(source, str):
        return [f"{key}.source: give the column name for format {fmt!r}, got {source!r}"]
    names = EPW_FIELDS[6:]
    if fmt == "epw" and isinstance(source, int) and not 6 <= source < len(EPW_FIELDS):
        return [
            f"{key}.source: EPW data fields are numbered 6..{len(EPW_FIELDS) - 1}, got {source}"
        ]
    if fmt == "epw" and isinstance(source, str) and source not in names:
        close = difflib.get_close_matches(source, names, n=1)
        hint = f"did you mean {close[0]!r}?" if close else f"EPW fields: {', '.join(names)}"
        return [f"{key}.source: {source!r} is not an EPW field; {hint}"]
    return []
