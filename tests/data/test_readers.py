"""Readers of measured-data files: good files, malformed files, the real shared data."""

from __future__ import annotations

import csv
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayescal.clock import parse_time_zone
from bayescal.data.readers import (
    epw_field,
    read_csv,
    read_epw,
    read_modelica_table,
    read_parquet,
)
from bayescal.errors import DataError
from bayescal.simulators.epw_format import EPW_FIELDS
from paths import FIXTURES, SHARED_DATA

FIXTURE_CSV = FIXTURES / "wall-study" / "wall.csv"
SHARED = SHARED_DATA
TWIN_HOUSE = SHARED / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"
UCCLE = SHARED / "weather" / "BEL_VLG_Uccle.064470_TMYx.2007-2021.epw"
UTC1 = timezone(timedelta(hours=1))


def _write(tmp_path: Path, text: str, name: str = "f.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# --------------------------------------------------------------------------- CSV


def test_csv_fixture_values_and_utc_clock() -> None:
    frame = read_csv(FIXTURE_CSV, "time", time_zone=UTC1)
    with FIXTURE_CSV.open() as f:  # independent reading with the csv module
        rows = list(csv.DictReader(f))
    assert frame.shape == (len(rows), 3)
    np.testing.assert_array_equal(frame["q_si"].to_numpy(), [float(r["q_si"]) for r in rows])
    # Naive local times of UTC+01:00 become UTC one hour earlier.
    first = datetime.fromisoformat(rows[0]["time"]).replace(tzinfo=UTC1).astimezone(UTC)
    assert frame.index[0] == pd.Timestamp(first)
    assert str(frame.index.tz) == "UTC"
    assert frame.index.is_monotonic_increasing


def test_csv_semicolons_decimal_commas_format_and_missing_cells(tmp_path: Path) -> None:
    text = "t;a;b\n01/02/2020 00:00;1,5;\n01/02/2020 00:30;-2,25;NaN\n"
    frame = read_csv(
        _write(tmp_path, text), "t", time_format="%d/%m/%Y %H:%M", delimiter=";", decimal=","
    )
    np.testing.assert_array_equal(frame["a"].to_numpy(), [1.5, -2.25])
    assert np.isnan(frame["b"]).all()
    assert frame.index[1] == pd.Timestamp("2020-02-01 00:30", tz="UTC")


def test_csv_offsets_in_timestamps_win(tmp_path: Path) -> None:
    text = "time,x\n2020-01-01T01:00:00+01:00,1\n2020-01-01T01:30:00+01:00,2\n"
    frame = read_csv(_write(tmp_path, text), "time", time_zone=parse_time_zone("UTC-05:00"))
    assert frame.index[0] == pd.Timestamp("2020-01-01 00:00", tz="UTC")


def test_csv_reads_only_wanted_columns(tmp_path: Path) -> None:
    text = "time,x,comment\n2020-01-01T00:00,1,hello\n2020-01-01T00:30,2,world\n"
    frame = read_csv(_write(tmp_path, text), "time", columns=["x"])
    assert list(frame.columns) == ["x"]


GOOD_HEAD = "time,a,b\n2020-01-01T00:00,1,2\n"
BAD_CSV = [
    ("", {}, "the file is empty"),
    ("time,a,b\n", {}, "has a header but no data rows"),
    (GOOD_HEAD + "2020-01-01T00:30,1\n", {}, "line 3 has 2 fields, the header has 3"),
    (GOOD_HEAD + "2020-01-01T00:30,1,2,3\n", {}, "line 3 has 4 fields"),
    (GOOD_HEAD + "2020-01-01T00:30,abc,2\n", {}, r"line 3, column 'a': 'abc' is not a number"),
    ("time;a\n2020-01-01T00:00;1,5\n", {"delimiter": ";"}, r"decimal commas: set data.decimal"),
    ("time;a;b\n2020-01-01T00:00;1;2\n", {}, r"only one column.*data.delimiter = ';'"),
    ("Time,a\n2020-01-01T00:00,1\n", {}, r"no column 'time' in the file; did you mean 'Time'"),
    (GOOD_HEAD + "not a time,1,2\n", {}, r"line 3: cannot read time 'not a time'.*time_format"),
    (
        GOOD_HEAD + "2020-01-01T00:30,1,2\n2020-01-01T00:20,1,2\n",
        {},
        r"backwards at line 4 \('2020-01-01T00:20'\) after line 3",
    ),
    (GOOD_HEAD + "2020-01-01T00:00,1,2\n", {}, r"line 3 \('2020-01-01T00:00'\) repeats line 2"),
    ("time,a,a\n2020-01-01T00:00,1,2\n", {}, "duplicated column names"),
    (GOOD_HEAD, {"columns": ["c"]}, r"no column 'c'"),
    (
        GOOD_HEAD + "31/01/2020,1,2\n",
        {"time_format": "%Y-%m-%dT%H:%M"},
        r"line 3: cannot read time.*check data.time_format",
    ),
    (
        "time,a\n2013-10-27T02:30,1\n",
        {"time_zone": parse_time_zone("Europe/Brussels")},
        r"line 2 \('2013-10-27T02:30'\): this local time occurs twice.*UTC offsets",
    ),
    (
        "time,a\n2013-03-31T02:30,1\n",
        {"time_zone": parse_time_zone("Europe/Brussels")},
        r"does not exist.*skip an hour on 2013-03-31",
    ),
]


@pytest.mark.parametrize(("text", "kwargs", "match"), BAD_CSV)
def test_csv_malformed(tmp_path: Path, text: str, kwargs: dict, match: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(DataError, match=match) as info:
        read_csv(path, "time", **kwargs)
    assert str(path) in str(info.value)  # the file is named
    assert "\n" not in str(info.value)


def test_csv_binary_and_missing_files(tmp_path: Path) -> None:
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"time,a\x00\x01\n")
    with pytest.raises(DataError, match="NUL bytes"):
        read_csv(binary, "time")
    with pytest.raises(DataError, match="file not found"):
        read_csv(tmp_path / "nope.csv", "time")


def test_symbolic_link_loops_and_broken_links_are_named(tmp_path: Path) -> None:
    (tmp_path / "a.csv").symlink_to("b.csv")
    (tmp_path / "b.csv").symlink_to("a.csv")
    with pytest.raises(DataError) as info:
        read_csv(tmp_path / "a.csv", "time")
    text = info.value.one_line()
    assert "symbolic link loop (a.csv -> b.csv -> a.csv)" in text
    assert "file not found" not in text
    assert "point it at the file itself" in text
    (tmp_path / "up").symlink_to("down")
    (tmp_path / "down").symlink_to("up")  # a loop in a folder of the path
    with pytest.raises(DataError, match="symbolic link loop in a folder on the path"):
        read_parquet(tmp_path / "up" / "x.parquet", "time")
    (tmp_path / "gone.csv").symlink_to("deleted.csv")
    with pytest.raises(DataError, match=r"broken symbolic link to 'deleted\.csv'"):
        read_csv(tmp_path / "gone.csv", "time")
    (tmp_path / "real.csv").write_text("time,a\n2020-01-01 00:00,1\n", encoding="utf-8")
    (tmp_path / "link.csv").symlink_to("real.csv")  # a link to a file is read as the file
    assert read_csv(tmp_path / "link.csv", "time")["a"].tolist() == [1.0]


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be"])
def test_csv_in_utf16_is_read(tmp_path: Path, encoding: str) -> None:
    """Excel's "Unicode text" export (UTF-16, tab-separated) reads like its UTF-8 twin."""
    text = FIXTURE_CSV.read_text(encoding="utf-8").replace(",", "\t")
    path = tmp_path / "export.txt"
    path.write_bytes(text.encode(encoding))
    frame = read_csv(path, "time", time_zone=UTC1, delimiter="\t")
    pd.testing.assert_frame_equal(frame, read_csv(FIXTURE_CSV, "time", time_zone=UTC1))


def test_csv_in_broken_utf16_says_to_resave_as_utf8(tmp_path: Path) -> None:
    path = tmp_path / "export.csv"
    path.write_bytes("time,a\n".encode("utf-16") + b"\x00\xd8")  # a lone surrogate
    with pytest.raises(DataError, match=r"UTF-16.*re-save it as UTF-8"):
        read_csv(path, "time")


def test_csv_epoch_seconds_and_milliseconds(tmp_path: Path) -> None:
    expected = read_csv(FIXTURE_CSV, "time", time_zone=UTC1)
    frame = pd.read_csv(FIXTURE_CSV)
    local = pd.to_datetime(frame["time"]).dt.tz_localize(UTC1)
    seconds = (local - pd.Timestamp("1970-01-01", tz="UTC")).dt.total_seconds()
    for time_format, factor in (("epoch", 1), ("epoch_ms", 1000)):
        frame["time"] = (seconds * factor).astype("int64")
        path = tmp_path / f"{time_format}.csv"
        frame.to_csv(path, index=False)
        # the zone does not matter: Unix times are UTC
        got = read_csv(path, "time", time_format=time_format, time_zone="Asia/Tokyo")
        pd.testing.assert_frame_equal(got, expected, check_index_type=False)
        with pytest.raises(DataError, match=f"set data.time_format = '{time_format}'"):
            read_csv(path, "time")
    with pytest.raises(DataError, match=r"line 2: cannot read time '20.*as seconds.*remove data"):
        read_csv(FIXTURE_CSV, "time", time_format="epoch")


def test_parquet_epoch_seconds(tmp_path: Path) -> None:
    times = pd.date_range("2020-01-01", periods=4, freq="30min", tz="UTC")
    seconds = (times - pd.Timestamp("1970-01-01", tz="UTC")).total_seconds().astype("int64")
    pd.DataFrame({"t": seconds, "x": [1.0, 2.0, 3.0, 4.0]}).to_parquet(tmp_path / "e.parquet")
    frame = read_parquet(tmp_path / "e.parquet", "t", time_format="epoch")
    assert (frame.index == times).all()
    with pytest.raises(DataError, match=r"set data\.time_format = 'epoch'"):
        read_parquet(tmp_path / "e.parquet", "t")


def test_row_labels_travel_with_the_frame(tmp_path: Path) -> None:
    frame = read_csv(FIXTURE_CSV, "time")
    labels = frame.attrs["rows"]
    assert labels.row(0) == f"line 2 ({pd.read_csv(FIXTURE_CSV)['time'][0]!r})"


# --------------------------------------------------------------------------- Parquet


def test_parquet_round_trip_with_time_index(tmp_path: Path) -> None:
    times = pd.date_range("2020-01-01", periods=4, freq="30min", name="time")
    frame = pd.DataFrame({"x": [1.0, 2.0, np.nan, 4.0], "label": list("abcd")}, index=times)
    frame.to_parquet(tmp_path / "d.parquet")
    read = read_parquet(tmp_path / "d.parquet", "time", time_zone=UTC1, columns=["x"])
    assert read.index[0] == pd.Timestamp("2019-12-31 23:00", tz="UTC")
    np.testing.assert_array_equal(read["x"].to_numpy(), frame["x"].to_numpy())
    with pytest.raises(DataError, match=r"line 1, column 'label': 'a' is not a number"):
        read_parquet(tmp_path / "d.parquet", "time", columns=["label"])


def test_parquet_corrupt(tmp_path: Path) -> None:
    path = _write(tmp_path, "not parquet at all", "x.parquet")
    with pytest.raises(DataError, match="cannot read the file as Parquet"):
        read_parquet(path, "time")


# --------------------------------------------------------------------------- Modelica

TABLE = """#1
# a comment line
double tab(3,3)  # rows, columns
  0     20.0  -1.5
  600   21.0  -1.0
  # comment inside
  1200  22.5,  -0.5
"""


def test_modelica_table(tmp_path: Path) -> None:
    path = _write(tmp_path, TABLE, "t.txt")
    frame = read_modelica_table(path, datetime(2013, 1, 1), time_zone=UTC1)
    assert list(frame.columns) == [1, 2]
    assert frame.index[0] == pd.Timestamp("2012-12-31 23:00", tz="UTC")
    assert (frame.index[1] - frame.index[0]) == pd.Timedelta(minutes=10)
    np.testing.assert_array_equal(frame[2].to_numpy(), [-1.5, -1.0, -0.5])


def test_modelica_picks_named_table(tmp_path: Path) -> None:
    text = "double a(1,2)\n0 1\ndouble b(2,2)\n0 5\n60 6\n"
    frame = read_modelica_table(_write(tmp_path, text, "t.txt"), datetime(2020, 1, 1), table="b")
    np.testing.assert_array_equal(frame[1].to_numpy(), [5.0, 6.0])
    with pytest.raises(DataError, match=r"no table 'c' in the file; it has \['a', 'b'\]"):
        read_modelica_table(tmp_path / "t.txt", datetime(2020, 1, 1), table="c")


BAD_TABLES = [
    ("", "the file is empty"),
    ("#1\n", "no table header found"),
    ("#1\n0 1 2\n", r"line 2: expected a header 'double NAME\(ROWS,COLS\)'"),
    ("#1\ndouble t(3,2)\n0 1\n60 2\n", r"declares 3 rows, the file has 2.*truncated"),
    ("#1\ndouble t(2,3)\n0 1 2\n60 2\n", r"line 4 has 2 values, table t\(2,3\) declares 3"),
    ("#1\ndouble t(2,2)\n0 1\n60 x\n", r"line 4: 'x' is not a number"),
    ("#1\ndouble t(2,2)\n0 1,5\n60 2,5\n", r"line 3 has 3 values.*decimal commas"),
    ("#1\ndouble t(2,1)\n0\n60\n", "no data column besides time"),
    ("#1\ndouble t(2,2)\n0 1\n1e12 2\n", r"line 4: time 1000000000000.0 s is not a time"),
    ("#1\ndouble t(2,2)\n60 1\n0 2\n", r"backwards at line 4 \('0'\) after line 3 \('60'\)"),
]


@pytest.mark.parametrize(("text", "match"), BAD_TABLES)
def test_modelica_malformed(tmp_path: Path, text: str, match: str) -> None:
    path = _write(tmp_path, text, "t.txt")
    with pytest.raises(DataError, match=match):
        read_modelica_table(path, datetime(2013, 1, 1))


# --------------------------------------------------------------------------- EPW


def _epw(rows: list[str], tz: str = "1.0") -> str:
    header = [f"LOCATION,Somewhere,,BEL,src,000000,50.8,4.36,{tz},100.0"]
    header += [f"HEADER {i}" for i in range(2, 9)]
    return "\n".join(header + rows) + "\n"


def _row(year: int, month: int, day: int, hour: int, temp: str, ghi: str = "0") -> str:
    fields = ["0"] * len(EPW_FIELDS)
    fields[:6] = [str(year), str(month), str(day), str(hour), "60", "?9"]
    fields[6], fields[EPW_FIELDS.index("ghi")] = temp, ghi
    return ",".join(fields)


def test_epw_hour_ending_time_zone_typical_year_and_missing_codes(tmp_path: Path) -> None:
    rows = [_row(2019, 12, 31, 23, "5.0"), _row(2016, 12, 31, 24, "99.9", "9999")]
    frame = read_epw(_write(tmp_path, _epw(rows), "w.epw"))
    # Hour 23 local (UTC+1) ends at 23:00 local = 22:00 UTC; mixed years go on the first.
    assert frame.index[0] == pd.Timestamp("2019-12-31 22:00", tz="UTC")
    assert frame.index[1] == pd.Timestamp("2019-12-31 23:00", tz="UTC")
    assert frame["temp_air_out"].iloc[0] == 5.0
    assert np.isnan(frame["temp_air_out"].iloc[1])
    assert np.isnan(frame["ghi"].iloc[1])
    assert epw_field(6) == "temp_air_out"
    assert epw_field("ghi") == "ghi"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("LOCATION,x\n", "not an EPW LOCATION line"),
        (_epw([], tz="one"), "time zone 'one' is not a number"),
        (_epw([], tz="50.8"), r"time zone '50.8' is not a UTC offset"),  # found by fuzzing
        (_epw([], tz="nan"), r"time zone 'nan' is not a UTC offset"),
        (_epw([]), "no data rows"),
        (_epw([_row(2019, 1, 1, 1, "1"), "2019,1,1,2,60"]), r"line 10 has 5 fields"),
        (_epw([_row(2019, 1, 1, 25, "1")]), r"line 9: date or time field out of range"),
        (_epw([_row(2019, 2, 30, 1, "1")]), r"invalid date"),
    ],
)
def test_epw_malformed(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(DataError, match=match):
        read_epw(_write(tmp_path, text, "w.epw"))


# --------------------------------------------------------------------------- fuzzing


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(payload=st.binary(max_size=300))
def test_random_bytes_raise_only_data_errors(tmp_path: Path, payload: bytes) -> None:
    path = tmp_path / "fuzz.txt"
    path.write_bytes(payload)
    for read in (
        lambda: read_csv(path, "time"),
        lambda: read_modelica_table(path, datetime(2020, 1, 1)),
    ):
        try:
            frame = read()
        except DataError as exc:
            message = str(exc)
        else:
            message = str(frame.index.tz)  # a file that happens to parse: clock in UTC
            assert message == "UTC"
        assert "\n" not in message


# --------------------------------------------------------------------------- shared data


def _need(path: Path) -> None:
    if not SHARED.is_dir():
        pytest.skip(f"shared data folder {SHARED} is absent (a fresh clone)")
    assert path.is_file(), f"{path} is missing from the shared data"


def test_twin_house_validation_table() -> None:
    _need(TWIN_HOUSE)
    frame = read_modelica_table(TWIN_HOUSE, datetime(2013, 1, 1), time_zone=UTC1)
    assert frame.shape == (5905, 50)  # README: 5905 rows x 51 columns, column 0 is time
    # First row: 20044800 s after 2013-01-01 00:00 UTC+1 (day 232, 21 August local).
    start = datetime(2013, 1, 1, tzinfo=UTC1) + timedelta(seconds=20044800)
    assert frame.index[0] == pd.Timestamp(start)
    assert (np.diff(frame.index.asi8) == 600 * 10**9).all()  # 10 min, no gaps
    with TWIN_HOUSE.open() as f:  # the raw text of the first data row
        first = [float(v) for v in f.readlines()[2].split()]
    assert frame[14].iloc[0] == first[14]  # westfacade_S_IS_T
    assert frame[15].iloc[0] == first[15]


def test_uccle_epw() -> None:
    _need(UCCLE)
    frame = read_epw(UCCLE)
    assert len(frame) == 8760
    # Hour 1 of 1 January, local standard time UTC+1, ends at 00:00 UTC.
    assert frame.index[0].month == 1
    assert frame.index[0].day == 1
    assert frame.index[0].hour == 0
    assert (np.diff(frame.index.asi8) == 3600 * 10**9).all()
    with UCCLE.open() as f:
        first = f.readlines()[8].split(",")
    assert frame["temp_air_out"].iloc[0] == float(first[6])
    assert frame["ghi"].min() >= 0  # no missing-value codes left


def test_time_zone_given_by_name(tmp_path: Path) -> None:
    path = _write(tmp_path, "time,a\n2013-07-01T12:00,1\n2013-07-01T12:30,2\n")
    frame = read_csv(path, "time", time_zone="Europe/Brussels")  # summer time: UTC+2
    assert frame.index[0] == pd.Timestamp("2013-07-01 10:00", tz="UTC")
    with pytest.raises(DataError, match="unknown time zone 'Mars/Olympus'"):
        read_csv(path, "time", time_zone="Mars/Olympus")
