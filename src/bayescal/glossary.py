"""One glossary of series names, with their dimension and internal unit.

Readers rename source columns to these names at the edge; simulators,
studies and reports only ever see these names.

Sign conventions
----------------
``heat_flux_in``
    Heat flux at the inside surface of a wall, positive from the wall into the
    room [W/m²] (the convention of the Annex 58 Twin House heat-flux plates).
``heat_flux_out``
    Heat flux at the outside surface, positive from the outside environment
    into the wall [W/m²]. In steady state with a warm inside,
    ``heat_flux_in = heat_flux_out < 0``.

Meters and zones
----------------
``electricity``, ``gas``, ``heating_energy`` and ``cooling_energy`` are
energies over each interval of the study clock [J] (a meter's reading: the
value stamped ``t`` is the total over ``(t - step, t]``). A building has many
zones and meters: these names and ``temp_air_in``, ``heating_power`` take a
label, ``temp_air_in_core`` or ``electricity_lights`` (lower-case letters,
digits and ``_``), and keep their quantity.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from bayescal.units import INTERNAL_UNIT


@dataclass(frozen=True)
class Quantity:
    """A glossary entry."""

    name: str
    dimension: str
    description: str

    @property
    def unit(self) -> str:
        """Internal unit of the quantity."""
        return INTERNAL_UNIT[self.dimension]


_ENTRIES = [
    Quantity("temp_surf_out", "temperature", "outside surface temperature of a wall"),
    Quantity("temp_surf_in", "temperature", "inside surface temperature of a wall"),
    Quantity("temp_interface", "temperature", "temperature at a layer interface in a wall"),
    Quantity("heat_flux_in", "heat_flux", "inside-surface heat flux, positive wall -> room"),
    Quantity("heat_flux_out", "heat_flux", "outside-surface heat flux, positive outside -> wall"),
    Quantity("heat_flux_interface", "heat_flux", "heat flux at a layer interface, outside -> in"),
    Quantity("temp_air_out", "temperature", "outdoor (ambient) air temperature"),
    Quantity("temp_air_in", "temperature", "indoor air temperature"),
    Quantity("temp_sky", "temperature", "effective sky temperature"),
    Quantity("ghi", "heat_flux", "global horizontal irradiance"),
    Quantity("dhi", "heat_flux", "diffuse horizontal irradiance"),
    Quantity("dni", "heat_flux", "direct normal irradiance"),
    Quantity("gvi_south", "heat_flux", "global irradiance on a south-facing vertical plane"),
    Quantity("ir_horizontal", "heat_flux", "horizontal long-wave (infrared) irradiance"),
    Quantity("poa_global_out", "heat_flux", "global irradiance incident on a wall's outside face"),
    Quantity("wind_speed", "speed", "wind speed at the site"),
    Quantity("wind_direction", "angle", "wind direction, degrees from north, clockwise"),
    Quantity("relative_humidity", "fraction_percent", "relative humidity"),
    Quantity("pressure", "pressure", "atmospheric pressure"),
    Quantity("heating_power", "power", "heating power delivered to the indoor air"),
    Quantity("heat_input", "power", "imposed heat input to the indoor air (free-float)"),
    Quantity(
        "hvac_operation",
        "dimensionless",
        "share of each clock interval the HVAC runs by its schedule (a building's known "
        "operating hours: 1 on, 0 off)",
    ),
    Quantity("electricity", "energy", "electricity use over each clock interval (a meter)"),
    Quantity("gas", "energy", "fuel (natural gas) use over each clock interval (a meter)"),
    Quantity("heating_energy", "energy", "heat delivered over each clock interval"),
    Quantity("cooling_energy", "energy", "heat removed over each clock interval"),
]

_INDEXED = re.compile(r"^(?P<base>\w+_interface)_(?P<index>\d+)$")
#: Names that take a zone or meter label: ``temp_air_in_core``, ``electricity_lights``.
LABELLED = (
    "temp_air_in",
    "heating_power",
    "electricity",
    "gas",
    "heating_energy",
    "cooling_energy",
)
_LABELLED = re.compile(
    r"^(?P<base>" + "|".join(LABELLED) + r")_(?P<label>[a-z0-9]+(?:_[a-z0-9]+)*)$"
)


class _Glossary(dict[str, Quantity]):
    """The glossary entries by name; looking up a labelled or indexed name finds its base.

    Iterating gives the entries only (``temp_air_in``, not every zone label).
    """

    def __missing__(self, name: str) -> Quantity:
        found = _derived(self, name)
        if found is None:
            raise KeyError(name)
        return found

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and (
            dict.__contains__(self, name) or _derived(self, name) is not None
        )

    def get(self, name: str, default: Quantity | None = None) -> Quantity | None:  # type: ignore[override]
        try:
            return self[name]
        except KeyError:
            return default


def _derived(entries: dict[str, Quantity], name: str) -> Quantity | None:
    """The entry of an indexed (``temp_interface_2``) or labelled (``temp_air_in_core``) name."""
    for pattern in (_INDEXED, _LABELLED):
        match = pattern.match(name)
        if match and dict.__contains__(entries, match["base"]):
            base = dict.__getitem__(entries, match["base"])
            label = match.groupdict().get("label")
            text = f"{base.description} ({label})" if label else base.description
            return Quantity(name, base.dimension, text)
    return None


GLOSSARY: dict[str, Quantity] = _Glossary({q.name: q for q in _ENTRIES})


def glossary_quantity(name: str) -> Quantity | None:
    """The glossary entry of a series name, or None.

    Interface series of walls carry the interface index: ``temp_interface_2``
    is a ``temp_interface`` (the interface between layers 1 and 2). Zones and
    meters carry a label: ``temp_air_in_core`` is a ``temp_air_in``.
    """
    return GLOSSARY.get(name)
