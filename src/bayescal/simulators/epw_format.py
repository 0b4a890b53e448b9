"""The EPW weather-file format: the fields of a data row.

Used by the EPW reader (:func:`bayescal.data.readers.read_epw`) and by the
study-file checks of EPW columns; apart from the writer
(:mod:`bayescal.simulators.epw`, rows of the same 35 fields) so that knowing
the format costs no solar-position imports.
"""

from __future__ import annotations

__all__ = ["EPW_FIELDS"]

EPW_FIELDS: tuple[str, ...] = (
    "year",
    "month",
    "day",
    "hour",
    "minute",
    "data_source",
    "temp_air_out",
    "temp_dew",
    "relative_humidity",
    "pressure",
    "etr",
    "etrn",
    "ir_horizontal",
    "ghi",
    "dni",
    "dhi",
    "ghi_illuminance",
    "dni_illuminance",
    "dhi_illuminance",
    "zenith_luminance",
    "wind_direction",
    "wind_speed",
    "total_sky_cover",
    "opaque_sky_cover",
    "visibility",
    "ceiling_height",
    "present_weather_observation",
    "present_weather_codes",
    "precipitable_water",
    "aerosol_optical_depth",
    "snow_depth",
    "days_since_last_snowfall",
    "albedo",
    "liquid_precipitation_depth",
    "liquid_precipitation_quantity",
)
"""Column names of an EPW data row, by field index (EnergyPlus Auxiliary Programs,
"Weather converter"). Units: temperatures °C, relative humidity %, pressure Pa,
irradiances W/m² (averages over the hour ending at the timestamp), wind m/s and
degrees from north."""
