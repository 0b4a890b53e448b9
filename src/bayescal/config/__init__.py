"""The study file: ``study.toml`` validated into frozen pydantic models.

Every field carries a description (with its unit in brackets) and examples;
the study-file reference (``docs/study-file.md``) is generated from these
models by :mod:`bayescal.config.reference`. The package re-exports its public
names, so ``from bayescal.config import Study, load_study`` works.

Modules
-------
:mod:`~bayescal.config.study`
    :class:`Study`, the small sections, the checks across sections,
    :func:`load_study` and :func:`study_from_dict`.
:mod:`~bayescal.config.data`
    ``[data]`` and its columns.
:mod:`~bayescal.config.parameters`
    ``[parameters.<name>]`` and the priors as the study file writes them.
:mod:`~bayescal.config.simulators`
    The ``[simulator]`` sections, one class per simulator type (EnergyPlus in
    :mod:`~bayescal.config.energyplus`, command and FMU in
    :mod:`~bayescal.config.external`).
:mod:`~bayescal.config.screening`
    ``[screening]``: the Morris design of ``bayescal screen``.
:mod:`~bayescal.config.targets`
    Calibration targets: their kinds and units, sensor-model targets.
:mod:`~bayescal.config.base`
    The section base class and the field, path and duration helpers.
:mod:`~bayescal.config.messages`
    Validation errors as one-line messages.
:mod:`~bayescal.config.build`
    The simulator a study describes (:func:`build_simulator`).
"""

from bayescal.config.base import Duration, Instant
from bayescal.config.build import build_simulator, nominal_parameters
from bayescal.config.data import FORMATS, ColumnSpec, DataSection
from bayescal.config.energyplus import EnergyPlusOutput, EnergyPlusSchedule, EnergyPlusSection
from bayescal.config.external import CommandOutputs, CommandSection, FmuSection
from bayescal.config.messages import format_errors
from bayescal.config.parameters import BetaPriorSpec, Parameter, PriorSpec, UniformPriorSpec
from bayescal.config.screening import ScreeningSection
from bayescal.config.simulators import BoxSimulator, LayerSpec, SimulatorSection, WallSimulator
from bayescal.config.study import (
    NUTS_MIN_WARMUP,
    STUDY_FILE,
    CalibrationSection,
    DesignSection,
    DiscrepancySection,
    EmulatorSection,
    OutputsSection,
    PeriodsSection,
    PredictSection,
    RunnerSection,
    Study,
    StudySection,
    load_study,
    study_from_dict,
)

__all__ = [
    "FORMATS",
    "NUTS_MIN_WARMUP",
    "STUDY_FILE",
    "BetaPriorSpec",
    "BoxSimulator",
    "CalibrationSection",
    "ColumnSpec",
    "CommandOutputs",
    "CommandSection",
    "DataSection",
    "DesignSection",
    "DiscrepancySection",
    "Duration",
    "EmulatorSection",
    "EnergyPlusOutput",
    "EnergyPlusSchedule",
    "EnergyPlusSection",
    "FmuSection",
    "Instant",
    "LayerSpec",
    "OutputsSection",
    "Parameter",
    "PeriodsSection",
    "PredictSection",
    "PriorSpec",
    "RunnerSection",
    "ScreeningSection",
    "SimulatorSection",
    "Study",
    "StudySection",
    "UniformPriorSpec",
    "WallSimulator",
    "build_simulator",
    "format_errors",
    "load_study",
    "nominal_parameters",
    "study_from_dict",
]
