"""The EPW writer: layout, time convention, fills, and a round trip through the reader.

That EnergyPlus itself reads the files is tested in ``test_energyplus.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.constants import Stefan_Boltzmann, zero_Celsius
from scipy.optimize import brentq

from bayescal.errors import DataError
from bayescal.simulators.base import Forcing
from bayescal.simulators.epw import (
    EpwSite,
    clark_allen_ir,
    dew_point,
    epw_table,
    standard_pressure,
    write_epw,
)

SITE = EpwSite(latitude=50.8, longitude=4.35, time_zone=1.0, elevation=100.0, city="Uccle")
STEP = 1800.0


def _forcing(series: dict[str, np.ndarray], start: str = "2021-03-10T00:00") -> Forcing:
    return Forcing(STEP, series, start=np.datetime64(start))


def _buck_saturation(temp: float) -> float:
    """Saturation vapour pressure over water, Buck (1981) [hPa]: a second, independent formula."""
    return 6.1121 * np.exp((18.678 - temp / 234.5) * (temp / (257.14 + temp)))


@pytest.mark.parametrize(("temp", "rh"), [(20.0, 50.0), (0.0, 80.0), (30.0, 30.0), (-10.0, 90.0)])
def test_dew_point_agrees_with_buck(temp: float, rh: float) -> None:
    target = rh / 100 * _buck_saturation(temp)
    expected = brentq(lambda td: _buck_saturation(td) - target, -60.0, 60.0)
    # Magnus and Buck fits differ by < 0.1 K over -40..50 °C.
    assert dew_point(np.array(temp), np.array(rh)) == pytest.approx(expected, abs=0.1)


def test_dew_point_at_saturation_is_the_air_temperature() -> None:
    temps = np.array([-5.0, 10.0, 25.0])
    np.testing.assert_allclose(dew_point(temps, np.full(3, 100.0)), temps, atol=1e-12)


def test_clark_allen_ir_clear_sky_at_zero_dew_point() -> None:
    # ln(T_dp / 273.15) = 0 and no cloud: emissivity 0.787 (Clark and Allen 1978).
    ir = clark_allen_ir(np.array(10.0), np.array(0.0), sky_cover=0.0)
    assert ir == pytest.approx(0.787 * Stefan_Boltzmann * (10.0 + zero_Celsius) ** 4, rel=1e-12)


def test_standard_pressure() -> None:
    assert standard_pressure(0.0) == pytest.approx(101325.0)
    # ICAO standard atmosphere table: 89 875 Pa at 1000 m (table rounding: 1 Pa).
    assert standard_pressure(1000.0) == pytest.approx(89875.0, abs=2.0)


def test_layout_and_hour_convention() -> None:
    n = 48 * 3
    table = epw_table(_forcing({"temp_air_out": np.full(n, 5.0)}), SITE)
    assert len(table) == 8760
    assert table.shape[1] == 35
    first, last = table.iloc[0], table.iloc[-1]
    # Hour 1 is the hour ending 01:00, stamped minute 60; the last is 31 Dec hour 24.
    assert (first["month"], first["day"], first["hour"], first["minute"]) == (1, 1, 1, 60)
    assert (last["month"], last["day"], last["hour"], last["minute"]) == (12, 31, 24, 60)
    sub = epw_table(_forcing({"temp_air_out": np.full(n, 5.0)}), SITE, records_per_hour=2)
    assert list(sub["minute"][:4]) == [30, 60, 30, 60]
    assert list(sub["hour"][:4]) == [1, 1, 2, 2]


def test_leap_year_has_february_29() -> None:
    table = epw_table(_forcing({"temp_air_out": np.zeros(48)}, "2020-06-01T00:00"), SITE)
    assert len(table) == 8784
    assert ((table["month"] == 2) & (table["day"] == 29)).sum() == 24


def test_instants_and_interval_means() -> None:
    # A temperature and a GHI that are linear in time: the record value at the hour's end
    # and the hourly mean (= value at mid-hour) are known exactly.
    n = 48 * 2
    t = np.arange(n) * STEP
    temp = 2.0 + t / 3600.0 * 0.1
    ghi = 100.0 + t / 3600.0 * 2.0
    forcing = _forcing({"temp_air_out": temp, "ghi": ghi, "dhi": ghi, "dni": np.zeros(n)})
    table = epw_table(forcing, SITE)
    # The forcing starts 2021-03-10 00:00 UTC = 01:00 local; record k ends k+1 h after
    # 1 January 00:00 local.
    start_local = (np.datetime64("2021-03-10T01:00") - np.datetime64("2021-01-01T00:00")) / (
        np.timedelta64(1, "h")
    )
    rows = np.arange(int(start_local) + 1, int(start_local) + 40)  # inside the forcing
    hours_after_start = rows + 1 - start_local
    np.testing.assert_allclose(table["temp_air"].to_numpy()[rows], 2.0 + 0.1 * hours_after_start)
    np.testing.assert_allclose(
        table["ghi"].to_numpy()[rows], 100.0 + 2.0 * (hours_after_start - 0.5), rtol=1e-12
    )


def test_fills_for_absent_series() -> None:
    table = epw_table(_forcing({"temp_air_out": np.full(48, 12.0)}), SITE)
    np.testing.assert_allclose(table["relative_humidity"], 70.0)
    np.testing.assert_allclose(table["pressure"], standard_pressure(SITE.elevation))
    np.testing.assert_allclose(table["wind_speed"], 0.0)
    np.testing.assert_allclose(table["ghi"], 0.0)
    expected_ir = clark_allen_ir(np.array(12.0), dew_point(np.array(12.0), np.array(70.0)))
    np.testing.assert_allclose(table["ir_horizontal"], expected_ir)


def test_sky_temperature_gives_black_body_ir() -> None:
    forcing = _forcing({"temp_air_out": np.full(48, 5.0), "temp_sky": np.full(48, -20.0)})
    table = epw_table(forcing, SITE)
    np.testing.assert_allclose(table["ir_horizontal"], Stefan_Boltzmann * (253.15**4))


def test_ghi_alone_is_split_consistently() -> None:
    n = 48 * 3
    d = np.arange(n) * STEP / 86400.0
    ghi = np.clip(600.0 * np.sin(2 * np.pi * (d - 0.3)), 0.0, None)
    table = epw_table(_forcing({"temp_air_out": np.full(n, 10.0), "ghi": ghi}), SITE)
    # Closure ghi = dhi + dni cos(zenith) at the records' mid-times (zenith < 80°).
    import pandas as pd
    import pvlib

    year = pd.Timestamp("2021-01-01") - pd.Timedelta(hours=SITE.time_zone)
    mid = pd.DatetimeIndex(year + pd.to_timedelta(np.arange(8760) + 0.5, unit="h"), tz="UTC")
    zenith = pvlib.solarposition.get_solarposition(mid, SITE.latitude, SITE.longitude)[
        "apparent_zenith"
    ].to_numpy()
    up = (zenith < 80) & (table["ghi"].to_numpy() > 1)
    assert up.sum() > 20
    closure = table["dhi"] + table["dni"] * np.cos(np.radians(zenith))
    # The altitude passed to pvlib differs (100 m vs 0 m): < 0.01° of zenith.
    np.testing.assert_allclose(closure[up], table["ghi"][up], rtol=1e-3, atol=0.5)


def test_forcing_across_new_year_is_rejected() -> None:
    with pytest.raises(DataError, match="calendar year"):
        epw_table(_forcing({"temp_air_out": np.zeros(96)}, "2021-12-31T12:00"), SITE)


def test_bad_records_per_hour_is_rejected() -> None:
    with pytest.raises(DataError, match="divide 60"):
        epw_table(_forcing({"temp_air_out": np.zeros(48)}), SITE, records_per_hour=7)


def test_header(tmp_path: Path) -> None:
    path = write_epw(tmp_path / "w.epw", _forcing({"temp_air_out": np.zeros(48)}), SITE)
    lines = path.read_text().splitlines()
    assert lines[0].split(",")[:2] == ["LOCATION", "Uccle"]
    assert [float(x) for x in lines[0].split(",")[6:10]] == [50.8, 4.35, 1.0, 100.0]
    assert lines[7] == "DATA PERIODS,1,1,Data,Friday,1/1,12/31"  # 1 January 2021 was a Friday
    assert len(lines) == 8 + 8760
    assert all(len(line.split(",")) == 35 for line in lines[8:])


@pytest.mark.parametrize("records_per_hour", [1, 2])
def test_round_trip_through_the_reader(tmp_path: Path, records_per_hour: int) -> None:
    readers = pytest.importorskip("bayescal.data.readers")
    if not hasattr(readers, "read_epw"):
        pytest.skip("bayescal.data.readers.read_epw is not available")
    n = 48 * 4
    t = np.arange(n) * STEP
    series = {
        "temp_air_out": 5.0 + 5.0 * np.sin(2 * np.pi * t / 86400.0),
        "relative_humidity": 60.0 + 10.0 * np.cos(2 * np.pi * t / 86400.0),
        "wind_speed": 2.0 + np.sin(t / 86400.0),
    }
    forcing = _forcing(series)
    path = write_epw(tmp_path / "w.epw", forcing, SITE, records_per_hour=records_per_hour)
    frame = readers.read_epw(path)
    # The reader stamps records with their end, in UTC; pick the forcing's instants.
    stamps = frame.index.tz_convert("UTC").tz_localize(None).to_numpy().astype("datetime64[s]")
    position = np.searchsorted(stamps, forcing.times)
    on_grid = stamps[np.clip(position, 0, len(stamps) - 1)] == forcing.times
    every = 2 // records_per_hour  # hourly records hold every other half-hourly sample
    assert on_grid.sum() == n // every
    rows = frame.iloc[position[on_grid]]
    # Tolerances: the file's rounding (0.01 K, 0.1 %, 0.01 m/s).
    for name, tol in (("temp_air_out", 0.006), ("relative_humidity", 0.06), ("wind_speed", 0.006)):
        np.testing.assert_allclose(rows[name], series[name][on_grid], atol=tol, err_msg=name)
