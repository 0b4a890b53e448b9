"""Write EnergyPlus weather (EPW) files from measured boundary-condition series.

EnergyPlus reads its outdoor conditions from an EPW file. :func:`write_epw`
builds one from a :class:`~bayescal.simulators.base.Forcing`: one record per
``1 / records_per_hour`` hour for the whole calendar year (local standard time)
that contains the forcing, so that any run period inside the forcing is covered.

Time convention
---------------
EPW records are stamped with the *end* of their interval: hour ``h`` (1–24)
is the hour from ``h - 1`` to ``h`` o'clock local standard time (with several
records per hour, record ``j`` of the hour ends ``(j + 1) * 60 / rph`` minutes
after ``h - 1`` o'clock; the minute field holds that end). The forcing's clock
is UTC; local standard time is UTC plus the site's ``time_zone`` hours.

* Instantaneous quantities (dry-bulb temperature, humidity, pressure, wind,
  long-wave irradiance) take the value of the forcing at the record's end,
  interpolated linearly between samples, as EnergyPlus treats them.
* Solar irradiances are energies over the interval [Wh/m²]: they are the exact
  mean of the linearly interpolated forcing over the record's interval.

Outside the forcing's span every series holds its first or last value; those
records only feed EnergyPlus's warm-up and the unused ends of the first and
last simulated days.

Fill values for absent series
-----------------------------
``temp_air_out``
    :data:`FILL` ``["temp_air_out"]`` = 10 °C.
``relative_humidity``
    70 %; the dew point is computed from dry bulb and relative humidity with
    the Magnus formula (Alduchov and Eskridge 1996).
``pressure``
    Standard atmosphere at the site elevation.
``ghi``, ``dni``, ``dhi``
    All three given: used as they are. Two given: the third from the closure
    ``ghi = dhi + dni cos(zenith)``. Only ``ghi``: split with the Erbs model
    (``pvlib.irradiance.erbs``). None: zero.
``ir_horizontal``
    From ``temp_sky`` as ``sigma T_sky^4`` if given, else the Clark–Allen sky
    emissivity EnergyPlus itself uses, with an opaque sky cover of
    :data:`FILL` ``["sky_cover"]`` = 5 tenths.
``wind_speed``, ``wind_direction``
    0 m/s and 0° (no forced convection rather than an invented wind).

Fields EnergyPlus does not use in its heat balance (illuminances, visibility,
ceiling height, present weather, precipitation) are written with neutral
values.
"""

from __future__ import annotations

import calendar
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pvlib
from scipy.constants import Stefan_Boltzmann, zero_Celsius

from bayescal.errors import DataError
from bayescal.simulators.base import Forcing

FILL: Mapping[str, float] = {
    "temp_air_out": 10.0,
    "relative_humidity": 70.0,
    "wind_speed": 0.0,
    "wind_direction": 0.0,
    "sky_cover": 5.0,
    "albedo": 0.2,
}
"""Values written where the forcing has no series (glossary units; sky cover in tenths)."""

_SECONDS_PER_DAY = 86400.0
_MIN_COS_ZENITH = 0.065  # below this (zenith > ~86°) DNI from closure is unstable: set to 0


@dataclass(frozen=True)
class EpwSite:
    """Where the weather applies (the EPW ``LOCATION`` line).

    Parameters
    ----------
    latitude
        Latitude, north positive. [°]
    longitude
        Longitude, east positive. [°]
    time_zone
        Offset of local standard time from UTC. [h]
    elevation
        Height above sea level. [m]
    city
        Name written in the header.
    """

    latitude: float
    longitude: float
    time_zone: float = 0.0
    elevation: float = 0.0
    city: str = "bayescal"


def read_epw_site(path: str | Path) -> EpwSite:
    """Location and time zone from the ``LOCATION`` line of an EPW file.

    Raises
    ------
    DataError
        If the first line is not an EPW ``LOCATION`` line.
    """
    with Path(path).open(encoding="latin-1") as handle:
        fields = handle.readline().split(",")
    try:
        lat, lon, zone, elevation = (float(f) for f in fields[6:10])
    except ValueError:
        raise DataError("the first line is not an EPW LOCATION line", source=str(path)) from None
    return EpwSite(lat, lon, zone, elevation, city=fields[1])


def local_year(forcing: Forcing, time_zone: float) -> int:
    """Calendar year (local standard time) that holds the whole forcing.

    Raises
    ------
    DataError
        If the forcing crosses a new year in local standard time.
    """
    offset = np.timedelta64(round(time_zone * 3600), "s")
    times = forcing.times + offset
    first = int(str(times[0])[:4])
    last = int(str(times[-1])[:4])
    if first != last:
        raise DataError(
            f"the forcing spans {first}-{last} in local standard time; an EPW and an "
            "EnergyPlus schedule file hold one calendar year",
            hint="split the record at the new year",
        )
    return first


def seconds_in_year(forcing: Forcing, year: int, time_zone: float) -> np.ndarray:
    """Forcing sample instants as seconds since 1 January ``year`` 00:00 local standard time. [s]"""
    start = np.datetime64(f"{year:04d}-01-01T00:00:00", "s") - np.timedelta64(
        round(time_zone * 3600), "s"
    )
    return (forcing.times - start).astype(float)


def dew_point(temp_air: np.ndarray, relative_humidity: np.ndarray) -> np.ndarray:
    """Dew-point temperature by the Magnus formula (Alduchov and Eskridge 1996).

    Parameters
    ----------
    temp_air
        Dry-bulb temperature. [°C]
    relative_humidity
        Relative humidity, clipped to 1–100. [%]

    Returns
    -------
    numpy.ndarray
        Dew-point temperature. [°C]
    """
    a, b = 17.625, 243.04
    gamma = np.log(np.clip(relative_humidity, 1.0, 100.0) / 100.0) + a * temp_air / (b + temp_air)
    return b * gamma / (a - gamma)


def clark_allen_ir(
    temp_air: np.ndarray, temp_dew: np.ndarray, sky_cover: float = FILL["sky_cover"]
) -> np.ndarray:
    """Horizontal long-wave irradiance from the Clark–Allen sky emissivity.

    Parameters
    ----------
    temp_air
        Dry-bulb temperature. [°C]
    temp_dew
        Dew-point temperature. [°C]
    sky_cover
        Opaque sky cover. [tenths]

    Returns
    -------
    numpy.ndarray
        Horizontal infrared irradiance from the sky. [W/m²]
    """
    n = sky_cover
    emissivity = (0.787 + 0.764 * np.log((temp_dew + zero_Celsius) / zero_Celsius)) * (
        1.0 + 0.0224 * n - 0.0035 * n**2 + 0.00028 * n**3
    )
    return emissivity * Stefan_Boltzmann * (temp_air + zero_Celsius) ** 4


def standard_pressure(elevation: float) -> float:
    """Pressure of the standard atmosphere at ``elevation`` [m]. [Pa]"""
    return 101325.0 * (1.0 - 2.25577e-5 * elevation) ** 5.25588


def _at(s: np.ndarray, v: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Linear interpolation of samples ``(s, v)`` at ``x``, holding the end values."""
    return np.interp(x, s, v)


def _interval_mean(s: np.ndarray, v: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact mean over ``[a, b]`` of the linear interpolant of ``(s, v)`` held at the ends."""
    cumulative = np.concatenate(([0.0], np.cumsum(np.diff(s) * (v[1:] + v[:-1]) / 2.0)))

    def integral(x: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(s, x, side="right") - 1, 0, len(s) - 1)
        xk = np.clip(x, s[0], s[-1])
        inside = cumulative[k] + (xk - s[k]) * (v[k] + np.interp(xk, s, v)) / 2.0
        below = np.minimum(x - s[0], 0.0) * v[0]
        above = np.maximum(x - s[-1], 0.0) * v[-1]
        return inside + below + above

    return (integral(b) - integral(a)) / (b - a)


def _solar_fields(
    forcing: Forcing,
    s: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    times_utc: pd.DatetimeIndex,
    site: EpwSite,
) -> dict[str, np.ndarray]:
    """GHI, DNI, DHI and extraterrestrial irradiance, means over each record. [W/m²]"""
    solpos = pvlib.solarposition.get_solarposition(
        times_utc, site.latitude, site.longitude, altitude=site.elevation
    )
    zenith = solpos["apparent_zenith"].to_numpy()
    cos_z = np.cos(np.radians(zenith))
    # Day of year as numbers: pvlib's DatetimeIndex path uses an attribute pandas deprecates.
    day_of_year = times_utc.day_of_year.to_numpy(dtype=float)
    e0n = np.asarray(pvlib.irradiance.get_extra_radiation(day_of_year), dtype=float)
    given = {
        n: _interval_mean(s, forcing[n], start, end)
        for n in ("ghi", "dni", "dhi")
        if n in forcing.series
    }
    ghi, dni, dhi = _complete_components(given, zenith, cos_z, day_of_year)
    return {
        "ghi": np.clip(ghi, 0.0, None),
        "dni": np.clip(dni, 0.0, None),
        "dhi": np.clip(dhi, 0.0, None),
        "ext_normal": e0n,
        "ext_horizontal": e0n * np.maximum(cos_z, 0.0),
    }


def _complete_components(
    given: dict[str, np.ndarray],
    zenith: np.ndarray,
    cos_z: np.ndarray,
    day_of_year: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(GHI, DNI, DHI) from whichever of them are given (see the module notes). [W/m²]"""
    up = cos_z > _MIN_COS_ZENITH
    safe_cos = np.where(up, cos_z, 1.0)
    names = frozenset(given)
    if names == {"ghi", "dni", "dhi"}:
        return given["ghi"], given["dni"], given["dhi"]
    if names == {"ghi", "dhi"}:
        dni = np.where(up, (given["ghi"] - given["dhi"]) / safe_cos, 0.0)
        return given["ghi"], dni, given["dhi"]
    if names == {"ghi", "dni"}:
        return given["ghi"], given["dni"], given["ghi"] - given["dni"] * np.maximum(cos_z, 0.0)
    if names == {"dni", "dhi"}:
        return given["dhi"] + given["dni"] * np.maximum(cos_z, 0.0), given["dni"], given["dhi"]
    if names == {"ghi"}:
        split = pvlib.irradiance.erbs(given["ghi"], zenith, day_of_year)
        dni = np.asarray(split["dni"], dtype=float)
        return (
            given["ghi"],
            np.where(up, np.nan_to_num(dni), 0.0),
            np.asarray(split["dhi"], dtype=float),
        )
    if not names:
        zero = np.zeros_like(cos_z)
        return zero, zero, zero
    raise DataError(
        f"cannot build the solar components from {sorted(names)} alone",
        hint="give ghi, or two of ghi, dni and dhi",
    )


def epw_table(forcing: Forcing, site: EpwSite, *, records_per_hour: int = 1) -> pd.DataFrame:
    """The EPW data records for the calendar year holding ``forcing``.

    Parameters
    ----------
    forcing
        Boundary conditions; the glossary series listed in the module notes
        are used, the others ignored.
    site
        Location and time zone.
    records_per_hour
        Records per hour, a divisor of 60. [1/h]

    Returns
    -------
    pandas.DataFrame
        One row per record, the 35 EPW fields in file order (units as in the
        EPW format: °C, %, Pa, Wh/m², m/s, °, tenths).
    """
    if records_per_hour < 1 or 60 % records_per_hour:
        raise DataError(
            f"records_per_hour must divide 60, got {records_per_hour}",
            hint="use 1, 2, 3, 4, 6, 10, 12, 15, 20, 30 or 60",
        )
    year = local_year(forcing, site.time_zone)
    s = seconds_in_year(forcing, year, site.time_zone)
    days = 366 if calendar.isleap(year) else 365
    dt = 3600.0 / records_per_hour
    end = np.arange(1, round(days * _SECONDS_PER_DAY / dt) + 1) * dt
    start = end - dt
    year_utc = pd.Timestamp(f"{year:04d}-01-01") - pd.Timedelta(hours=site.time_zone)
    mid_utc = pd.DatetimeIndex(year_utc + pd.to_timedelta(end - dt / 2.0, unit="s"), tz="UTC")
    local_end = pd.Timestamp(f"{year:04d}-01-01") + pd.to_timedelta(end - 1.0, unit="s")

    def inst(name: str, fill: float) -> np.ndarray:
        return _at(s, forcing[name], end) if name in forcing.series else np.full(end.shape, fill)

    temp = inst("temp_air_out", FILL["temp_air_out"])
    rh = np.clip(inst("relative_humidity", FILL["relative_humidity"]), 1.0, 100.0)
    dew = dew_point(temp, rh)
    if "ir_horizontal" in forcing.series:
        ir = _at(s, forcing["ir_horizontal"], end)
    elif "temp_sky" in forcing.series:
        ir = Stefan_Boltzmann * (_at(s, forcing["temp_sky"], end) + zero_Celsius) ** 4
    else:
        ir = clark_allen_ir(temp, dew)
    solar = _solar_fields(forcing, s, start, end, mid_utc, site)
    day_start = np.floor((end - 1.0) / _SECONDS_PER_DAY) * _SECONDS_PER_DAY
    hour = np.ceil((end - day_start) / 3600.0 - 1e-9)
    minute = np.round((end - day_start - (hour - 1.0) * 3600.0) / 60.0)
    n = len(end)
    return pd.DataFrame(
        {
            "year": np.full(n, year),
            "month": local_end.month,
            "day": local_end.day,
            "hour": hour.astype(int),
            "minute": minute.astype(int),
            "flags": "?9?9?9?9E0?9?9?9?9?9?9?9?9?9?9?9?9?9?9?9*9*9?9?9?9",
            "temp_air": temp,
            "temp_dew": dew,
            "relative_humidity": rh,
            "pressure": inst("pressure", standard_pressure(site.elevation)),
            "ext_horizontal": solar["ext_horizontal"],
            "ext_normal": solar["ext_normal"],
            "ir_horizontal": ir,
            "ghi": solar["ghi"],
            "dni": solar["dni"],
            "dhi": solar["dhi"],
            "illum_global": np.zeros(n),
            "illum_direct": np.zeros(n),
            "illum_diffuse": np.zeros(n),
            "zenith_luminance": np.zeros(n),
            "wind_direction": np.mod(inst("wind_direction", FILL["wind_direction"]), 360.0),
            "wind_speed": np.clip(inst("wind_speed", FILL["wind_speed"]), 0.0, None),
            "sky_cover_total": np.full(n, FILL["sky_cover"]),
            "sky_cover_opaque": np.full(n, FILL["sky_cover"]),
            "visibility": np.full(n, 9999.0),
            "ceiling_height": np.full(n, 99999.0),
            "weather_observation": np.full(n, 9),
            "weather_codes": "999999999",
            "precipitable_water": np.zeros(n),
            "aerosol_optical_depth": np.zeros(n),
            "snow_depth": np.zeros(n),
            "days_since_snow": np.full(n, 88),
            "albedo": np.full(n, FILL["albedo"]),
            "liquid_precipitation_depth": np.zeros(n),
            "liquid_precipitation_quantity": np.ones(n),
        }
    )


_FORMATS = {
    "temp_air": "%.2f",
    "temp_dew": "%.2f",
    "relative_humidity": "%.1f",
    "pressure": "%.0f",
    "wind_direction": "%.1f",
    "wind_speed": "%.2f",
    "albedo": "%.3f",
}


def _header(site: EpwSite, year: int, records_per_hour: int) -> list[str]:
    weekday = calendar.day_name[calendar.weekday(year, 1, 1)]
    leap = "Yes" if calendar.isleap(year) else "No"
    city = site.city.replace(",", " ")
    return [
        f"LOCATION,{city},-,-,bayescal,999999,{site.latitude:.4f},{site.longitude:.4f},"
        f"{site.time_zone:.2f},{site.elevation:.1f}",
        "DESIGN CONDITIONS,0",
        "TYPICAL/EXTREME PERIODS,0",
        "GROUND TEMPERATURES,0",
        f"HOLIDAYS/DAYLIGHT SAVINGS,{leap},0,0,0",
        "COMMENTS 1,written by bayescal from measured boundary conditions",
        "COMMENTS 2,absent series filled as documented in bayescal.simulators.epw",
        f"DATA PERIODS,1,{records_per_hour},Data,{weekday},1/1,12/31",
    ]


def write_epw(
    path: str | Path, forcing: Forcing, site: EpwSite, *, records_per_hour: int = 1
) -> Path:
    """Write an EPW file for the calendar year holding ``forcing``.

    Parameters
    ----------
    path
        File to write.
    forcing
        Boundary conditions (see the module notes for the series used).
    site
        Location and time zone written to the header.
    records_per_hour
        Records per hour, a divisor of 60; EnergyPlus needs a ``Timestep``
        that is a multiple of it. [1/h]

    Returns
    -------
    pathlib.Path
        The file written.
    """
    table = epw_table(forcing, site, records_per_hour=records_per_hour)
    formats = [
        _FORMATS.get(name, "%.1f") if table[name].dtype.kind == "f" else "%s"
        for name in table.columns
    ]
    row_format = ",".join(formats)
    columns = [table[name].tolist() for name in table.columns]
    lines = _header(site, int(table["year"].iloc[0]), records_per_hour)
    lines += [row_format % row for row in zip(*columns, strict=True)]
    out = Path(path)
    out.write_text("\n".join(lines) + "\n", encoding="ascii")
    return out
