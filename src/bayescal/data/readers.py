"""Readers of measured-data files: CSV, Parquet, EnergyPlus weather, Modelica tables.

Every reader returns a :class:`pandas.DataFrame` indexed by a tz-aware UTC
:class:`pandas.DatetimeIndex` named ``"time"``, strictly increasing, holding
the file's columns as float64 (NaN for missing cells). Anything malformed
raises :class:`~bayescal.errors.DataError` naming the file, the line and the
fix; no parser traceback reaches the user.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Sequence
from datetime import UTC, datetime, tzinfo
from pathlib import Path

import numpy as np
import pandas as pd

from bayescal.clock import parse_time_zone
from bayescal.config.base import path_problem
from bayescal.data.align import MAX_LISTED, RowLabels, check_index, localize
from bayescal.errors import DataError
from bayescal.simulators.epw_format import EPW_FIELDS

NA_TOKENS = frozenset({"", "nan", "NaN", "NAN", "NA", "N/A", "n/a", "null", "NULL", "None", "-"})
"""Cell texts read as missing values."""

_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+(?:[eE][+-]?\d+)?$")


def _read_text(path: Path) -> str:
    problem = path_problem(path)
    if problem is not None:
        raise DataError(
            problem,
            hint="check data.file in study.toml (relative paths start at the study folder)"
            + ("; point it at the file itself" if "link" in problem else ""),
            source=str(path),
        )
    data = path.read_bytes()
    utf16 = _utf16(data)
    try:
        text = data.decode(utf16 or "utf-8-sig")
    except UnicodeDecodeError as exc:
        if utf16:
            raise DataError(
                f"cannot read the file as UTF-16 text (byte {exc.start})",
                hint="re-save it as UTF-8 text (CSV UTF-8 in Excel)",
                source=str(path),
            ) from None
        text = data.decode("latin-1")  # decodes any byte
    if "\x00" in text:
        raise DataError("the file contains NUL bytes: it is not a text file", source=str(path))
    if not text.strip():
        raise DataError("the file is empty", source=str(path))
    return text


def _utf16(data: bytes) -> str | None:
    """``"utf-16"`` for text with a UTF-16 byte-order mark, ``"utf-16-le"``/``"-be"`` for
    UTF-16 without one (a NUL byte beside every ASCII character: Excel's "Unicode
    text"), else ``None``."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return "utf-16"
    head = data[:200]
    if len(head) >= 8 and len(head) % 2 == 0:
        even, odd = head[0::2], head[1::2]
        if odd.count(0) == len(odd) and even.count(0) == 0:
            return "utf-16-le"
        if even.count(0) == len(even) and odd.count(0) == 0:
            return "utf-16-be"
    return None


# --------------------------------------------------------------------------- numbers


def _to_float(
    cells: np.ndarray, lines: np.ndarray, column: str, source: str, decimal: str = "."
) -> np.ndarray:
    """Convert one column of cell texts to float; a non-numeric cell is an error."""
    if decimal == ".":
        try:  # fast path: every cell a plain number
            return np.asarray(cells, dtype=object).astype(float)
        except (ValueError, TypeError, OverflowError):
            pass
    texts = pd.Series(cells, dtype=object).astype(str).str.strip()
    if decimal != ".":
        texts = texts.str.replace(decimal, ".", regex=False)
    numbers = pd.to_numeric(texts.where(~texts.isin(NA_TOKENS)), errors="coerce")
    values = np.array(numbers, dtype=float)  # a writable copy
    bad = np.flatnonzero(np.isnan(values) & ~texts.isin(NA_TOKENS).to_numpy())
    if bad.size:
        cell = str(cells[bad[0]])
        hint = (
            "the file seems to use decimal commas: set data.decimal = ','"
            if decimal == "." and _DECIMAL_COMMA.match(cell.strip())
            else "fix or blank the cell (empty cells are read as missing values)"
        )
        raise DataError(
            f"line {lines[bad[0]]}, column {column!r}: {cell!r} is not a number"
            + (f" ({bad.size} such cells)" if bad.size > 1 else ""),
            hint=hint,
            source=source,
        )
    return values


def _numeric_frame(
    columns: dict[str, np.ndarray],
    index: pd.DatetimeIndex,
    lines: np.ndarray,
    source: str,
    texts: np.ndarray,
) -> pd.DataFrame:
    """The frame of a reader; ``attrs["rows"]`` holds each row's line and time as written
    (:class:`~bayescal.data.align.RowLabels`), for messages of later steps."""
    for name, values in columns.items():
        infinite = np.flatnonzero(np.isinf(values))
        if infinite.size:
            raise DataError(
                f"line {lines[infinite[0]]}, column {name!r}: {values[infinite[0]]} is not a "
                "finite number",
                hint="blank the cell to mark a missing value",
                source=source,
            )
    frame = pd.DataFrame(columns, index=_ns_index(pd.DatetimeIndex(index), lines, source))
    frame.index.name = "time"
    check_index(pd.DatetimeIndex(frame.index), source, lines, texts)
    frame.attrs["rows"] = RowLabels(np.asarray(lines), np.asarray(texts, dtype=str))
    return frame


def _ns_index(index: pd.DatetimeIndex, lines: np.ndarray, source: str) -> pd.DatetimeIndex:
    """The index in nanoseconds; a time beyond their range (years 1678-2261) is an error."""
    try:
        return index.as_unit("ns")
    except (OverflowError, ValueError):  # pandas' OutOfBoundsDatetime is a ValueError
        bad = np.flatnonzero((index.year < 1678) | (index.year > 2261))
        pos = int(bad[0]) if bad.size else 0
        raise DataError(
            f"line {lines[pos]}: time {index[pos]} is outside the years 1678 to 2261",
            hint="check the time column (and data.time_format)",
            source=source,
        ) from None


def _select(available: Sequence[object], wanted: Sequence[object] | None, source: str) -> list:
    if wanted is None:
        return list(available)
    missing = [w for w in wanted if w not in available]
    if missing:
        import difflib

        names = [str(a) for a in available]
        close = difflib.get_close_matches(str(missing[0]), names, n=1)
        hint = f"did you mean {close[0]!r}?" if close else f"columns are {_short(names)}"
        raise DataError(f"no column {missing[0]!r} in the file", hint=hint, source=source)
    return list(wanted)


def _short(names: Sequence[object]) -> str:
    shown = ", ".join(repr(n) for n in list(names)[: 3 * MAX_LISTED])
    return shown + (", ..." if len(names) > 3 * MAX_LISTED else "")


# --------------------------------------------------------------------------- CSV


def _guess_delimiter(header: str) -> str | None:
    counts = {d: header.count(d) for d in (";", "\t", ",", "|")}
    best = max(counts, key=lambda d: counts[d])
    return best if counts[best] else None


def _split_rows(
    text: str, delimiter: str, source: str
) -> tuple[list[str], list[list[str]], list[int]]:
    reader = csv.reader(text.splitlines(), delimiter=delimiter)
    header: list[str] | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        for row in reader:
            if not row or all(not c.strip() for c in row):
                continue
            if header is None:
                header = [c.strip() for c in row]
                continue
            if len(row) != len(header):
                raise DataError(
                    f"line {reader.line_num} has {len(row)} fields, the header has {len(header)}",
                    hint="the row is truncated or has extra fields"
                    + (
                        "; with decimal commas the delimiter must not be ','"
                        if delimiter == ","
                        else ""
                    ),
                    source=source,
                )
            rows.append(row)
            lines.append(reader.line_num)
    except csv.Error as exc:
        raise DataError(f"line {reader.line_num}: {exc}", source=source) from None
    if header is None or not rows:
        raise DataError("the file has a header but no data rows", source=source)
    return header, rows, lines


_UTC_OFFSET = re.compile(r"(?:Z|[+-]\d{2}:?\d{2})$")


def _check_offsets(texts: pd.Series, lines: np.ndarray, source: str) -> None:
    """Timestamps with a UTC offset mixed with naive ones (local times) are ambiguous."""
    marked = texts.str.contains(_UTC_OFFSET).to_numpy(dtype=bool)
    if marked.any() and not marked.all():
        aware, naive = int(np.argmax(marked)), int(np.argmax(~marked))
        raise DataError(
            f"line {lines[aware]} has a time with a UTC offset ({texts.iloc[aware]!r}), line "
            f"{lines[naive]} one without ({texts.iloc[naive]!r}); mixing them is ambiguous",
            hint="write every time with its offset, or none (local times of data.time_zone)",
            source=source,
        )


EPOCH_FORMATS = {"epoch": "s", "epoch_ms": "ms"}
"""``data.time_format`` values for Unix times: seconds (or milliseconds) since
1970-01-01 00:00 UTC."""
_EPOCH_LIMIT = 9.2e9  # seconds: the nanosecond timestamps end in 2262


def _epoch_times(texts: pd.Series, lines: np.ndarray, unit: str, source: str) -> pd.DatetimeIndex:
    """Unix times (``unit`` ``"s"`` or ``"ms"``) -> tz-aware UTC times, to the millisecond."""
    numbers = pd.to_numeric(texts, errors="coerce").to_numpy(dtype=float)
    seconds = numbers / (1000.0 if unit == "ms" else 1.0)
    bad = np.flatnonzero(~(np.abs(seconds) < _EPOCH_LIMIT))
    if bad.size:
        name = "milliseconds" if unit == "ms" else "seconds"
        hint = (
            "data.time_format = 'epoch' reads seconds, 'epoch_ms' milliseconds"
            if np.isfinite(numbers[bad[0]])
            else "these are no Unix times: remove data.time_format for ISO 8601 times, or "
            "give their strftime format"
        )
        raise DataError(
            f"line {lines[bad[0]]}: cannot read time {texts.iloc[bad[0]]!r} as {name} since "
            "1970-01-01 UTC",
            hint=hint,
            source=source,
        )
    millis = np.round(seconds * 1e3).astype(np.int64)
    return pd.DatetimeIndex(pd.to_datetime(millis, unit="ms", utc=True))


def _time_hint(time_format: str | None, cell: str) -> str:
    if time_format:
        return "check data.time_format (strftime codes, e.g. '%d/%m/%Y %H:%M')"
    try:
        number = float(cell)
    except ValueError:
        number = 0.0
    if abs(number) > 1e8:
        unit = "epoch_ms" if abs(number) > 1e11 else "epoch"
        return (
            f"the times look like Unix times: set data.time_format = '{unit}' "
            f"({'milli' if unit == 'epoch_ms' else ''}seconds since 1970-01-01 UTC)"
        )
    return (
        "set data.time_format (strftime codes, e.g. '%d/%m/%Y %H:%M', or 'epoch'); "
        "without it times must be ISO 8601"
    )


def _parse_times(
    cells: np.ndarray, lines: np.ndarray, time_format: str | None, source: str
) -> pd.DatetimeIndex:
    texts = pd.Series(cells, dtype=object).astype(str).str.strip()
    if time_format in EPOCH_FORMATS:
        return _epoch_times(texts, lines, EPOCH_FORMATS[time_format], source)
    fmt = time_format or "ISO8601"
    try:
        times = pd.to_datetime(texts, format=fmt, errors="coerce")
    except (ValueError, TypeError) as exc:  # mixed offsets, bad format string
        _check_offsets(texts, lines, source)
        try:
            times = pd.to_datetime(texts, format=fmt, errors="coerce", utc=True)
        except (ValueError, TypeError):
            raise DataError(f"cannot read the time column: {exc}", source=source) from None
    bad = np.flatnonzero(pd.isna(times).to_numpy())
    if bad.size:
        raise DataError(
            f"line {lines[bad[0]]}: cannot read time {str(cells[bad[0]])!r}",
            hint=_time_hint(time_format, str(cells[bad[0]]).strip()),
            source=source,
        )
    return pd.DatetimeIndex(times)


def read_csv(
    path: str | Path,
    time_column: str,
    *,
    time_format: str | None = None,
    time_zone: tzinfo | str | None = None,
    delimiter: str = ",",
    decimal: str = ".",
    columns: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Read a delimited text file with a header line and a time column.

    Parameters
    ----------
    path
        The file.
    time_column
        Name of the column holding timestamps.
    time_format
        strftime format of the timestamps; ISO 8601 when omitted.
    time_zone
        Zone of naive timestamps: a ``tzinfo``, an IANA name or a fixed offset
        such as ``"UTC+01:00"`` (UTC when omitted); timestamps carrying an
        offset keep it.
    delimiter
        Field separator.
    decimal
        Decimal mark of the numbers (``"."`` or ``","``).
    columns
        Columns to read (all others are ignored); all when omitted.

    Returns
    -------
    pandas.DataFrame
        The chosen columns as float64, indexed by UTC time.
    """
    path = Path(path)
    source = str(path)
    text = _read_text(path)
    header, rows, lines = _split_rows(text, delimiter, source)
    if len(header) == 1 and time_column not in header:
        guess = _guess_delimiter(header[0])
        hint = (
            f"the header looks delimited by {guess!r}: set data.delimiter = {guess!r}"
            if guess
            else "check data.delimiter"
        )
        raise DataError(
            f"only one column found with delimiter {delimiter!r}", hint=hint, source=source
        )
    if len(set(header)) != len(header):
        dups = sorted({h for h in header if header.count(h) > 1})
        raise DataError(f"duplicated column names {dups}", source=source)
    if time_column not in header:
        _select(header, [time_column], source)
    cells = np.array(rows, dtype=object)
    line_numbers = np.asarray(lines)
    wanted = _select([h for h in header if h != time_column], columns, source)
    time_cells = cells[:, header.index(time_column)]
    texts = np.array([str(c).strip() for c in time_cells])
    times = _parse_times(time_cells, line_numbers, time_format, source)
    labels = RowLabels(line_numbers, texts)
    index = localize(times, _zone(time_zone, source), source, labels)
    data = {
        name: _to_float(cells[:, header.index(name)], line_numbers, name, source, decimal)
        for name in wanted
    }
    return _numeric_frame(data, index, line_numbers, source, texts)


def _zone(time_zone: tzinfo | str | None, source: str) -> tzinfo:
    """The zone of naive times: a tzinfo, a name or offset for ``parse_time_zone``, or UTC."""
    if time_zone is None:
        return UTC
    if isinstance(time_zone, str):
        try:
            return parse_time_zone(time_zone)
        except ValueError as exc:
            raise DataError(str(exc), source=source) from None
    return time_zone


# --------------------------------------------------------------------------- Parquet


def read_parquet(
    path: str | Path,
    time_column: str,
    *,
    time_format: str | None = None,
    time_zone: tzinfo | str | None = None,
    columns: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Read a Parquet table with a time column (or a time index of that name).

    Parameters are those of :func:`read_csv`; a time column of strings is
    parsed like a CSV's.
    """
    path = Path(path)
    source = str(path)
    if not path.is_file() or not path.stat().st_size:
        _read_text(path)  # raises the not-found or empty-file error
    try:
        frame = pd.read_parquet(path)
    except Exception as exc:  # pyarrow raises many types for corrupt files
        raise DataError(
            f"cannot read the file as Parquet ({type(exc).__name__}: {exc})".splitlines()[0],
            hint="check data.format",
            source=source,
        ) from None
    if time_column not in frame.columns and frame.index.name == time_column:
        frame = frame.reset_index()
    names = [str(c) for c in frame.columns]
    _select(names, [time_column], source)
    wanted = _select([n for n in names if n != time_column], columns, source)
    lines = np.arange(1, len(frame) + 1)
    raw_time = frame[time_column]
    if pd.api.types.is_datetime64_any_dtype(raw_time):
        times = pd.DatetimeIndex(raw_time)
        texts = np.array([str(t) for t in times])
    else:
        cells = raw_time.to_numpy(dtype=object)
        texts = np.array([str(c).strip() for c in cells])
        times = _parse_times(cells, lines, time_format, source)
    index = localize(times, _zone(time_zone, source), source, RowLabels(lines, texts))
    data = {}
    for name in wanted:
        col = frame[name]
        if pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_bool_dtype(col):
            data[name] = col.to_numpy(dtype=float, na_value=np.nan)
        else:
            data[name] = _to_float(col.to_numpy(dtype=object), lines, name, source)
    return _numeric_frame(data, index, lines, source, texts)


# --------------------------------------------------------------------------- EPW

_EPW_MISSING = {
    "temp_air_out": 99.9,
    "temp_dew": 99.9,
    "relative_humidity": 999.0,
    "pressure": 999999.0,
    "etr": 9999.0,
    "etrn": 9999.0,
    "ir_horizontal": 9999.0,
    "ghi": 9999.0,
    "dni": 9999.0,
    "dhi": 9999.0,
    "wind_direction": 999.0,
    "wind_speed": 999.0,
}
_EPW_MIN_FIELDS = EPW_FIELDS.index("wind_speed") + 1
_EPW_HEADER_LINES = 8


def epw_field(source: str | int) -> str:
    """The EPW column name for a field index or name (``6`` -> ``"temp_air_out"``)."""
    if isinstance(source, int) and not isinstance(source, bool):
        if not 0 <= source < len(EPW_FIELDS):
            raise DataError(f"EPW field index {source} is outside 0..{len(EPW_FIELDS) - 1}")
        return EPW_FIELDS[source]
    return str(source)


def _epw_zone(location: str, source: str) -> tzinfo:
    from datetime import timedelta, timezone

    fields = location.split(",")
    if fields[0].strip().upper() != "LOCATION" or len(fields) < 10:
        raise DataError(
            "line 1 is not an EPW LOCATION line (expected 10 comma-separated fields)",
            hint="check data.format",
            source=source,
        )
    try:
        hours = float(fields[8])
    except ValueError:
        raise DataError(
            f"line 1: time zone {fields[8]!r} is not a number of hours", source=source
        ) from None
    if not -12.0 <= hours <= 14.0:  # NaN included
        raise DataError(
            f"line 1: time zone {fields[8]!r} is not a UTC offset (expected -12 to +14 hours)",
            source=source,
        )
    return timezone(timedelta(hours=hours))


def read_epw(path: str | Path, *, year: int | None = None) -> pd.DataFrame:
    """Read an EnergyPlus weather file.

    Timestamps: the hour field 1–24 is the hour *ending* (row ``hour = 1``
    holds 00:00–01:00 and is stamped 01:00 local standard time), converted to
    UTC with the offset of the LOCATION line. Typical-year files mix years
    from month to month; they are put on one year (that of the first row,
    unless ``year`` is given).

    Parameters
    ----------
    path
        The ``.epw`` file.
    year
        Year to put all rows on (optional).

    Returns
    -------
    pandas.DataFrame
        The numeric fields of :data:`EPW_FIELDS` from ``temp_air_out`` on, missing-value
        codes (99.9, 999, 9999...) as NaN; ``attrs["time_zone"]`` holds the file's
        fixed offset.
    """
    path = Path(path)
    source = str(path)
    lines = _read_text(path).splitlines()
    zone = _epw_zone(lines[0], source)
    body = [
        (i + 1, line) for i, line in enumerate(lines) if i >= _EPW_HEADER_LINES and line.strip()
    ]
    if not body:
        raise DataError("no data rows after the 8 header lines", source=source)
    rows = [line.split(",") for _, line in body]
    width = len(rows[0])
    line_numbers = np.array([n for n, _ in body])
    for (number, _), row in zip(body, rows, strict=True):
        if len(row) != width or width < _EPW_MIN_FIELDS:
            raise DataError(
                f"line {number} has {len(row)} fields, expected {max(width, _EPW_MIN_FIELDS)}",
                hint="the file is truncated or not an EPW file",
                source=source,
            )
    cells = np.array(rows, dtype=object)
    stamp = {
        name: _to_float(cells[:, i], line_numbers, name, source)
        for i, name in enumerate(EPW_FIELDS[:5])
    }
    index = _epw_times(stamp, year, line_numbers, source)
    texts = np.array([",".join(str(c).strip() for c in row[:5]) for row in rows])
    index = localize(index, zone, source)
    data = {}
    for i, name in enumerate(EPW_FIELDS[6:width], start=6):
        if name == "present_weather_codes":
            continue
        values = _to_float(cells[:, i], line_numbers, name, source)
        if name in _EPW_MISSING:
            values[values >= _EPW_MISSING[name]] = np.nan
        data[name] = values
    frame = _numeric_frame(data, index, line_numbers, source, texts)
    frame.attrs["time_zone"] = zone
    return frame


def _epw_times(
    stamp: dict[str, np.ndarray], year: int | None, lines: np.ndarray, source: str
) -> pd.DatetimeIndex:
    bad = np.flatnonzero(~np.all([np.isfinite(v) for v in stamp.values()], axis=0))
    if bad.size:
        raise DataError(f"line {lines[bad[0]]}: missing date or time field", source=source)
    minutes = stamp["minute"]
    hours = stamp["hour"]
    out = (hours < 1) | (hours > 24) | (minutes < 0) | (minutes > 60)
    out |= (stamp["year"] < 1700) | (stamp["year"] > 2200)
    out |= (stamp["month"] < 1) | (stamp["month"] > 12) | (stamp["day"] < 1) | (stamp["day"] > 31)
    bad = np.flatnonzero(out)
    if bad.size:
        raise DataError(f"line {lines[bad[0]]}: date or time field out of range", source=source)
    years = stamp["year"].astype(int)
    if year is not None or np.unique(years).size > 1:
        years = np.full_like(years, year if year is not None else years[0])
    if np.all(np.isin(minutes, (0.0, 60.0))):
        offset = hours * 60.0
    else:
        offset = (hours - 1.0) * 60.0 + minutes
    try:
        dates = pd.to_datetime(
            {"year": years, "month": stamp["month"].astype(int), "day": stamp["day"].astype(int)}
        )
    except (ValueError, TypeError) as exc:
        raise DataError(f"invalid date in the file: {exc}", source=source) from None
    return pd.DatetimeIndex(dates + pd.to_timedelta(offset, unit="min"))


# --------------------------------------------------------------------------- Modelica

_MAX_SECONDS = 3e9  # about 95 years: beyond it, column 0 cannot be seconds since the epoch
_TABLE_HEADER = re.compile(r"^\s*(?:double|float)\s+(\w+)\s*\(\s*(\d+)\s*,\s*(\d+)\s*\)")


def _table_lines(
    text: str, table: str | None, source: str
) -> tuple[str, int, int, list[tuple[int, str]]]:
    """Find the table's header and collect the lines that follow it."""
    found: list[str] = []
    current: tuple[str, int, int] | None = None
    chosen: tuple[str, int, int] | None = None
    body: list[tuple[int, str]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        match = _TABLE_HEADER.match(line)
        if match:
            current = (match.group(1), int(match.group(2)), int(match.group(3)))
            found.append(current[0])
            if chosen is not None:
                break
            if table is None or current[0] == table:
                chosen = current
            continue
        if current is None:
            raise DataError(
                f"line {number}: expected a header 'double NAME(ROWS,COLS)', "
                f"got {raw.strip()[:40]!r}",
                hint="is this a Modelica CombiTimeTable file? otherwise set data.format",
                source=source,
            )
        if chosen is not None:
            body.append((number, line))
    if chosen is None:
        raise DataError(
            f"no table {table!r} in the file; it has {found}" if table else "no table header found",
            source=source,
        )
    return chosen[0], chosen[1], chosen[2], body


def _table_values(
    body: list[tuple[int, str]], rows: int, cols: int, name: str, source: str
) -> np.ndarray:
    values = np.empty((len(body), cols))
    for i, (number, line) in enumerate(body):
        tokens = line.replace(",", " ").split()
        if len(tokens) != cols:
            raise DataError(
                f"line {number} has {len(tokens)} values, table {name}({rows},{cols}) declares "
                f"{cols} columns",
                hint="the row is truncated, or the numbers use decimal commas (use '.')",
                source=source,
            )
        try:
            values[i] = [float(t) for t in tokens]
        except ValueError:
            bad = next(t for t in tokens if not _is_float(t))
            raise DataError(f"line {number}: {bad!r} is not a number", source=source) from None
    if len(body) != rows:
        raise DataError(
            f"table {name}({rows},{cols}) declares {rows} rows, the file has {len(body)}",
            hint="the file is truncated or the header is wrong",
            source=source,
        )
    return values


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def read_modelica_table(
    path: str | Path,
    epoch: datetime | pd.Timestamp,
    *,
    time_zone: tzinfo | str | None = None,
    table: str | None = None,
    columns: Sequence[int] | None = None,
) -> pd.DataFrame:
    """Read a Modelica ``CombiTimeTable`` text file.

    Format: an optional ``#1`` line, a header ``double NAME(ROWS,COLS)``, then
    ``ROWS`` lines of ``COLS`` numbers separated by blanks (or commas);
    ``#`` starts a comment. Column 0 is time in seconds since ``epoch``.

    Parameters
    ----------
    path
        The file.
    epoch
        The instant of ``t = 0``; a naive value is a local time of ``time_zone``.
    time_zone
        Zone of a naive epoch, as for :func:`read_csv` (UTC when omitted).
    table
        Name of the table in a file holding several; the first when omitted.
    columns
        Column indices to keep (1 .. COLS-1); all when omitted.

    Returns
    -------
    pandas.DataFrame
        Columns named by their integer index, indexed by UTC time.
    """
    path = Path(path)
    source = str(path)
    name, rows, cols, body = _table_lines(_read_text(path), table, source)
    if cols < 2:
        raise DataError(
            f"table {name}({rows},{cols}) has no data column besides time", source=source
        )
    values = _table_values(body, rows, cols, name, source)
    lines = np.array([number for number, _ in body])
    wanted = _select(list(range(1, cols)), columns, source)
    start = pd.Timestamp(epoch)
    if start.tz is None:
        start = localize(pd.DatetimeIndex([start]), _zone(time_zone, source), source)[0]
    seconds = values[:, 0]
    bad = np.flatnonzero(~(np.abs(seconds) < _MAX_SECONDS))
    if bad.size:
        raise DataError(
            f"line {lines[bad[0]]}: time {float(seconds[bad[0]])!r} s is not a time since "
            f"the epoch (expected a finite number of seconds below {_MAX_SECONDS:.0e})",
            source=source,
        )
    offsets = pd.to_timedelta(np.round(seconds * 1e3).astype(np.int64), unit="ms")
    index = pd.DatetimeIndex(start.tz_convert("UTC") + offsets)
    texts = np.array([line.replace(",", " ").split()[0] for _, line in body])
    return _numeric_frame({c: values[:, c] for c in wanted}, index, lines, source, texts)
