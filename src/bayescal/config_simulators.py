"""The ``[simulator]`` section of the study file: one frozen model per simulator type.

:data:`SimulatorSection` is the union, told apart by ``type``: ``"wall"`` and
``"box"`` (the built-in finite-volume models), ``"energyplus"`` (an EnergyPlus
model, IDF or epJSON), ``"command"`` (any external program fed by rendered
templates) and ``"fmu"`` (a co-simulation FMU). A new simulator type is one
more class here, added to the union, plus a builder in
:mod:`bayescal.simulators.factory`.

Each section tells the rest of the configuration what can be known before a
run (:class:`_SimulatorBase`): which calibration targets exist and the kind of
quantity each sets (so that a parameter's ``unit`` can be checked), which
series the simulator produces and which boundary conditions it needs.

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
    the fields in :data:`ENERGYPLUS_FIELD_KINDS` is known whatever the object
    (``Conductivity`` is W/(m·K) in every object that has one) and checked
    against the parameter's ``unit``; any other numeric field is accepted
    with any unit, because its unit cannot be known without EnergyPlus's
    schema. That the object and field exist is checked when the simulator is
    built (the model is read then).
``command``
    A placeholder of the templates (``$R`` -> ``"R"``); its unit is whatever
    the program reads, so any unit is accepted.
``fmu``
    An FMU variable name; parameters are passed unconverted, so any unit is
    accepted.

The base model and the field helpers shared with :mod:`bayescal.config` live
here because ``config`` imports this module (not the other way round).
Any simulator
    ``"measured.<output>.offset"`` and ``"measured.<output>.gain"``: a sensor
    model on an output, ``reading = gain * simulated + offset`` (a heat-flux
    plate's zero offset, a pyranometer's calibration factor), calibrated
    with the physics; see :func:`parse_sensor_target`. The offset takes the
    output's unit (any spelling with the same scale: ``K`` or ``°C`` for a
    temperature), the gain ``1``.
"""

from __future__ import annotations

import difflib
import os
import re
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal, Union

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from bayescal.errors import DataError
from bayescal.simulators.fvm import LAYER_PROPERTIES
from bayescal.units import dimension_of

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


# --------------------------------------------------------------------------- helpers


def _f(description: str, *examples: Any, **constraints: Any) -> Any:
    """A documented field: description (unit in brackets), examples, constraints."""
    return Field(description=description, examples=list(examples), **constraints)


def _fail(messages: list[str]) -> None:
    """Raise the collected cross-field problems (each message starts with its key path)."""
    if messages:
        raise PydanticCustomError("cross_check", "{text}", {"text": "; ".join(messages)})


def _suggest(name: str, valid: list[str] | tuple[str, ...]) -> str:
    close = difflib.get_close_matches(name, list(valid), n=1)
    return f"; did you mean {close[0]!r}?" if close else f"; expected one of {', '.join(valid)}"


def _resolve(value: Path, info: ValidationInfo, what: str) -> Path:
    """An absolute path; relative ones start at the study folder and may not leave it."""
    if str(value) in ("", "."):
        raise ValueError(f"expected {what}, got {str(value)!r}")
    if value.is_absolute():
        return value
    root = Path(os.path.normpath(Path((info.context or {}).get("root", Path.cwd()))))
    resolved = Path(os.path.normpath(root / value))
    if not resolved.is_relative_to(root):
        raise ValueError(
            f"path {str(value)!r} leaves the study folder; give an absolute path or move "
            "it into the study folder"
        )
    return resolved


class _Section(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


# --------------------------------------------------------------------------- target kinds

_KIND_UNITS = {
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


def _normal_unit(unit: str) -> str:
    return re.sub(r"[\s·.*()^]", "", unit.replace("²", "2").replace("³", "3"))


# --------------------------------------------------------------------------- [simulator]


class _SimulatorBase(_Section):
    """What every simulator section tells the rest of the configuration."""

    if TYPE_CHECKING:  # every section has a literal ``type`` field
        type: str

    path_keys: ClassVar[tuple[str, ...]] = ()
    """Keys holding paths (resolved to absolute ones), made relative for the config hash."""

    def target_kinds(self) -> dict[str, str] | None:
        """Calibratable target -> kind (see ``_KIND_UNITS``); None: the set is open."""
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
                f"{_suggest(target, sorted(kinds))}"
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


class LayerSpec(_Section):
    """One layer of a wall, outside to inside."""

    name: str = _f("Layer name, used in targets.", "concrete")
    thickness: float = _f("Thickness. [m]", 0.15, gt=0)
    conductivity: float = _f("Thermal conductivity. [W/(m·K)]", 0.12, gt=0)
    density: float = _f("Density. [kg/m³]", 552.0, gt=0)
    specific_heat: float = _f("Specific heat capacity. [J/(kg·K)]", 800.0, gt=0)

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        if not _NAME.match(value):
            raise ValueError(f"layer names are identifiers (letters, digits, _), got {value!r}")
        return value


class WallSimulator(_SimulatorBase):
    """``type = "wall"``: the built-in wall (:class:`bayescal.simulators.wall.MultilayerWall`)."""

    type: Literal["wall"] = _f("Simulator type.", "wall")
    layers: list[LayerSpec] = _f(
        "Layers from the outside face to the inside face ([[simulator.layers]] tables).",
        [
            {
                "name": "concrete",
                "thickness": 0.15,
                "conductivity": 0.12,
                "density": 552.0,
                "specific_heat": 800.0,
            }
        ],
        min_length=1,
    )
    boundary: Literal["surface", "air"] = _f(
        "'surface': measured surface temperatures imposed on both faces; 'air': air "
        "temperatures through the surface resistances, plus absorbed solar outside.",
        "air",
        default="surface",
    )
    r_se: float = _f(
        "Outside surface resistance (air boundary). [m²·K/W]", 0.04, default=0.04, gt=0
    )
    r_si: float = _f("Inside surface resistance (air boundary). [m²·K/W]", 0.13, default=0.13, gt=0)
    solar_absorptance: float = _f(
        "Solar absorptance of the outside face; > 0 needs boundary 'air' and the boundary "
        "condition poa_global_out. [-]",
        0.6,
        default=0.0,
        ge=0,
        le=1,
    )
    outputs: list[str] = _f(
        "Series produced: heat_flux_in, heat_flux_out, temp_surf_out, temp_surf_in, and "
        "temp_interface_<i> / heat_flux_interface_<i> at the interface between layers i-1 "
        "and i (outside layer 0).",
        ["heat_flux_in", "temp_interface_2"],
        default=["heat_flux_in"],
        min_length=1,
    )
    scheme: Literal["crank-nicolson", "backward-euler", "exact"] = _f(
        "Time integration scheme.", "exact", default="crank-nicolson"
    )
    tolerance: float = _f(
        "Relative error bound of the periodic response down to the period of two clock "
        "steps; it chooses mesh and sub-steps. [-]",
        1e-3,
        default=1e-2,
        gt=0,
        le=0.25,
    )
    cells: list[int] | None = _f("Cells per layer, overriding tolerance.", [4, 10, 4], default=None)

    @model_validator(mode="after")
    def _consistent(self) -> WallSimulator:
        from bayescal.simulators.wall import allowed_outputs

        names = [layer.name for layer in self.layers]
        allowed = allowed_outputs(len(names))
        problems = [
            f"simulator.outputs: {out!r} is not a wall output{_suggest(out, allowed)}"
            for out in self.outputs
            if out not in allowed
        ]
        if len(set(names)) != len(names):
            problems.append(f"simulator.layers: layer names must be unique, got {names}")
        if len(set(self.outputs)) != len(self.outputs):
            problems.append(f"simulator.outputs: repeated names in {self.outputs}")
        if self.boundary == "surface" and self.solar_absorptance > 0:
            problems.append(
                "simulator.solar_absorptance: > 0 needs boundary = 'air' (imposed surface "
                "temperatures already contain the solar gains)"
            )
        if self.cells is not None and (len(self.cells) != len(names) or min(self.cells) < 1):
            problems.append(f"simulator.cells: one count >= 1 per layer, got {self.cells}")
        _fail(problems)
        return self

    def target_kinds(self) -> dict[str, str]:
        kinds = {"thickness": "length"} | {p: p for p in LAYER_PROPERTIES if p != "thickness"}
        found = {f"{layer.name}.{p}": kinds[p] for layer in self.layers for p in LAYER_PROPERTIES}
        if self.boundary == "air":  # surface resistances and solar act only with air boundaries
            found |= {"r_si": "resistance", "r_se": "resistance"}
            found["solar_absorptance"] = "dimensionless"
        return found

    def output_names(self) -> tuple[str, ...]:
        return tuple(self.outputs)

    def input_names(self) -> tuple[str, ...]:
        if self.boundary == "surface":
            return ("temp_surf_out", "temp_surf_in")
        solar = ("poa_global_out",) if self.solar_absorptance > 0 else ()
        return ("temp_air_out", "temp_air_in", *solar)


_BOX_KINDS = {"k_wall": "conductivity", "d_wall": "density", "c_wall": "specific_heat"}
_BOX_KINDS |= {"r_ag": "resistance", "r_glass": "resistance", "c_internal": "capacity"}
_BOX_KINDS |= {name: "length" for name in ("thickness", "side", "glazed_side")}
_BOX_KINDS |= {f"h_in_{s}": "coefficient" for s in ("wall", "ceiling", "floor")}
_BOX_KINDS |= {"h_out_a": "coefficient", "h_out_b": "wind_coefficient", "ua_leak": "conductance"}
"""Kinds of the box constants; the others (t_w, emissivities, absorptivity, albedo) are [-]."""


class BoxSimulator(_SimulatorBase):
    """``type = "box"``: the built-in test box (:class:`bayescal.simulators.box.TestBox`)."""

    type: Literal["box"] = _f("Simulator type.", "box")
    mode: Literal["coheating", "freefloat"] = _f(
        "'coheating': indoor air temperature imposed, heating power computed; 'freefloat': "
        "indoor air temperature computed (heat_input optional).",
        "coheating",
    )
    latitude: float = _f("Site latitude, north positive. [°]", 50.69, ge=-90, le=90)
    longitude: float = _f("Site longitude, east positive. [°]", 4.53, ge=-180, le=180)
    altitude: float = _f("Site altitude. [m]", 100.0, default=0.0)
    window_azimuth: float = _f(
        "Azimuth the window faces, clockwise from north (180 = south). [°]",
        180.0,
        default=180.0,
        ge=0,
        lt=360,
    )
    constants: dict[str, float] = _f(
        "Values overriding the box's nominal constants (bayescal.simulators.box.DEFAULTS: "
        "k_wall [W/(m·K)], d_wall [kg/m³], c_wall [J/(kg·K)], r_ag [m²·K/W], t_w [-], "
        "emissivity [-], absorptivity [-], geometry and surface coefficients).",
        {"c_wall": 800.0, "emissivity": 0.85},
        default_factory=dict,
    )
    cells: int = _f("Finite-volume cells across the wall.", 20, default=20, ge=1)
    max_step: float = _f("Longest time step. [s]", 600.0, default=600.0, gt=0)
    sky_model: Literal["isotropic", "haydavies", "perez"] = _f(
        "Sky-diffuse transposition model.", "perez", default="haydavies"
    )

    @field_validator("constants")
    @classmethod
    def _known_constants(cls, value: dict[str, float]) -> dict[str, float]:
        from bayescal.simulators.box import DEFAULTS

        for name in value:
            if name not in DEFAULTS:
                raise ValueError(f"{name!r} is not a box constant{_suggest(name, list(DEFAULTS))}")
        return value

    def target_kinds(self) -> dict[str, str]:
        from bayescal.simulators.box import DEFAULTS

        return {name: _BOX_KINDS.get(name, "dimensionless") for name in DEFAULTS}

    def output_names(self) -> tuple[str, ...]:
        return ("heating_power",) if self.mode == "coheating" else ("temp_air_in",)

    def input_names(self) -> tuple[str, ...]:
        control = ("temp_air_in",) if self.mode == "coheating" else ()
        return ("temp_air_out", "ghi", "dhi", "wind_speed", *control)


# --------------------------------------------------------------------------- energyplus

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


def energyplus_field_key(field: str) -> str:
    """epJSON key of a field named as in the IDD (``"Specific Heat"`` -> ``"specific_heat"``)."""
    return re.sub(r"[^0-9a-z]+", "_", field.strip().lower()).strip("_")


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


class EnergyPlusSchedule(_Section):
    """``[simulator.schedules.<glossary name>]``: the ``Schedule:File`` a forcing series feeds."""

    schedule: str = _f(
        "Name of the Schedule:File object in the model.", "TempSurfOut", min_length=1
    )
    lead_steps: int = _f(
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


class EnergyPlusOutput(_Section):
    """``[simulator.outputs.<name>]`` (energyplus): a report variable returned as a series."""

    variable: str = _f(
        "Report variable name.", "Surface Inside Face Conduction Heat Transfer Rate per Area"
    )
    key: str = _f("Key value (surface, zone... name), case-insensitive.", "Wall")
    scale: float = _f(
        "Factor applied to the values (-1 flips a sign convention). [-]", -1.0, default=1.0
    )


class EnergyPlusSection(_SimulatorBase):
    """``type = "energyplus"``: an EnergyPlus model
    (:class:`bayescal.simulators.energyplus.EnergyPlusSimulator`)."""

    path_keys: ClassVar[tuple[str, ...]] = ("model", "weather")

    type: Literal["energyplus"] = _f("Simulator type.", "energyplus")
    model: Path = _f(
        "The model, .epJSON or .idf (converted once by EnergyPlus), relative to the study "
        "folder (or absolute).",
        "paper_wall.epJSON",
    )
    schedules: dict[str, EnergyPlusSchedule] = _f(
        "Forcing series (glossary name) -> Schedule:File name, or {schedule, lead_steps}; "
        "each series is written as one CSV row per EnergyPlus time step.",
        {
            "temp_surf_out": "TempSurfOut",
            "temp_surf_in": {"schedule": "TempAirIn", "lead_steps": 1},
        },
        default_factory=dict,
    )
    outputs: dict[str, EnergyPlusOutput] = _f(
        "Output name (glossary name for calibrated outputs) -> {variable, key, scale}.",
        {
            "heat_flux_in": {
                "variable": "Surface Inside Face Conduction Heat Transfer Rate per Area",
                "key": "Wall",
            }
        },
        min_length=1,
    )
    weather: Literal["from-forcing"] | Path = _f(
        "'from-forcing' (an EPW written from the boundary conditions; absent series filled as "
        "bayescal.simulators.epw says) or an EPW file, relative to the study folder.",
        "from-forcing",
        "weather/uccle.epw",
        default="from-forcing",
    )
    algorithm: Literal["ConductionTransferFunction", "ConductionFiniteDifference"] | None = _f(
        "Heat-conduction algorithm (HeatBalanceAlgorithm); the model's if omitted.",
        "ConductionTransferFunction",
        default=None,
    )
    timesteps_per_hour: int | None = _f(
        "EnergyPlus time steps per hour, a divisor of 60 (at least 20 for "
        "ConductionFiniteDifference); the model's Timestep if omitted. [1/h]",
        6,
        default=None,
        ge=1,
        le=60,
    )
    warmup_days: int = _f(
        "Whole days simulated before the first sample with its boundary conditions. [d]",
        3,
        default=3,
        ge=0,
    )
    timeout: float = _f("A run taking longer is stopped and fails. [s]", 600.0, default=600.0, gt=0)

    @field_validator("model")
    @classmethod
    def _model(cls, value: Path, info: ValidationInfo) -> Path:
        resolved = _resolve(value, info, "a model file")
        if resolved.suffix.lower() not in (".epjson", ".idf"):
            raise ValueError(f"expected an .epJSON or .idf model, got {value.name!r}")
        return resolved

    @field_validator("weather")
    @classmethod
    def _weather(cls, value: str | Path, info: ValidationInfo) -> str | Path:
        if isinstance(value, str):
            return value
        resolved = _resolve(value, info, "'from-forcing' or an EPW file")
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
        _fail(problems)
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


# --------------------------------------------------------------------------- command

_RUN_FOLDER_RESERVED = ("forcing.csv", "stdout.txt", "stderr.txt")
"""Files the command simulator itself writes into each run folder."""


def _run_file(name: str, what: str) -> str:
    """A file name inside the run folder: relative, without '..', not a reserved name."""
    pure = PurePosixPath(name)
    if not name or "\\" in name or pure.is_absolute() or ".." in pure.parts:
        raise ValueError(
            f"{what} {name!r} must be a relative path inside the run folder, without '..'"
        )
    if str(pure) in (*_RUN_FOLDER_RESERVED, "."):
        raise ValueError(
            f"{what} {name!r} is reserved; the run folder holds {_RUN_FOLDER_RESERVED}"
        )
    return str(pure)


class CommandOutputs(_Section):
    """``[simulator.outputs]`` (command): the CSV file the program writes and its columns."""

    file: str = _f(
        "CSV file (with a header line) the program writes, relative to its run folder.",
        "out.csv",
        default="out.csv",
    )
    columns: dict[str, str] = _f(
        "Output name (glossary name for calibrated outputs) -> column of the file.",
        {"heat_flux_out": "q"},
        min_length=1,
    )
    time_column: str | None = _f(
        "Column with the time since the first sample [s]; checked against the study clock.",
        "time",
        default=None,
    )

    @field_validator("file")
    @classmethod
    def _file(cls, value: str) -> str:
        return _run_file(value, "output file")


class CommandSection(_SimulatorBase):
    """``type = "command"``: an external program run once per parameter set
    (:class:`bayescal.simulators.command.CommandSimulator`)."""

    type: Literal["command"] = _f("Simulator type.", "command")
    command: list[str] = _f(
        "Argument list, run without a shell in a fresh run folder. The program is a name on "
        "the PATH, an absolute path or a path relative to the study folder; arguments may "
        "hold {run_dir}, {base_dir}, {forcing_csv}, {output_csv}, {start}, {step}, {n} and "
        "{<rendered template name>}.",
        ["python3", "{base_dir}/rc_wall.py", "{output_csv}"],
        min_length=1,
    )
    templates: dict[str, str] = _f(
        "Template file (relative to the study folder) -> name of the rendered file in the run "
        "folder. Templates use $NAME or ${NAME} for the parameter targets, $$ for a dollar.",
        {"params.tmpl": "params.txt"},
        default_factory=dict,
    )
    inputs: list[str] = _f(
        "Boundary conditions written to forcing.csv (column time [s], then these, in "
        "internal units).",
        ["temp_air_out"],
        default_factory=list,
    )
    outputs: CommandOutputs = _f(
        "The output file and its columns.",
        {"file": "out.csv", "columns": {"heat_flux_out": "q"}, "time_column": "time"},
    )
    timeout: float = _f("Wall-clock limit of one run. [s]", 600.0, default=3600.0, gt=0)
    env: dict[str, str] = _f(
        "Environment variables added to (or replacing) the caller's.",
        {"OMP_NUM_THREADS": "1"},
        default_factory=dict,
    )

    @field_validator("command")
    @classmethod
    def _program(cls, value: list[str], info: ValidationInfo) -> list[str]:
        if not all(value):
            raise ValueError(f"arguments must not be empty, got {value!r}")
        if "/" in value[0] or (os.altsep and os.altsep in value[0]) or os.sep in value[0]:
            _resolve(Path(value[0]), info, "a program")
        return value

    @field_validator("templates")
    @classmethod
    def _templates(cls, value: dict[str, str], info: ValidationInfo) -> dict[str, str]:
        rendered: set[str] = set()
        for source, name in value.items():
            _resolve(Path(source), info, "a template file")
            target = _run_file(name, "rendered template name")
            if target in rendered:
                raise ValueError(f"two templates render to the same file {target!r}")
            rendered.add(target)
        return value

    @model_validator(mode="after")
    def _consistent(self) -> CommandSection:
        problems = []
        if len(set(self.inputs)) != len(self.inputs):
            problems.append(f"simulator.inputs: repeated names in {self.inputs}")
        if self.outputs.file in {_run_file(n, "") for n in self.templates.values()}:
            problems.append(
                f"simulator.outputs.file: {self.outputs.file!r} is also a rendered template"
            )
        _fail(problems)
        return self

    def target_kind(self, target: str) -> str | None:
        if not (target.isascii() and target.isidentifier()):
            raise ValueError(
                f"{target!r} is not a template placeholder name (letters, digits and _, not "
                "starting with a digit)"
            )
        return None

    def output_names(self) -> tuple[str, ...]:
        return tuple(self.outputs.columns)

    def input_names(self) -> tuple[str, ...]:
        return tuple(self.inputs)


# --------------------------------------------------------------------------- fmu


class FmuSection(_SimulatorBase):
    """``type = "fmu"``: a co-simulation FMU, FMI 2.0 or 3.0
    (:class:`bayescal.simulators.fmu.FmuSimulator`)."""

    path_keys: ClassVar[tuple[str, ...]] = ("fmu",)

    type: Literal["fmu"] = _f("Simulator type.", "fmu")
    fmu: Path = _f(
        "The .fmu file (or an extracted FMU folder), relative to the study folder (or absolute).",
        "wall.fmu",
    )
    inputs: dict[str, str] = _f(
        "FMU input variable -> boundary condition (glossary name) that feeds it.",
        {"T_out": "temp_air_out"},
        default_factory=dict,
    )
    outputs: dict[str, str] = _f(
        "Output name (glossary name for calibrated outputs) -> FMU variable.",
        {"heat_flux_out": "q"},
        min_length=1,
    )
    start_values: dict[str, float] = _f(
        "Further FMU variables fixed for every run (in the FMU's units).",
        {"T0": 293.15},
        default_factory=dict,
    )
    units: dict[str, str] = _f(
        "FMU input or output variable -> the unit it uses (see bayescal.units), converted "
        "from and to internal units; variables not listed are passed unchanged. Parameters "
        "are never converted.",
        {"T_out": "K", "T": "K"},
        default_factory=dict,
    )
    start_time: float = _f("FMU time of the first sample. [s]", 0.0, default=0.0)
    substeps: int = _f("Communication steps per study time step.", 4, default=1, ge=1)
    tolerance: float | None = _f(
        "Relative tolerance of the FMU's solver; its default if omitted. [-]",
        1e-6,
        default=None,
        gt=0,
    )

    @field_validator("fmu")
    @classmethod
    def _fmu(cls, value: Path, info: ValidationInfo) -> Path:
        return _resolve(value, info, "an FMU file")

    @model_validator(mode="after")
    def _consistent(self) -> FmuSection:
        problems = []
        connected = {*self.inputs, *self.outputs.values()}
        for var, unit in self.units.items():
            if var not in connected:
                problems.append(
                    f"simulator.units.{var}: {var!r} is no FMU input or output of this section"
                )
            try:
                dimension_of(unit)
            except DataError as exc:
                problems.append(f"simulator.units.{var}: {exc.one_line()}")
        _fail(problems)
        return self

    def target_kind(self, target: str) -> str | None:
        if not target.strip():
            raise ValueError("an FMU variable name must not be empty")
        if target in self.start_values:
            raise ValueError(f"{target!r} is also fixed in simulator.start_values; remove it there")
        return None

    def output_names(self) -> tuple[str, ...]:
        return tuple(self.outputs)

    def input_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.inputs.values()))


SimulatorSection = Annotated[
    Union[WallSimulator, BoxSimulator, EnergyPlusSection, CommandSection, FmuSection],  # noqa: UP007
    Field(discriminator="type"),
]
"""The simulator union; a new simulator type is one more class here."""
