"""Build the simulator a study describes.

The study's ``[simulator]`` section says which simulator and its fixed inputs;
``[parameters.<name>].targets`` says what each calibration parameter sets.
:func:`build_simulator` returns an object following the
:class:`~bayescal.simulators.base.Simulator` protocol whose parameter names are
the study's parameter names. Errors a study can cause in its files are
raised as :class:`~bayescal.errors.ConfigError` naming the study key.

:func:`energyplus_test_box` builds the Annex 58 test box of the paper from the
shipped EnergyPlus model ``simulators/models/test_box.epJSON`` (its docstring
describes that model), the counterpart of the built-in
:class:`~bayescal.simulators.box.TestBox`.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from bayescal.config import (
    BoxSimulator,
    CommandSection,
    EnergyPlusSection,
    FmuSection,
    Study,
    WallSimulator,
)
from bayescal.config_simulators import (
    energyplus_field_key,
    parse_energyplus_target,
    parse_sensor_target,
)
from bayescal.errors import BayescalError, ConfigError, SimulatorError
from bayescal.simulators.base import Forcing, Simulator, check_parameters
from bayescal.simulators.fvm import Layer

if TYPE_CHECKING:
    from bayescal.simulators.energyplus import EnergyPlusSimulator


@dataclass(frozen=True)
class _Wrapped:
    """A simulator wrapped around ``inner``, with its boundary conditions and outputs."""

    inner: Simulator

    @property
    def input_names(self) -> tuple[str, ...]:
        return self.inner.input_names

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.inner.output_names


@dataclass(frozen=True)
class TargetedSimulator(_Wrapped):
    """Expose a simulator whose own parameters are fixed names under study names.

    Each study parameter sets one or more of the inner simulator's parameters
    (its targets) to the same value.

    Parameters
    ----------
    inner
        The simulator; its ``parameter_names`` are the possible targets.
    targets
        Study parameter name -> inner parameter names.
    """

    targets: Mapping[str, tuple[str, ...]]

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.targets)

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        check_parameters(parameters, self.parameter_names, type(self.inner).__name__)
        inner = {t: float(v) for name, v in parameters.items() for t in self.targets[name]}
        return self.inner.simulate(inner, forcing)


@dataclass(frozen=True)
class SensorModel(_Wrapped):
    """A simulator whose outputs pass through calibrated sensors.

    ``reading = gain * simulated + offset`` per output, with gains and offsets
    set by study parameters whose targets are ``"measured.<output>.gain"`` or
    ``".offset"`` (the other parameters go to the inner simulator). A gain or
    offset absent from the study is 1 or 0.

    Parameters
    ----------
    inner
        The simulator of the physics.
    names
        All study parameter names, in the study's order.
    sensors
        Study parameter name -> its ``(output, "gain" | "offset")`` targets.
    """

    names: tuple[str, ...]
    sensors: Mapping[str, tuple[tuple[str, str], ...]]

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.names

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        check_parameters(parameters, self.parameter_names, type(self.inner).__name__)
        inner = {k: v for k, v in parameters.items() if k not in self.sensors}
        out = dict(self.inner.simulate(inner, forcing))
        gain: dict[str, float] = {}
        offset: dict[str, float] = {}
        for name, targets in self.sensors.items():
            for output, prop in targets:
                (gain if prop == "gain" else offset)[output] = float(parameters[name])
        for output in {*gain, *offset}:
            if output not in out:
                raise SimulatorError(
                    f"the simulator produced no {output!r} for its sensor model",
                    hint=f"it produced {', '.join(out)}",
                )
            out[output] = gain.get(output, 1.0) * np.asarray(out[output]) + offset.get(output, 0.0)
        return out


def _targets(study: Study) -> dict[str, Sequence[str]]:
    return {name: list(p.targets) for name, p in study.parameters.items()}


def _wall(section: WallSimulator, study: Study) -> Simulator:
    from bayescal.simulators.wall import MultilayerWall

    layers = [
        Layer(spec.name, spec.thickness, spec.conductivity, spec.density, spec.specific_heat)
        for spec in section.layers
    ]
    return MultilayerWall(
        layers,
        parameters=_targets(study),
        boundary=section.boundary,
        r_se=section.r_se,
        r_si=section.r_si,
        solar_absorptance=section.solar_absorptance,
        outputs=tuple(section.outputs),
        scheme=section.scheme,
        tolerance=section.tolerance,
        cells=section.cells,
    )


def _box(section: BoxSimulator, study: Study) -> Simulator:
    from bayescal.simulators.box import TestBox

    inner_names = tuple(sorted({t for p in study.parameters.values() for t in p.targets}))
    box = TestBox(
        mode=section.mode,
        latitude=section.latitude,
        longitude=section.longitude,
        altitude=section.altitude,
        window_azimuth=section.window_azimuth,
        parameters=inner_names,
        cells=section.cells,
        max_step=section.max_step,
        sky_model=section.sky_model,
        **section.constants,
    )
    targets = {name: tuple(p.targets) for name, p in study.parameters.items()}
    return TargetedSimulator(box, targets)


def _energyplus(section: EnergyPlusSection, study: Study) -> Simulator:
    from bayescal.simulators.energyplus import (
        EnergyPlusSimulator,
        FieldTarget,
        ScheduleInput,
    )

    _require_file(section.model, "simulator.model", "EnergyPlus model")
    if isinstance(section.weather, Path):
        _require_file(section.weather, "simulator.weather", "weather file")
    parameters = {
        name: [FieldTarget(*parse_energyplus_target(t)) for t in p.targets]
        for name, p in study.parameters.items()
    }
    try:
        return EnergyPlusSimulator(
            section.model,
            parameters=parameters,
            schedules={
                n: ScheduleInput(s.schedule, s.lead_steps) for n, s in section.schedules.items()
            },
            outputs={n: (o.variable, o.key, o.scale) for n, o in section.outputs.items()},
            weather=section.weather,
            timesteps_per_hour=section.timesteps_per_hour,
            algorithm=section.algorithm,
            warmup_days=section.warmup_days,
            timeout=section.timeout,
        )
    except SimulatorError as exc:
        raise _energyplus_problem(section, study) or exc from None


def _require_file(path: Path, key: str, what: str) -> None:
    if not path.is_file():
        raise ConfigError(
            f"{what} {path.name!r} does not exist in {str(path.parent)!r}",
            hint="correct the path (relative to the study folder) or copy the file there",
            source=key,
        )


def _named(objects: Mapping[str, Any], name: str) -> Any:
    """The object of that name, EnergyPlus names being case-insensitive; None if absent."""
    return next((v for k, v in objects.items() if k.lower() == name.lower()), None)


def _choices(name: str, valid: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, list(valid), n=1, cutoff=0.5)
    return f"did you mean {close[0]!r}?" if close else f"choose one of {sorted(valid)}"


def _energyplus_problem(section: EnergyPlusSection, study: Study) -> ConfigError | None:
    """The first target or schedule of the study the model lacks, as a keyed ConfigError.

    Called once construction has failed (so the model is read only then).
    """
    from bayescal.simulators.energyplus import load_model

    model = load_model(section.model)
    types = {key.lower(): value for key, value in model.items()}
    found = section.model.name
    for name, parameter in study.parameters.items():
        for target in parameter.targets:
            kind, obj, field = parse_energyplus_target(target)
            objects = types.get(kind.lower(), {})
            fields = _named(objects, obj)
            key = f"parameters.{name}.targets"
            if fields is None:
                listed = (
                    _choices(obj, list(objects))
                    if objects
                    else f"it has no {kind} objects; {_choices(kind, list(model))}"
                )
                return ConfigError(f"{found} has no {kind} named {obj!r}; {listed}", source=key)
            numeric = [k for k, v in fields.items() if isinstance(v, int | float)]
            value = fields.get(energyplus_field_key(field))
            where = f"{kind} {obj!r} in {found}"
            if value is None:
                return ConfigError(
                    f"{where} has no field {field!r} (written as in the IDD, 'Specific Heat', "
                    f"or in epJSON, 'specific_heat'); {_choices(field, numeric)}",
                    source=key,
                )
            if isinstance(value, bool) or not isinstance(value, int | float):
                return ConfigError(
                    f"field {field!r} of {where} is {value!r}, not a number; calibrate one of "
                    f"its numeric fields {sorted(numeric)}",
                    source=key,
                )
    schedules = types.get("schedule:file", {})
    for series, spec in section.schedules.items():
        if _named(schedules, spec.schedule) is None:
            return ConfigError(
                f"{found} has no Schedule:File named {spec.schedule!r}; "
                f"{_choices(spec.schedule, list(schedules))}",
                source=f"simulator.schedules.{series}",
            )
    return None


def _command(section: CommandSection, study: Study) -> Simulator:
    from bayescal.simulators.command import CommandSimulator

    targets = {name: tuple(p.targets) for name, p in study.parameters.items()}
    nominal = {t: p.nominal for p in study.parameters.values() for t in p.targets}
    try:
        command = CommandSimulator(
            section.command,
            base_dir=study.root,
            parameters=tuple(nominal),
            outputs=section.outputs.columns,
            templates=section.templates,
            inputs=section.inputs,
            output_file=section.outputs.file,
            time_column=section.outputs.time_column,
            nominal=nominal,
            timeout=section.timeout,
            env=section.env,
        )
    except ConfigError as exc:
        raise _keyed(exc, _command_key(exc, section, study.root)) from None
    return TargetedSimulator(command, targets)


def _keyed(error: BayescalError, key: str | None) -> BayescalError:
    """``error`` as a ConfigError prefixed with the study key it concerns (if known)."""
    return error if key is None else ConfigError(error.one_line(), source=key)


def _command_key(error: ConfigError, section: CommandSection, root: Path) -> str | None:
    """The study key a command simulator's construction error is about."""
    templates = {str(Path(os.path.normpath(root / name))) for name in section.templates}
    if error.source is not None and error.source in templates:
        return "simulator.templates"
    if "executable" in error.message:
        return "simulator.command"
    return None


def _fmu(section: FmuSection, study: Study) -> Simulator:
    from bayescal.simulators.fmu import FmuSimulator

    if not section.fmu.exists():
        _require_file(section.fmu, "simulator.fmu", "FMU")
    try:
        return FmuSimulator(
            section.fmu,
            parameters={name: tuple(p.targets) for name, p in study.parameters.items()},
            inputs=section.inputs,
            outputs=section.outputs,
            start_values=section.start_values,
            units=section.units,
            start_time=section.start_time,
            substeps=section.substeps,
            tolerance=section.tolerance,
        )
    except BayescalError as exc:
        raise _keyed(exc, _fmu_key(section, study)) from None


def _fmu_key(section: FmuSection, study: Study) -> str | None:
    """The first study key naming a variable the FMU does not have (None if all exist)."""
    from fmpy import read_model_description

    try:
        names = {v.name for v in read_model_description(str(section.fmu)).modelVariables}
    except Exception:  # FMPy raises bare Exceptions; the original error then stands
        return None
    references = [
        (f"parameters.{n}.targets", t) for n, p in study.parameters.items() for t in p.targets
    ]
    references += [("simulator.inputs", var) for var in section.inputs]
    references += [(f"simulator.outputs.{name}", var) for name, var in section.outputs.items()]
    references += [("simulator.start_values", var) for var in section.start_values]
    return next((key for key, var in references if var not in names), None)


TEST_BOX_TARGETS: dict[str, tuple[str, str, str]] = {
    "k_wall": ("Material", "BoxWall", "Conductivity"),
    "d_wall": ("Material", "BoxWall", "Density"),
    "r_ag": ("WindowMaterial:Gas", "Cavity", "Thickness"),
    "t_w": ("WindowMaterial:Glazing", "OuterPane", "Solar Transmittance at Normal Incidence"),
}
"""The paper's four test-box parameters (names of :mod:`bayescal.simulators.box`) -> the
field of ``models/test_box.epJSON`` each sets (object type, name, field)."""

_BOX_CONTROL_OBJECTS = (
    "ZoneControl:Thermostat",
    "ThermostatSetpoint:SingleHeatingOrCooling",
    "ZoneHVAC:IdealLoadsAirSystem",
    "ZoneHVAC:EquipmentList",
    "ZoneHVAC:EquipmentConnections",
)


def energyplus_test_box(
    mode: Literal["coheating", "freefloat"] = "coheating",
    *,
    latitude: float | None = None,
    longitude: float | None = None,
    time_zone: float | None = None,
    altitude: float | None = None,
    window_azimuth: float = 180.0,
    heat_input: bool = False,
    outputs: Mapping[str, Sequence[Any]] | None = None,
    **options: Any,
) -> EnergyPlusSimulator:
    """The Annex 58 test box in EnergyPlus (``models/test_box.epJSON``).

    The same box as :class:`bayescal.simulators.box.TestBox`, with the same
    parameter names (:data:`TEST_BOX_TARGETS`), inputs and outputs, so that
    either can stand in for the other in a study.

    The model
    ---------
    Geometry
        One zone, a 96 cm inner cube on a stand (floor 0.5 m above the
        ground, exposed to outside air, seeing only the ground); surfaces on
        inner dimensions, as the built-in box. A 52 x 52 cm window, centred in
        the south wall; the frame band of the 60 x 60 cm opening is wall.
    Walls, roof and floor
        One 12 cm homogeneous layer ``Material BoxWall`` (``k_wall`` = 0.125
        W/(m·K), ``d_wall`` = 2250 kg/m³, 800 J/(kg·K); thermal absorptance
        0.85, solar 0.4), conduction transfer functions at 6 steps per hour.
    Window
        Two 4 mm panes at 1 W/(m·K) (``r_glass`` 0.008 m²·K/W) around a
        custom gas ``Cavity`` of conductivity 1 W/(m·K) and a viscosity high
        enough to suppress convection, so that the cavity's thickness in m is
        its resistance ``r_ag`` in m²·K/W. The pane faces towards the cavity
        have emissivity 0.001: the cavity conducts only, as ``r_ag`` in
        :mod:`~bayescal.simulators.box`. The outer pane transmits ``t_w`` at
        normal incidence (reflectance 0.075, the rest absorbed); the inner
        pane is clear (transmittance 1), so that the window's normal
        transmittance is ``t_w``. Unlike the built-in box, EnergyPlus keeps
        the solar power absorbed in the outer pane and uses its own angular
        dependence (one pane instead of two).
    Surface coefficients
        Inside: the built-in box's combined coefficients imposed as
        convection coefficients (walls and window 1/0.13, ceiling 1/0.10,
        floor 1/0.17 W/(m²·K)); EnergyPlus adds long-wave exchange between the
        inside faces, which the built-in box folds into those coefficients.
        Outside: ``4 + 4 v`` W/(m²·K) with the weather file's wind speed ``v``
        (ISO 6946 annex C, a user curve) and EnergyPlus's long-wave exchange
        with sky, air and ground (a vertical face sees part of its sky view
        at air temperature; the built-in box sees the sky alone).
    Control
        ``"coheating"``: an unlimited ideal-loads system holds the zone air at
        the ``TempAirIn`` schedule (``temp_air_in``); ``heating_power`` [W] is
        the heat it adds to the air (``Zone Air Heat Balance System Air
        Transfer Rate``, negative when it cools). ``"freefloat"``: no
        thermostat; ``temp_air_in`` [°C] is the zone mean air temperature,
        and with ``heat_input`` a convective heater adds the series
        ``heat_input`` [W] (schedule ``HeatInput``, design level 1 W).
    Weather
        Written from the forcing (:mod:`bayescal.simulators.epw`:
        ``temp_air_out``, ``ghi``, ``dhi``, ``wind_speed``, and
        ``relative_humidity`` and ``ir_horizontal`` where given) unless
        ``weather=`` names an EPW file.

    The model file holds both controls (thermostat and heater); this
    function removes what ``mode`` does not use. A study can use the file
    itself (``type = "energyplus"``) with both schedules mapped, or a copy
    edited to one mode; there ``r_ag`` targets ``WindowMaterial:Gas:Cavity:
    Thickness`` and so takes the unit ``m``.

    Parameters
    ----------
    mode
        ``"coheating"`` or ``"freefloat"``.
    latitude, longitude
        Site, north and east positive; default the model's (Limelette,
        Belgium: 50.69, 4.53). [°]
    time_zone
        Local standard time minus UTC; default the model's (1). [h]
    altitude
        Site elevation; default the model's (100). [m]
    window_azimuth
        Azimuth the window faces, clockwise from north. [°]
    heat_input
        Free-float only: whether the forcing has a ``heat_input`` series
        driving the heater.
    outputs
        Further outputs, name -> ``(variable, key)`` or ``(variable, key,
        scale)`` (surface temperatures, transmitted solar...).
    **options
        Further :class:`~bayescal.simulators.energyplus.EnergyPlusSimulator`
        arguments (``parameters``, ``timesteps_per_hour``, ``weather``...).

    Raises
    ------
    SimulatorError
        For an unknown mode, or ``heat_input`` with co-heating.
    """
    import json
    import tempfile

    from bayescal.simulators.energyplus import (
        MODELS,
        EnergyPlusSimulator,
        FieldTarget,
        load_model,
    )

    if mode not in ("coheating", "freefloat"):
        raise SimulatorError(f"mode must be 'coheating' or 'freefloat', got {mode!r}")
    if heat_input and mode == "coheating":
        raise SimulatorError(
            "heat_input applies to mode 'freefloat' only; the heating is the output"
        )
    model = load_model(MODELS / "test_box.epJSON")
    site = model["Site:Location"]["Limelette"]
    given = {"latitude": latitude, "longitude": longitude, "time_zone": time_zone}
    site.update({k: float(v) for k, v in given.items() if v is not None})
    if altitude is not None:
        site["elevation"] = float(altitude)
    model["Building"]["Annex 58 test box"]["north_axis"] = (float(window_azimuth) - 180.0) % 360.0
    if mode == "freefloat":
        for key in (*_BOX_CONTROL_OBJECTS, "Schedule:Constant"):
            del model[key]
        del model["Schedule:File"]["TempAirIn"]
    if not heat_input:
        del model["OtherEquipment"]
        del model["Schedule:File"]["HeatInput"]
    schedules = {"temp_air_in": "TempAirIn"} if mode == "coheating" else {}
    if heat_input:
        schedules["heat_input"] = "HeatInput"
    main = {
        "coheating": {"heating_power": ("Zone Air Heat Balance System Air Transfer Rate", "Box")},
        "freefloat": {"temp_air_in": ("Zone Mean Air Temperature", "Box")},
    }[mode]
    options.setdefault("parameters", {n: FieldTarget(*t) for n, t in TEST_BOX_TARGETS.items()})
    with tempfile.TemporaryDirectory(prefix="bayescal-test-box-") as tmp:
        path = Path(tmp) / f"test_box-{mode}.epJSON"
        path.write_text(json.dumps(model), encoding="utf-8")
        return EnergyPlusSimulator(
            path, schedules=schedules, outputs={**main, **(outputs or {})}, **options
        )


def build_simulator(study: Study) -> Simulator:
    """The simulator of ``study``, taking the study's parameter names.

    Files the study names (EnergyPlus model, templates, program, FMU) are
    read here, so problems in them surface now, before any run.

    Raises
    ------
    ConfigError
        If the simulator type has no builder, or a file the study names is
        missing or lacks what the study asks of it (an EnergyPlus object,
        field or schedule, a template placeholder, a program, an FMU
        variable); the message starts with the study key concerned, e.g.
        ``parameters.k_cb.targets:``.
    SimulatorError
        If an EnergyPlus model or an FMU cannot be read for another reason.

    Notes
    -----
    Parameters targeting ``"measured.<output>.gain"`` or ``".offset"`` wrap
    the simulator in a :class:`SensorModel`.
    """
    sensors = {
        name: tuple(found for t in p.targets if (found := parse_sensor_target(t)) is not None)
        for name, p in study.parameters.items()
    }
    sensors = {name: targets for name, targets in sensors.items() if targets}
    if not sensors:
        return _build_physics(study)
    physics = {name: p for name, p in study.parameters.items() if name not in sensors}
    inner = _build_physics(study.model_copy(update={"parameters": physics}))
    return SensorModel(inner, tuple(study.parameters), sensors)


def _build_physics(study: Study) -> Simulator:
    """The simulator of the study's ``[simulator]`` section (no sensor model)."""
    section = study.simulator
    if isinstance(section, WallSimulator):
        return _wall(section, study)
    if isinstance(section, BoxSimulator):
        return _box(section, study)
    if isinstance(section, EnergyPlusSection):
        return _energyplus(section, study)
    if isinstance(section, CommandSection):
        return _command(section, study)
    if isinstance(section, FmuSection):
        return _fmu(section, study)
    raise ConfigError(f"simulator.type {section.type!r} cannot be built yet")


def nominal_parameters(study: Study) -> dict[str, float]:
    """Nominal value of every calibration parameter (physical units)."""
    return {name: p.nominal for name, p in study.parameters.items()}
