"""Build the simulator a study describes, and the nominal values of its parameters.

The study's ``[simulator]`` section says which simulator and its fixed inputs;
``[parameters.<name>].targets`` says what each calibration parameter sets.
:func:`build_simulator` returns an object following the
:class:`~bayescal.simulators.base.Simulator` protocol whose parameter names are
the study's parameter names. Errors a study can cause in its files are
raised as :class:`~bayescal.errors.ConfigError` naming the study key.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from bayescal.config.base import path_problem
from bayescal.config.energyplus import (
    EnergyPlusOutput,
    EnergyPlusSection,
    parse_energyplus_target,
)
from bayescal.config.external import CommandSection, FmuSection
from bayescal.config.simulators import BoxSimulator, WallSimulator
from bayescal.config.study import Study
from bayescal.config.targets import parse_sensor_target
from bayescal.errors import BayescalError, ConfigError, SimulatorError
from bayescal.simulators.base import Simulator
from bayescal.simulators.energyplus_model import energyplus_field_key
from bayescal.simulators.fvm import Layer
from bayescal.simulators.wrappers import (
    FixedParameters,
    IntervalMeans,
    SensorModel,
    TargetedSimulator,
)

__all__ = ["build_simulator", "nominal_parameters"]


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
        sky_air_split=section.sky_air_split,
        window_model=section.window_model,
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
            outputs={n: _energyplus_output(n, o, study) for n, o in section.outputs.items()},
            weather=section.weather,
            timesteps_per_hour=section.timesteps_per_hour,
            algorithm=section.algorithm,
            warmup_days=section.warmup_days,
            timeout=section.timeout,
            workdir=study.root / study.study.output_dir / "energyplus"
            if section.keep_outputs
            else None,
            keep_outputs=section.keep_outputs,
        )
    except SimulatorError as exc:
        raise _energyplus_problem(section, study) or exc from None


def _energyplus_output(name: str, output: EnergyPlusOutput, study: Study) -> dict[str, Any]:
    """One ``[simulator.outputs.<name>]`` as the adapter takes it, aggregated like its data."""
    column = study.data.columns.get(name)
    spec: dict[str, Any] = {
        "scale": output.scale,
        "aggregate": column.aggregate if column is not None else "point",
    }
    if output.meter is not None:
        spec["meter"] = output.meter
        spec["aggregate"] = "sum" if spec["aggregate"] == "point" else spec["aggregate"]
    else:
        spec |= {"variable": output.variable, "key": output.key}
    return spec


def _require_file(path: Path, key: str, what: str) -> None:
    problem = path_problem(path)
    if problem is not None:
        where = f"{what} {path.name!r} in {str(path.parent)!r}"
        raise ConfigError(
            f"{what} {path.name!r} does not exist in {str(path.parent)!r}"
            if problem == "file not found"
            else f"{where}: {problem}",
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
    from bayescal.simulators.energyplus_model import load_model

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


def build_simulator(study: Study, *, screening: bool = False) -> Simulator:
    """The simulator of ``study``, taking the study's parameter names.

    Screening candidates (``screen = true``) are held at their nominal values
    unless ``screening`` is true (then every parameter is free: ``bayescal
    screen`` and ``bayescal simulate``).

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
        simulator = _build_physics(study)
    else:
        physics = {name: p for name, p in study.parameters.items() if name not in sensors}
        inner = _build_physics(study.model_copy(update={"parameters": physics}))
        simulator = SensorModel(inner, tuple(study.parameters), sensors)
    if screening or not study.candidates:
        return simulator
    fixed = {name: study.parameters[name].nominal for name in study.candidates}
    return FixedParameters(simulator, fixed)


def _build_physics(study: Study) -> Simulator:
    """The simulator of the study's ``[simulator]`` section (no sensor model)."""
    section = study.simulator
    if isinstance(section, WallSimulator):
        return _interval_means(_wall(section, study), section, study)
    if isinstance(section, BoxSimulator):
        return _interval_means(_box(section, study), section, study)
    if isinstance(section, EnergyPlusSection):
        return _energyplus(section, study)
    if isinstance(section, CommandSection):
        return _command(section, study)
    if isinstance(section, FmuSection):
        return _fmu(section, study)
    raise ConfigError(f"simulator.type {section.type!r} cannot be built yet")


def _interval_means(
    simulator: Simulator, section: WallSimulator | BoxSimulator, study: Study
) -> Simulator:
    """The built-in ``simulator``, its outputs whose data say ``aggregate = "mean"`` averaged."""
    columns = study.data.columns
    means = tuple(
        sorted(
            name
            for name in (*study.outputs.calibrate, *study.outputs.held_out)
            if name in columns and columns[name].aggregate == "mean"
        )
    )
    return IntervalMeans(simulator, means, section.substeps) if means else simulator


def nominal_parameters(study: Study) -> dict[str, float]:
    """Nominal value of every calibration parameter (physical units)."""
    return {name: p.nominal for name, p in study.parameters.items()}
