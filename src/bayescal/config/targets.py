"""Calibration targets: what a parameter sets, the kind of quantity it is and its unit.

Each ``[simulator]`` section tells the rest of the configuration what can be
known before a run (:class:`SimulatorBase`): which calibration targets exist
and the kind of quantity each sets (so that a parameter's ``unit`` can be
checked against :data:`KIND_UNITS`), which series the simulator produces and
which boundary conditions it needs.

Calibration targets, written in ``[parameters.<name>].targets``
------------------------------------------------------------------
``wall``
    ``"<layer>.<property>"`` and, with air boundaries, ``r_si``, ``r_se``,
    ``solar_absorptance``.
``box``
    A constant of :data:`bayescal.simulators.box.DEFAULTS`.
``energyplus``
    ``"ObjectType:ObjectName:Field"``, e.g.
    ``"Material:AeratedConcrete:Conductivity"``. The field is the last
    segment and the object name the one before it, so object types may hold
    colons (``"Material:NoMass:R13:Thermal_Resistance"``); an object name that
    holds a colon is written in double quotes
    (``'Material:"Block1:Wall":Conductivity'``). Fields are named as in the
    IDD (``Specific Heat``) or as in epJSON (``specific_heat``). The unit of
    the fields in :data:`bayescal.config.energyplus.ENERGYPLUS_FIELD_KINDS`
    is known whatever the object (``Conductivity`` is W/(m·K) in every object
    that has one) and checked against the parameter's ``unit``; any other
    numeric field is accepted with any unit, because its unit cannot be known
    without EnergyPlus's schema. That the object and field exist is checked
    when the simulator is built (the model is read then).
``command``
    A placeholder of the templates (``$R`` -> ``"R"``); its unit is whatever
    the program reads, so any unit is accepted.
``fmu``
    An FMU variable name; parameters are passed unconverted, so any unit is
    accepted.
Any simulator
    ``"measured.<output>.offset"`` and ``"measured.<output>.gain"``: a sensor
    model on an output, ``reading = gain * simulated + offset`` (a heat-flux
    plate's zero offset, a pyranometer's calibration factor), calibrated
    with the physics; see :func:`parse_sensor_target`. The offset takes the
    output's unit (any spelling with the same scale: ``K`` or ``°C`` for a
    temperature), the gain ``1``.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, ClassVar

from bayescal.config.base import Section, suggestion

__all__ = [
    "KIND_UNITS",
    "SENSOR_PREFIX",
    "SENSOR_PROPERTIES",
    "SimulatorBase",
    "normal_unit",
    "parse_sensor_target",
]

KIND_UNITS = {
    "length": ({"m"}, "m"),
    "conductivity": ({"W/mK", "W/Km", "Wm-1K-1", "W/m/K"}, "W/(m·K)"),
    "density": ({"kg/m3", "kgm-3"}, "kg/m³"),
    "specific_heat": ({"J/kgK", "J/Kkg", "Jkg-1K-1", "J/kg/K"}, "J/(kg·K)"),
    "resistance": ({"m2K/W", "Km2/W", "m2KW-1"}, "m²·K/W"),
    "coefficient": ({"W/m2K", "W/Km2", "Wm-2K-1", "W/m2/K"}, "W/(m²·K)"),
    "wind_coefficient": ({"J/m3K", "J/Km3", "Jm-3K-1", "Ws/m3K"}, "J/(m³·K)"),
    "capacity": ({"J/K", "JK-1"}, "J/K"),
    "conductance": ({"W/K", "WK-1"}, "W/K"),
    "dimensionless": ({"1", "-", "fraction"}, "1"),
}
"""Kind of a calibration target -> (accepted unit spellings, normalised; the SI unit)."""


SENSOR_PREFIX = "measured."
SENSOR_PROPERTIES = ("offset", "gain")


def parse_sensor_target(target: str) -> tuple[str, str] | None:
    """Split a sensor-model target ``"measured.<output>.<offset|gain>"``.

    Returns
    -------
    tuple or None
        ``(output, property)``, or None when ``target`` is not a sensor target
        (it then belongs to the simulator).

    Raises
    ------
    ValueError
        If the target starts with ``measured.`` but is not of that form.
    """
    if not target.startswith(SENSOR_PREFIX):
        return None
    output, _, prop = target[len(SENSOR_PREFIX) :].rpartition(".")
    if not output or prop not in SENSOR_PROPERTIES:
        raise ValueError(
            f"{target!r} is not a sensor target; write 'measured.<output>.offset' or "
            "'measured.<output>.gain', e.g. 'measured.heat_flux_in.offset'"
        )
    return output, prop


def normal_unit(unit: str) -> str:
    """A unit spelling reduced for comparison with :data:`KIND_UNITS` (``W/(m·K)`` -> ``W/mK``)."""
    return re.sub(r"[\s·.*()^]", "", unit.replace("²", "2").replace("³", "3"))


class SimulatorBase(Section):
    """What every simulator section tells the rest of the configuration."""

    if TYPE_CHECKING:  # every section has a literal ``type`` field
        type: str

    path_keys: ClassVar[tuple[str, ...]] = ()
    """Keys holding paths (resolved to absolute ones), made relative for the config hash."""

    def target_kinds(self) -> dict[str, str] | None:
        """Calibratable target -> kind (see :data:`KIND_UNITS`); None: the set is open."""
        return None

    def target_kind(self, target: str) -> str | None:
        """The kind of one calibration target; None where it cannot be known.

        Raises
        ------
        ValueError
            If the simulator has no such target; the message starts with the
            target and says what was expected.
        """
        kinds = self.target_kinds()
        if kinds is None:
            return None
        if target not in kinds:
            raise ValueError(
                f"{target!r} is not a target of the {self.type} simulator"
                f"{suggestion(target, sorted(kinds))}"
            )
        return kinds[target]

    def target_key(self, target: str) -> str:
        """The target in a canonical spelling, to find two parameters setting one target."""
        return target

    def output_names(self) -> tuple[str, ...]:
        """Series the simulator produces (empty: not known before it runs)."""
        return ()

    def input_names(self) -> tuple[str, ...]:
        """Boundary conditions the simulator cannot run without."""
        return ()
