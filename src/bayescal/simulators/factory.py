"""Build the simulator a study describes.

The study's ``[simulator]`` section says which simulator and its fixed inputs;
``[parameters.<name>].targets`` says what each calibration parameter sets.
:func:`build_simulator` returns an object following the
:class:`~bayescal.simulators.base.Simulator` protocol whose parameter names are
the study's parameter names.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from bayescal.config import (
    BoxSimulator,
    CommandSection,
    EnergyPlusSection,
    FmuSection,
    Study,
    WallSimulator,
)
from bayescal.config_simulators import parse_energyplus_target
from bayescal.errors import ConfigError
from bayescal.simulators.base import Forcing, Simulator, check_parameters
from bayescal.simulators.fvm import Layer


@dataclass(frozen=True)
class TargetedSimulator:
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

    inner: Simulator
    targets: Mapping[str, tuple[str, ...]]

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.targets)

    @property
    def input_names(self) -> tuple[str, ...]:
        return self.inner.input_names

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.inner.output_names

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        check_parameters(parameters, self.parameter_names, type(self.inner).__name__)
        inner = {t: float(v) for name, v in parameters.items() for t in self.targets[name]}
        return self.inner.simulate(inner, forcing)


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

    parameters = {
        name: [FieldTarget(*parse_energyplus_target(t)) for t in p.targets]
        for name, p in study.parameters.items()
    }
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


def _command(section: CommandSection, study: Study) -> Simulator:
    from bayescal.simulators.command import CommandSimulator

    targets = {name: tuple(p.targets) for name, p in study.parameters.items()}
    nominal = {t: p.nominal for p in study.parameters.values() for t in p.targets}
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
    return TargetedSimulator(command, targets)


def _fmu(section: FmuSection, study: Study) -> Simulator:
    from bayescal.simulators.fmu import FmuSimulator

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


def build_simulator(study: Study) -> Simulator:
    """The simulator of ``study``, taking the study's parameter names.

    Files the study names (EnergyPlus model, templates, program, FMU) are
    read here, so problems in them surface now, before any run.

    Raises
    ------
    ConfigError
        If the simulator type has no builder, or (command, FMU) for a
        template, program or variable the files do not have.
    SimulatorError
        If an EnergyPlus model or an FMU cannot be read, or lacks an object,
        schedule or variable the study names.
    """
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
