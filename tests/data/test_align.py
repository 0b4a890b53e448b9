"""The study clock (durations, zones, alignment, gaps, periods) and a study's measured data."""

from __future__ import annotations

import shutil
from datetime import UTC, timedelta, timezone
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayescal.clock import format_duration, parse_duration, parse_time_zone
from bayescal.config import load_study
from bayescal.data.align import (
    RowLabels,
    align,
    check_index,
    fill_gaps,
    localize,
    periods_with_gaps,
)
from bayescal.data.measured import load_measured
from bayescal.errors import DataError
from paths import FIXTURES

FIXTURE = FIXTURES / "wall-study"
UTC = UTC
UTC1 = timezone(timedelta(hours=1))
STEP = pd.Timedelta("30min")


def _frame(times: pd.DatetimeIndex, **columns: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame(columns, index=times)


def _utc(start: str, periods: int, freq: str) -> pd.DatetimeIndex:
    return pd.date_range(start, periods=periods, freq=freq, tz="UTC")


# --------------------------------------------------------------------------- parsing


@pytest.mark.parametrize(
    ("text", "seconds"),
    [("30min", 1800), ("1h", 3600), ("1D", 86400), ("10 minutes", 600), ("0min", 0)],
)
def test_parse_duration(text: str, seconds: int) -> None:
    assert parse_duration(text).total_seconds() == seconds


@pytest.mark.parametrize("bad", ["30", 30, "soon", None, True])
def test_parse_duration_refuses_unitless_or_garbage(bad: object) -> None:
    with pytest.raises(ValueError, match="duration"):
        parse_duration(bad)


def test_format_duration() -> None:
    assert format_duration(pd.Timedelta("2 days 06:30:00")) == "2D 6h 30min"
    assert format_duration(timedelta(0)) == "0s"


@pytest.mark.parametrize(
    ("text", "offset_hours"),
    [("UTC", 0), ("UTC+01:00", 1), ("+0530", 5.5), ("UTC-5", -5), ("GMT+2", 2)],
)
def test_fixed_offsets(text: str, offset_hours: float) -> None:
    zone = parse_time_zone(text)
    assert zone.utcoffset(None) == timedelta(hours=offset_hours)


def test_iana_zone_and_suggestion() -> None:
    zone = parse_time_zone("Europe/Brussels")
    winter = pd.Timestamp("2013-01-15 12:00").tz_localize(zone)
    assert winter.utcoffset() == timedelta(hours=1)
    with pytest.raises(ValueError, match="did you mean 'Europe/Brussels'"):
        parse_time_zone("Europe/Brusels")
    with pytest.raises(ValueError, match="beyond"):
        parse_time_zone("UTC+15:00")


def test_zone_abbreviations_get_the_zones_they_mean() -> None:
    """'CST' once got "did you mean 'UCT'": an abbreviation now names its usual zones."""
    with pytest.raises(ValueError, match="abbreviation") as info:
        parse_time_zone("CST")
    message = str(info.value)
    assert "'America/Chicago'" in message
    assert "'UTC-06:00'" in message
    assert "UCT" not in message
    with pytest.raises(ValueError, match="did you mean 'Europe/Brussels'"):
        parse_time_zone("brussels")


# --------------------------------------------------------------------------- index checks


def test_check_index_reports_lines() -> None:
    times = pd.DatetimeIndex(["2020-01-01 00:00", "2020-01-01 01:00", "2020-01-01 00:30"])
    with pytest.raises(DataError, match=r"backwards at lines 12: 2020-01-01 00:30:00 after"):
        check_index(times, "f", np.array([10, 11, 12]))
    with pytest.raises(DataError, match=r"missing or unreadable timestamps at rows 2"):
        check_index(pd.DatetimeIndex(["2020-01-01", None]), "f")


def test_localize_ambiguous_local_time() -> None:
    zone = parse_time_zone("Europe/Brussels")
    times = pd.DatetimeIndex(["2013-10-27 01:30", "2013-10-27 02:30", "2013-10-27 03:30"])
    labels = RowLabels(np.array([7, 8, 9]), np.array(["27/10 01:30", "27/10 02:30", "x"]))
    with pytest.raises(DataError, match=r"line 8 \('27/10 02:30'\): this local time occurs twice"):
        localize(times, zone, "f", labels)
    # the file holds the repeated hour twice, in order: the order tells which is which
    twice = pd.DatetimeIndex(
        ["2013-10-27 02:00", "2013-10-27 02:30", "2013-10-27 02:00", "2013-10-27 02:30"]
    )
    utc = localize(twice, zone, "f")
    assert (np.diff(utc.as_unit("ns").asi8) == pd.Timedelta("30min").value).all()
    with pytest.raises(DataError, match=r"does not exist.*data\.time_zone.*UTC\+01:00"):
        localize(pd.DatetimeIndex(["2013-03-31 02:30"]), zone, "f")
    aware = localize(pd.DatetimeIndex(["2013-10-27 02:30"]), UTC1, "f")
    assert aware[0] == pd.Timestamp("2013-10-27 01:30", tz="UTC")


# --------------------------------------------------------------------------- alignment


@pytest.mark.parametrize(("freq", "step"), [("10min", "30min"), ("30min", "1h"), ("5min", "1h")])
def test_resampling_is_centred_no_time_shift(freq: str, step: str) -> None:
    # A linear ramp: the mean over a centred window equals the ramp at the window's
    # centre, exactly, so any shift of the convention (odd or even ratio) would show.
    times = _utc("2020-01-01 00:00", 200, freq)
    minutes = (times - times[0]).total_seconds() / 60
    out = align(_frame(times, x=2.0 * minutes + 1.0), pd.Timedelta(step), zone=UTC)
    clock_minutes = (out.index - times[0]).total_seconds() / 60
    assert len(out) > 10
    # Tolerance: round-off of sums of a few hundred values of size ~1e3.
    np.testing.assert_allclose(out["x"], 2.0 * clock_minutes + 1.0, rtol=0, atol=1e-9)


def test_resampling_of_a_sinusoid_matches_the_three_point_mean() -> None:
    times = _utc("2020-01-01 00:00", 6 * 24, "10min")
    omega = 2 * np.pi / 86400.0
    t = (times - times[0]).total_seconds().to_numpy()
    out = align(_frame(times, x=np.sin(omega * t)), STEP, zone=UTC)
    tc = (out.index - times[0]).total_seconds().to_numpy()
    # Mean of sin at t-600, t, t+600 s = sin(omega t) (1 + 2 cos(omega 600)) / 3.
    expected = np.sin(omega * tc) * (1 + 2 * np.cos(omega * 600)) / 3
    np.testing.assert_allclose(out["x"], expected, rtol=0, atol=1e-12)  # round-off only


def test_clock_starts_at_first_fully_covered_window_on_local_midnight_grid() -> None:
    # 10-min data from 00:10 local (UTC+1): the grid is anchored at local midnight,
    # the first 30-min window [t-15, t+15) fully inside the data is centred on 00:30.
    times = pd.date_range("2020-01-01 00:10", periods=30, freq="10min").tz_localize(UTC1)
    out = align(_frame(times.tz_convert("UTC"), x=np.ones(30)), STEP, zone=UTC1)
    assert out.index[0] == pd.Timestamp("2020-01-01 00:30").tz_localize(UTC1)
    assert (np.diff(out.index.asi8) == STEP.value).all()


def test_windows_with_too_few_samples_are_missing() -> None:
    times = _utc("2020-01-01 00:00", 18, "10min")
    x = np.arange(18, dtype=float)
    x[[5, 6]] = np.nan  # window centred on 01:00 (samples 5, 6, 7) keeps one of three
    x[9] = np.nan  # window centred on 01:30 (samples 8, 9, 10) keeps two of three
    out = align(_frame(times, x=x), STEP, zone=UTC)
    by_time = out["x"]
    assert np.isnan(by_time[pd.Timestamp("2020-01-01 01:00", tz="UTC")])
    assert by_time[pd.Timestamp("2020-01-01 01:30", tz="UTC")] == pytest.approx((8 + 10) / 2)


def test_equal_step_on_grid_keeps_values_and_missing_rows_become_nan() -> None:
    times = _utc("2020-01-01 00:00", 10, "30min").delete([3, 4])
    out = align(_frame(times, x=np.arange(8.0)), STEP, zone=UTC)
    assert len(out) == 10
    np.testing.assert_array_equal(out["x"].to_numpy()[[0, 1, 2, 5]], [0.0, 1.0, 2.0, 3.0])
    assert np.isnan(out["x"].to_numpy()[[3, 4]]).all()


@pytest.mark.parametrize(
    ("times", "kwargs", "match"),
    [
        (_utc("2020-01-01", 10, "1h"), {}, "sampled every 1h, coarser than the study step 30min"),
        (_utc("2020-01-01 00:15", 10, "30min"), {}, r"not on the study clock.*data.start ="),
        (
            _utc("2020-01-01 00:00", 10, "30min"),
            {"start": pd.Timestamp("2019-12-31 23:00", tz="UTC")},
            "before the data cover it",
        ),
        (
            _utc("2020-01-01 00:00", 10, "30min"),
            {"end": pd.Timestamp("2020-01-02", tz="UTC")},
            "after the end of the data",
        ),
        (_utc("2020-01-01 00:00", 1, "30min"), {}, "at least two samples"),
    ],
)
def test_alignment_errors(times: pd.DatetimeIndex, kwargs: dict, match: str) -> None:
    with pytest.raises(DataError, match=match):
        align(_frame(times, x=np.zeros(len(times))), STEP, zone=UTC, **kwargs)


def test_start_fixes_the_grid_and_end_is_exclusive() -> None:
    times = _utc("2020-01-01 00:15", 10, "30min")
    out = align(
        _frame(times, x=np.arange(10.0)),
        STEP,
        zone=UTC1,
        start=pd.Timestamp("2020-01-01 01:45"),  # naive: local UTC+1, i.e. 00:45 UTC
        end=pd.Timestamp("2020-01-01 03:15", tz="UTC"),
    )
    assert out.index[0] == pd.Timestamp("2020-01-01 00:45", tz="UTC")
    assert out.index[-1] == pd.Timestamp("2020-01-01 02:45", tz="UTC")
    np.testing.assert_array_equal(out["x"], [1.0, 2.0, 3.0, 4.0, 5.0])


def _jittered(n: int, seed: int = 5) -> pd.DatetimeIndex:
    """A 30-min logger whose clock wanders by up to ±4 min, to the second."""
    jitter = np.random.default_rng(seed).integers(-240, 241, n)
    jitter[0] = 0
    return _utc("2020-01-01", n, "30min") + pd.to_timedelta(jitter, unit="s")


def test_a_jittering_clock_is_detected_and_resampling_offered() -> None:
    times = _jittered(200)
    labels = RowLabels(np.arange(2, 202), np.array([f"{t:%d/%m %H:%M:%S}" for t in times]))
    with pytest.raises(DataError, match=r"jitter around the study step 30min.*data\.resample"):
        align(_frame(times, x=np.zeros(200)), STEP, zone=UTC, labels=labels)


def test_linear_resampling_puts_a_jittering_clock_on_the_grid() -> None:
    times = _jittered(200)
    seconds = (times - times[0]).total_seconds().to_numpy()
    ramp = 3.0 * seconds / 3600 + 1.0  # a ramp: linear interpolation is exact
    x = ramp.copy()
    x[50] = np.nan  # a missing value and a missing row: the samples around each lie
    frame = _frame(times.delete(120), x=np.delete(x, 120))  # over 1.5 steps apart
    out = align(frame, STEP, zone=UTC, resample="linear")
    clock = (out.index - times[0]).total_seconds().to_numpy()
    assert out.index[0] == times[0]
    assert (np.diff(out.index.as_unit("ns").asi8) == STEP.value).all()
    got = out["x"].to_numpy()
    missing = np.isnan(got)
    assert 2 <= missing.sum() <= 4  # the instants between those samples, 1 or 2 each
    assert all(min(abs(c - 50 * 1800), abs(c - 120 * 1800)) <= 1800 for c in clock[missing])
    # Tolerance: float round-off of the interpolation weights of values ~ 300.
    np.testing.assert_allclose(got[~missing], 3.0 * clock[~missing] / 3600 + 1.0, atol=1e-9)


def test_a_few_rows_off_the_clock_are_named_and_the_clock_is_not_moved() -> None:
    """A stray 05:45 in half-hourly data: name its line, offer to remove or correct it
    (or to interpolate), not to start the clock on it (every other row would be off)."""
    times = _utc("2020-01-01 00:00", 48, "30min")
    stray = times.to_numpy().copy()
    stray[11] += np.timedelta64(15, "m")  # 05:30 -> 05:45
    shifted = pd.DatetimeIndex(stray)
    texts = np.array([f"{t:%Y-%m-%d %H:%M}" for t in shifted.tz_convert(UTC)])
    labels = RowLabels(np.arange(2, 50), texts)
    with pytest.raises(DataError) as info:
        align(_frame(shifted, x=np.zeros(48)), STEP, zone=UTC, labels=labels)
    message = str(info.value)
    assert "the timestamp on line 13 ('2020-01-01 05:45') is not on the study clock" in message
    assert "remove or correct that row in the file" in message
    assert "data.resample = 'linear'" in message
    assert "data.start" not in message
    stray[30] += np.timedelta64(10, "m")  # a second one: both named, still not a shift
    with pytest.raises(DataError) as info:
        align(_frame(pd.DatetimeIndex(stray), x=np.zeros(48)), STEP, zone=UTC)
    message = str(info.value)
    assert "the timestamps 2020-01-01 05:45 (UTC), 2020-01-01 15:10 (UTC) are not" in message
    assert "remove or correct those 2 rows" in message
    assert "data.start" not in message
    # the other remedy offered works: the samples interpolated onto the clock
    out = align(_frame(shifted, x=np.arange(48.0)), STEP, zone=UTC, resample="linear")
    assert len(out) == 48


def test_a_shifted_record_is_not_jitter_and_errors_show_local_times() -> None:
    times = _utc("2020-01-01 00:15", 10, "30min")
    labels = RowLabels(np.arange(2, 12), np.array([f"{t:%H:%M}" for t in times.tz_convert(UTC1)]))
    with pytest.raises(DataError) as info:
        align(_frame(times, x=np.zeros(10)), STEP, zone=UTC1, labels=labels)
    message = str(info.value)
    assert "the timestamps on line 3 ('01:45'), line 4 ('02:15')" in message
    assert "not on the study clock (instants 2020-01-01 01:30 (UTC+01:00) + k × 30min)" in message
    assert "data.start = '2020-01-01T01:45:00'" in message  # a local time, as data.start takes
    with pytest.raises(DataError, match=r"data\.start 2020-01-01 00:00 \(UTC\+01:00\) is before"):
        align(
            _frame(times, x=np.zeros(10)),
            STEP,
            zone=UTC1,
            start=pd.Timestamp("2020-01-01 00:00"),
            labels=labels,
        )


# --------------------------------------------------------------------------- gaps


def test_fill_gaps_interpolates_short_gaps_only() -> None:
    times = _utc("2020-01-01", 20, "30min")
    ramp = np.arange(20, dtype=float) * 0.5
    a, b = ramp.copy(), ramp.copy()
    a[[3, 4]] = np.nan  # 1 h gap: interpolated with max 1 h
    a[[10, 11, 12]] = np.nan  # 1.5 h gap: left missing
    b[[3, 4]] = np.nan  # same run as a's: reported once for both columns
    b[0] = np.nan  # at the edge: nothing to interpolate from
    filled, gaps = fill_gaps(_frame(times, a=a, b=b), pd.Timedelta("1h"))
    np.testing.assert_allclose(filled["a"].to_numpy()[[3, 4]], ramp[[3, 4]], atol=1e-12)
    assert np.isnan(filled["a"].to_numpy()[[10, 11, 12]]).all()
    assert np.isnan(filled["b"].to_numpy()[0])
    summary = [(g.columns, g.samples, g.length, g.interpolated) for g in gaps]
    assert summary == [
        (("b",), 1, pd.Timedelta("30min"), False),
        (("a", "b"), 2, pd.Timedelta("1h"), True),
        (("a",), 3, pd.Timedelta("90min"), False),
    ]
    assert gaps[2].first == times[10]
    assert gaps[2].last == times[12]
    assert "left missing" in gaps[2].describe()


def test_no_interpolation_by_default() -> None:
    times = _utc("2020-01-01", 6, "30min")
    x = np.array([1.0, np.nan, 3.0, 4.0, 5.0, 6.0])
    filled, gaps = fill_gaps(_frame(times, x=x), pd.Timedelta(0))
    assert np.isnan(filled["x"].iloc[1])
    assert not gaps[0].interpolated


def test_periods_with_gaps_matches_a_direct_check() -> None:
    rng = np.random.default_rng(3)
    missing = rng.random(500) < 0.01
    starts = np.arange(10, 450, 48)
    expected = [missing[s : s + 48].any() for s in starts]
    np.testing.assert_array_equal(periods_with_gaps(missing, starts, 48), expected)


# --------------------------------------------------------------------------- measured data


def _study_copy(tmp_path: Path, csv_edit=None, toml_edit=None) -> Path:  # type: ignore[no-untyped-def]
    folder = tmp_path / "study"
    shutil.copytree(FIXTURE, folder)
    if csv_edit is not None:
        frame = pd.read_csv(folder / "wall.csv")
        csv_edit(frame)
        frame.to_csv(folder / "wall.csv", index=False)
    if toml_edit is not None:
        text = (folder / "study.toml").read_text()
        (folder / "study.toml").write_text(toml_edit(text))
    return folder


def test_load_measured_fixture() -> None:
    study = load_study(FIXTURE)
    measured = load_measured(study)
    raw = pd.read_csv(FIXTURE / "wall.csv")
    assert measured.n == len(raw) == 288
    assert measured.step == 1800.0
    np.testing.assert_array_equal(measured.outputs["heat_flux_in"], raw["q_si"])
    np.testing.assert_array_equal(measured.forcing["temp_surf_out"], raw["T_se"])
    assert set(measured.forcing.series) == {"temp_surf_out", "temp_surf_in"}
    # Local 2012-02-01 00:00 at UTC+1 is 2012-01-31 23:00 UTC.
    assert measured.times[0] == np.datetime64("2012-01-31T23:00:00")
    assert measured.forcing.start == measured.times[0]
    lay = measured.layout  # 6 days: warm-up 1 day, 4 daily periods, 48-sample test window
    assert (lay.m_star, lay.period, lay.test) == (4, 48, 48)
    assert measured.gaps == ()


def test_units_scale_and_sign_are_applied(tmp_path: Path) -> None:
    def to_fahrenheit(frame: pd.DataFrame) -> None:
        frame["T_se"] = frame["T_se"] * 9 / 5 + 32

    def edit(text: str) -> str:
        text = text.replace('source = "T_se"\nunit = "degC"', 'source = "T_se"\nunit = "degF"')
        return text.replace('unit = "W/m2"', 'unit = "W/m2"\nsign = -1\nscale = 2.0')

    study = load_study(_study_copy(tmp_path, to_fahrenheit, edit))
    measured = load_measured(study)
    raw = pd.read_csv(FIXTURE / "wall.csv")
    np.testing.assert_allclose(measured.forcing["temp_surf_out"], raw["T_se"], atol=1e-9)
    np.testing.assert_allclose(measured.outputs["heat_flux_in"], -2.0 * raw["q_si"], atol=1e-12)


def test_output_gaps_are_reported_and_their_periods_dropped(tmp_path: Path) -> None:
    def hole(frame: pd.DataFrame) -> None:
        frame.loc[100:103, "q_si"] = np.nan  # inside the second training period

    measured = load_measured(load_study(_study_copy(tmp_path, hole)))
    assert len(measured.gaps) == 1
    assert measured.gaps[0].columns == ("heat_flux_in",)
    assert measured.gaps[0].samples == 4
    assert not measured.gaps[0].interpolated
    assert measured.layout.m_star == 3
    assert measured.layout.dropped_starts.tolist() == [96]


def test_a_boundary_condition_gap_drops_the_periods_it_touches(tmp_path: Path) -> None:
    """One missing row of a boundary condition: bridged for the simulator, its period
    dropped (what the docs say of gaps), and the setting that interpolates it named."""

    def hole(frame: pd.DataFrame) -> None:
        frame.loc[100, "T_si"] = np.nan  # inside the second training period [96, 144)

    folder = _study_copy(tmp_path, hole)
    measured = load_measured(load_study(folder))
    (gap,) = measured.gaps
    assert gap.bridged
    assert not gap.interpolated
    assert gap.where == "file line 102"  # header, then row 0 on line 2
    raw = pd.read_csv(FIXTURE / "wall.csv")["T_si"].to_numpy()
    assert measured.forcing["temp_surf_in"][100] == pytest.approx((raw[99] + raw[101]) / 2)
    assert np.isnan(measured.outputs["heat_flux_in"][100])  # measured against invented inputs
    assert measured.layout.dropped_starts.tolist() == [96]
    assert measured.layout.m_star == 3
    assert "bridged for the simulator, its periods dropped" in gap.describe()
    text = (folder / "study.toml").read_text()
    (folder / "study.toml").write_text(
        text.replace('step = "30min"', 'step = "30min"\nmax_gap_interpolate = "30min"')
    )
    measured = load_measured(load_study(folder))
    assert measured.gaps[0].interpolated
    assert measured.layout.m_star == 4
    assert np.isfinite(measured.outputs["heat_flux_in"]).all()


def test_after_a_boundary_gap_longer_than_a_period_the_warm_up_is_dropped(
    tmp_path: Path,
) -> None:
    def hole(frame: pd.DataFrame) -> None:
        frame.loc[60:120, "T_se"] = np.nan  # 61 samples, over one period (48)

    # No test window, so that two periods are left (a calibration needs two).
    no_test = _study_copy(
        tmp_path, hole, lambda t: t.replace("test_samples = 48", "test_samples = 0")
    )
    measured = load_measured(load_study(no_test))
    # touched: [48, 96), [96, 144); the warm-up of 48 samples after sample 120: [144, 192)
    assert measured.layout.dropped_starts.tolist() == [48, 96, 144]
    assert measured.layout.train_starts.tolist() == [192, 240]
    assert np.isfinite(measured.forcing["temp_surf_out"]).all()


def test_a_boundary_gap_over_every_period_is_an_error(tmp_path: Path) -> None:
    def hole(frame: pd.DataFrame) -> None:
        frame.loc[50:230, "T_se"] = np.nan

    with pytest.raises(DataError, match=r"all 4 training periods.*data\.max_gap_interpolate"):
        load_measured(load_study(_study_copy(tmp_path, hole)))


def test_too_short_record(tmp_path: Path) -> None:
    folder = _study_copy(
        tmp_path, toml_edit=lambda t: t.replace("test_samples = 48", "test_samples = 200")
    )
    with pytest.raises(
        DataError, match=r"the record is 6D \(288 samples\) long; it must be at least"
    ):
        load_measured(load_study(folder))


def test_finer_data_are_averaged(tmp_path: Path) -> None:
    folder = _study_copy(
        tmp_path,
        toml_edit=lambda t: t.replace('step = "30min"', 'step = "1h"').replace(
            "test_samples = 48", "test_samples = 24"
        ),
    )
    measured = load_measured(load_study(folder))
    raw = pd.read_csv(FIXTURE / "wall.csv")["q_si"].to_numpy()
    # The 1-h window centred on local 01:00 (the first one inside the record) holds the
    # samples at 00:30 and 01:30 on its edges (half weight each) and 01:00.
    expected = (raw[1] / 2 + raw[2] + raw[3] / 2) / 2
    assert measured.outputs["heat_flux_in"][0] == pytest.approx(expected, rel=1e-12)
    assert measured.step == 3600.0


EPW_STUDY = """
[study]
name = "epw-box"
[data]
file = "w.epw"
step = "1h"
[data.columns.temp_air_out]
source = "temp_air_out"
unit = "degC"
[data.columns.temp_air_in]
source = 7
unit = "degC"
[data.columns.ghi]
source = "ghi"
unit = "W/m2"
[data.columns.dhi]
source = "dhi"
unit = "W/m2"
[data.columns.wind_speed]
source = "wind_speed"
unit = "m/s"
[simulator]
type = "box"
mode = "freefloat"
latitude = 19.0
longitude = 72.8
[parameters.k_wall]
unit = "W/(m·K)"
nominal = 0.125
prior = { distribution = "uniform", lower = 0.05, upper = 0.2 }
targets = ["k_wall"]
[outputs]
calibrate = ["temp_air_in"]
[periods]
length = "1D"
warmup = "0min"
test_samples = 24
"""


def test_epw_study_uses_the_files_time_zone(tmp_path: Path) -> None:
    # A half-hour offset (UTC+05:30): hourly records end at whole local hours, i.e. at
    # half past in UTC; the clock must follow the file's zone, not UTC.
    header = ["LOCATION,Mumbai,,IND,src,000000,19.0,72.8,5.5,10.0"]
    header += [f"HEADER {i}" for i in range(2, 9)]
    rows = []
    for day in range(1, 4):
        for hour in range(1, 25):
            fields = ["0"] * 35
            fields[:6] = ["2021", "3", str(day), str(hour), "60", "?"]
            fields[6], fields[7] = f"{20 + hour / 10:.1f}", f"{10 + hour / 10:.1f}"
            rows.append(",".join(fields))
    (tmp_path / "w.epw").write_text("\n".join(header + rows) + "\n")
    (tmp_path / "study.toml").write_text(EPW_STUDY)
    measured = load_measured(load_study(tmp_path))
    assert measured.times[0] == np.datetime64("2021-02-28T19:30:00")  # 01:00 local
    assert measured.n == 72
    np.testing.assert_allclose(measured.forcing["temp_air_out"][:3], [20.1, 20.2, 20.3])
    np.testing.assert_allclose(measured.outputs["temp_air_in"][:3], [10.1, 10.2, 10.3])
