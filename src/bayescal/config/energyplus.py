"""The ``[simulator]`` section of ``type = "energyplus"``: the model, its schedules and outputs.

Targets are ``"ObjectType:ObjectName:Field"`` (:func:`parse_energyplus_target`);
the unit of the fields in :data:`ENERGYPLUS_FIELD_KINDS` is known whatever the
object, and checked against the parameter's unit.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import ValidationInfo, field_validator, model_validator

from bayescal.config.base import Section, field_doc, raise_problems, resolve_path
from bayescal.config.targets import SimulatorBase
from bayescal.simulators.energyplus_model import energyplus_field_key

__all__ = [
    "ENERGYPLUS_FIELD_KINDS",
    "PACKAGE_PREFIX",
    "EnergyPlusOutput",
    "EnergyPlusSchedule",
    "EnergyPlusSection",
    "package_file",
    "parse_energyplus_target",
]

_EPLUS_TARGET = re.compile(
    r"^(?P<object>[A-Za-z][A-Za-z0-9]*(?::[A-Za-z][A-Za-z0-9]*)*)"
    r':(?:"(?P<quoted>[^"]+)"|(?P<name>[^:"]+))'
    r":(?P<field>[A-Za-z][A-Za-z0-9 _\-]*)$"
)
ENERGYPLUS_FIELD_KINDS = {
    "thickness": "length",
    "conductivity": "conductivity",
    "density": "density",
    "specific_heat": "specific_heat",
    "thermal_resistance": "resistance",
    "thermal_absorptance": "dimensionless",
    "solar_absorptance": "dimensionless",
    "visible_absorptance": "dimensionless",
    "u_factor": "coefficient",
    "solar_heat_gain_coefficient": "dimensionless",
    "visible_transmittance": "dimensionless",
    "combined_convective_radiative_film_coefficient": "coefficient",
    "convection_coefficient_1": "coefficient",
    "convection_coefficient_2": "coefficient",
}
"""EnergyPlus fields (epJSON key) whose unit is known, whatever the object -> kind."""


def parse_energyplus_target(target: str) -> tuple[str, str, str]:
    """Split ``"ObjectType:ObjectName:Field"`` into its three parts.

    The field is the last segment and the name the one before it; a name
    holding a colon is written in double quotes (``'Material:"B1:Wall":Density'``).

    Raises
    ------
    ValueError
        If ``target`` does not have that form.
    """
    match = _EPLUS_TARGET.match(target.strip())
    if match is None or not (match["quoted"] or match["name"] or "").strip():
        raise ValueError(
            f"{target!r} is not an EnergyPlus field target; write 'ObjectType:ObjectName:Field' "
            "such as 'Material:AeratedConcrete:Conductivity' (a name holding ':' in double "
            "quotes)"
        )
    name = (match["quoted"] or match["name"]).strip()
    return match["object"], name, match["field"].strip()


PACKAGE_PREFIX = "pyenergyplus:"
"""A model or weather path starting with this names a file of the ``data`` folder that
``pyenergyplus-lbnl`` ships: ``"pyenergyplus:model/RefBldgSmallOfficeNew2004_Chicago.idf"``,
``"pyenergyplus:weather/USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw"``."""


def package_file(text: str) -> Path:
    """The file ``"pyenergyplus:<path>"`` names in the package's ``data`` folder.

    Raises
    ------
    ValueError
        If the package is not installed or holds no such file.
    """
    relative = text[len(PACKAGE_PREFIX) :].strip().lstrip("/")
    spec = importlib.util.find_spec("pyenergyplus")
    if spec is None or not spec.submodule_search_locations:
        raise ValueError(
            f"{text!r} names a file of the package pyenergyplus-lbnl, which is not installed; "
            "pip install 'bayescal[energyplus]'"
        )
    data = Path(next(iter(spec.submodule_search_locations))) / "data"
    path = data / relative
    if ".." in Path(relative).parts or not path.is_file():
        folders = ", ".join(sorted(p.name + "/" for p in data.iterdir() if p.is_dir()))
        raise ValueError(f"pyenergyplus ships no {relative!r} (its data folder holds {folders})")
    return path


def _from_package(value: object) -> object:
    if isinstance(value, str) and value.startswith(PACKAGE_PREFIX):
        return package_file(value)
    return value


class EnergyPlusSchedule(Section):
    """``[simulator.schedules.<glossary name>]``: the ``Schedule:File`` a forcing series feeds."""

    schedule: str = field_doc(
        "Name of the Schedule:File object in the model.", "TempSurfOut", min_length=1
    )
    lead_steps: int = field_doc(
        "Write the series this many EnergyPlus time steps ahead (1 for a zone-air setpoint that "
        "stands for an inside surface temperature).",
        1,
        default=0,
        ge=0,
    )

    @model_validator(mode="before")
    @classmethod
    def _from_name(cls, data: Any) -> Any:
        return {"schedule": data} if isinstance(data, str) else data


class EnergyPlusOutput(Section):
    """``[simulator.outputs.<name>]`` (energyplus): a report variable or a meter returned as
    a series (give ``variable`` and ``key``, or ``meter``)."""

    variable: str | None = field_doc(
        "Report variable name.",
        "Surface Inside Face Conduction Heat Transfer Rate per Area",
        "Zone Mean Air Temperature",
        default=None,
    )
    key: str | None = field_doc(
        "Key value (surface, zone... name) of the variable, case-insensitive.",
        "Wall",
        "Core_ZN",
        default=None,
    )
    meter: str | None = field_doc(
        "Meter name (an energy per time step, J): the output's [data.columns] entry "
        "says aggregate = 'sum'.",
        "Electricity:Facility",
        "NaturalGas:Facility",
        default=None,
    )
    scale: float = field_doc(
        "Factor applied to the values (-1 flips a sign convention). [-]", -1.0, default=1.0
    )

    @model_validator(mode="after")
    def _one_source(self) -> EnergyPlusOutput:
        if (self.meter is None) == (self.variable is None):
            raise ValueError("give either variable (with key) or meter")
        if self.variable is not None and self.key is None:
            raise ValueError(f"variable {self.variable!r} needs its key (a zone, surface... name)")
        if self.meter is not None and self.key is not None:
            raise ValueError("a meter has no key; remove key")
        return self


class EnergyPlusSection(SimulatorBase):
    """``type = "energyplus"``: an EnergyPlus model
    (:class:`bayescal.simulators.energyplus.EnergyPlusSimulator`)."""

    path_keys: ClassVar[tuple[str, ...]] = ("model", "weather")

    type: Literal["energyplus"] = field_doc("Simulator type.", "energyplus")
    model: Path = field_doc(
        "The model, .epJSON or .idf (converted once by EnergyPlus), relative to the study "
        "folder (or absolute); 'pyenergyplus:model/<file>' for a model that ships with "
        "EnergyPlus (package pyenergyplus-lbnl).",
        "paper_wall.epJSON",
        "pyenergyplus:model/RefBldgSmallOfficeNew2004_Chicago.idf",
    )
    schedules: dict[str, EnergyPlusSchedule] = field_doc(
        "Forcing series (glossary name) -> Schedule:File name, or {schedule, lead_steps}; "
        "each series is written as one CSV row per EnergyPlus time step.",
        {
            "temp_surf_out": "TempSurfOut",
            "temp_surf_in": {"schedule": "TempAirIn", "lead_steps": 1},
        },
        default_factory=dict,
    )
    outputs: dict[str, EnergyPlusOutput] = field_doc(
        "Output name (glossary name for calibrated outputs) -> {variable, key, scale}.",
        {
            "heat_flux_in": {
                "variable": "Surface Inside Face Conduction Heat Transfer Rate per Area",
                "key": "Wall",
            }
        },
        min_length=1,
    )
    weather: Literal["from-forcing"] | Path = field_doc(
        "'from-forcing' (an EPW written from the boundary conditions; absent series filled as "
        "bayescal.simulators.epw says) or an EPW file, relative to the study folder; "
        "'pyenergyplus:weather/<file>' for one that ships with EnergyPlus. The file travels "
        "with the simulator to the workers.",
        "from-forcing",
        "weather/uccle.epw",
        "pyenergyplus:weather/USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw",
        default="from-forcing",
    )
    algorithm: Literal["ConductionTransferFunction", "ConductionFiniteDifference"] | None = (
        field_doc(
            "Heat-conduction algorithm (HeatBalanceAlgorithm); the model's if omitted.",
            "ConductionTransferFunction",
            default=None,
        )
    )
    timesteps_per_hour: int | None = field_doc(
        "EnergyPlus time steps per hour, a divisor of 60 (at least 20 for "
        "ConductionFiniteDifference); the model's Timestep if omitted. [1/h]",
        6,
        default=None,
        ge=1,
        le=60,
    )
    warmup_days: int = field_doc(
        "Whole days simulated before the first sample with its boundary conditions. [d]",
        3,
        default=3,
        ge=0,
    )
    timeout: float = field_doc(
        "A run taking longer is stopped and fails. [s]", 600.0, default=600.0, gt=0
    )
    keep_outputs: bool = field_doc(
        "Keep every run's folder (model, EnergyPlus's output files) in OUTPUT_DIR/energyplus "
        "instead of deleting it once the requested series are read (debugging; a "
        "reference building's files take about 2 MB a run).",
        True,
        default=False,
    )

    @field_validator("model", "weather", mode="before")
    @classmethod
    def _package_paths(cls, value: object) -> object:
        return _from_package(value)

    @field_validator("model")
    @classmethod
    def _model(cls, value: Path, info: ValidationInfo) -> Path:
        resolved = resolve_path(value, info, "a model file")
        if resolved.suffix.lower() not in (".epjson", ".idf"):
            raise ValueError(f"expected an .epJSON or .idf model, got {value.name!r}")
        return resolved

    @field_validator("weather")
    @classmethod
    def _weather(cls, value: str | Path, info: ValidationInfo) -> str | Path:
        if isinstance(value, str):
            return value
        resolved = resolve_path(value, info, "'from-forcing' or an EPW file")
        if resolved.suffix.lower() != ".epw":
            raise ValueError(f"expected 'from-forcing' or an .epw file, got {str(value)!r}")
        return resolved

    @model_validator(mode="after")
    def _consistent(self) -> EnergyPlusSection:
        problems = []
        tph = self.timesteps_per_hour
        if tph is not None and 60 % tph:
            problems.append(
                f"simulator.timesteps_per_hour: {tph} does not divide 60; use 1, 2, 3, 4, 5, 6, "
                "10, 12, 15, 20, 30 or 60"
            )
        if tph is not None and tph < 20 and self.algorithm == "ConductionFiniteDifference":
            problems.append(
                f"simulator.timesteps_per_hour: {tph} is too few for ConductionFiniteDifference "
                "(EnergyPlus needs at least 20)"
            )
        fed: dict[str, str] = {}
        for series, spec in self.schedules.items():
            name = spec.schedule.lower()
            if name in fed:
                problems.append(
                    f"simulator.schedules.{series}: Schedule:File {spec.schedule!r} is already "
                    f"fed by {fed[name]!r}"
                )
            fed[name] = series
        raise_problems(problems)
        return self

    def target_kind(self, target: str) -> str | None:
        _, _, field = parse_energyplus_target(target)
        return ENERGYPLUS_FIELD_KINDS.get(energyplus_field_key(field))

    def target_key(self, target: str) -> str:
        obj, name, field = parse_energyplus_target(target)
        return f"{obj.lower()}:{name.lower()}:{energyplus_field_key(field)}"

    def output_names(self) -> tuple[str, ...]:
        return tuple(self.outputs)

    def input_names(self) -> tuple[str, ...]:
        return tuple(self.schedules)
