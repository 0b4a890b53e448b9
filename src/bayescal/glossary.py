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
]

GLOSSARY: dict[str, Quantity] = {q.name: q for q in _ENTRIES}


_INDEXED = re.compile(r"^(?P<base>\w+_interface)_(?P<index>\d+)$")


def glossary_quantity(name: str) -> Quantity | None:
    """The glossary entry of a series name, or None.

    Interface series of walls carry the interface index: ``temp_interface_2``
    is a ``temp_interface`` (the interface between layers 1 and 2).
    """
    if name in GLOSSARY:
        return GLOSSARY[name]
    match = _INDEXED.match(name)
    return GLOSSARY.get(match["base"]) if match else None
