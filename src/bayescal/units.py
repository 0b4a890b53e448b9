"""Units at the edge: conversion of measured columns to the SI units used inside.

Inside bayescal every quantity is in SI units, temperatures in °C (differences
in K). Data files declare the unit of each column; :func:`to_internal`
converts to the internal unit of the quantity's dimension. Only affine
conversions are needed, so a small table is kept here rather than a units
library.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.constants import Btu

from bayescal.errors import DataError


@dataclass(frozen=True)
class _Unit:
    dimension: str
    scale: float
    offset: float = 0.0  # internal = value * scale + offset


# Spellings accepted for each unit (case-sensitive where SI prefixes matter).
_UNITS: dict[str, _Unit] = {}


def _add(names: tuple[str, ...], dimension: str, scale: float, offset: float = 0.0) -> None:
    for name in names:
        _UNITS[name] = _Unit(dimension, scale, offset)


_add(("degC", "°C", "C", "celsius"), "temperature", 1.0)
_add(("K", "kelvin"), "temperature", 1.0, -273.15)
_add(("degF", "°F", "F", "fahrenheit"), "temperature", 5.0 / 9.0, -32.0 * 5.0 / 9.0)
_add(("W/m2", "W/m²", "W m-2", "W/m^2"), "heat_flux", 1.0)
_add(("kW/m2", "kW/m²", "kW m-2", "kW/m^2"), "heat_flux", 1000.0)
_add(("W",), "power", 1.0)
_add(("kW",), "power", 1000.0)
_add(("m/s", "m s-1"), "speed", 1.0)
_add(("km/h",), "speed", 1000.0 / 3600.0)
_add(("deg", "°", "degree"), "angle", 1.0)
_add(("%",), "fraction_percent", 1.0)
_add(("1", "-", "fraction"), "dimensionless", 1.0)
_add(("Pa",), "pressure", 1.0)
_add(("hPa", "mbar"), "pressure", 100.0)
_add(("kPa",), "pressure", 1000.0)
# Energy over a clock interval (meters): J inside.
_add(("J",), "energy", 1.0)
_add(("kJ",), "energy", 1.0e3)
_add(("MJ",), "energy", 1.0e6)
_add(("GJ",), "energy", 1.0e9)
_add(("Wh",), "energy", 3600.0)
_add(("kWh",), "energy", 3.6e6)
_add(("MWh",), "energy", 3.6e9)
_add(("kBtu",), "energy", 1.0e3 * Btu)  # international-table Btu
_add(("therm",), "energy", 1.0e5 * Btu)

INTERNAL_UNIT = {
    "temperature": "°C",
    "heat_flux": "W/m²",
    "power": "W",
    "speed": "m/s",
    "angle": "°",
    "fraction_percent": "%",
    "dimensionless": "1",
    "pressure": "Pa",
    "energy": "J",
}


def known_units() -> list[str]:
    """All accepted unit spellings."""
    return sorted(_UNITS)


def dimension_of(unit: str) -> str:
    """The physical dimension of a unit spelling, e.g. ``"temperature"`` for ``"degF"``.

    Raises
    ------
    DataError
        If the unit is not known.
    """
    try:
        return _UNITS[unit].dimension
    except KeyError:
        raise DataError(
            f"unknown unit {unit!r}",
            hint="use one of " + ", ".join(known_units()),
        ) from None


def same_scale(unit: str, dimension: str) -> bool:
    """Whether ``unit`` measures ``dimension`` on the internal unit's scale.

    True for the internal unit and for spellings that differ from it by an
    offset only (``K`` for temperature differences); False for unknown units.
    """
    known = _UNITS.get(unit)
    return known is not None and known.dimension == dimension and known.scale == 1.0


def spread_to_internal(value: float, unit: str, dimension: str) -> float:
    """A spread (standard deviation, difference) in ``unit`` in the internal unit.

    Only the scale applies: 0.2 K of noise is 0.2 °C of noise, not -272.95 °C.

    Raises
    ------
    bayescal.errors.DataError
        For an unknown unit or one of another dimension.
    """
    known = _UNITS.get(unit)
    if known is None:
        raise DataError(f"unknown unit {unit!r}; known: {', '.join(known_units())}")
    if known.dimension != dimension:
        raise DataError(
            f"{unit!r} is a {known.dimension.replace('_', ' ')} unit, expected "
            f"{dimension.replace('_', ' ')}"
        )
    return float(value) * known.scale


def to_internal(values: npt.ArrayLike, unit: str, *, dimension: str | None = None) -> np.ndarray:
    """Convert values in ``unit`` to the internal unit of its dimension.

    Parameters
    ----------
    values
        Values in ``unit``.
    unit
        Unit spelling, e.g. ``"degF"``, ``"kW"``.
    dimension
        If given, the dimension the caller expects; a unit of another dimension
        is an error (``"kW"`` for a temperature column).

    Returns
    -------
    numpy.ndarray
        Values in the internal unit (see ``INTERNAL_UNIT``), as float64.
    """
    dim = dimension_of(unit)
    if dimension is not None and dim != dimension:
        raise DataError(
            f"unit {unit!r} is a {dim.replace('_', ' ')} unit, expected a "
            f"{dimension.replace('_', ' ')} unit such as {INTERNAL_UNIT[dimension]!r}"
        )
    u = _UNITS[unit]
    return np.asarray(values, dtype=float) * u.scale + u.offset
