"""The study: ``study.toml`` validated into frozen pydantic models, and loading it.

A study is a folder holding ``study.toml``; relative paths in it start at that
folder. :func:`load_study` reads the file with :mod:`tomllib`, validates it
into :class:`Study` and turns every problem into one
:class:`~bayescal.errors.ConfigError` whose message lists each problem with
its key path, the value received and what was expected, on one line
(:mod:`bayescal.config.messages`).

This module holds :class:`Study`, the small sections (``[study]``,
``[outputs]``, ``[periods]``, ``[emulator]``, ``[runner]``) and the checks
across sections; ``[data]``, ``[design]``, ``[predict]``, ``[parameters]``,
``[simulator]``, ``[calibration]``, ``[discrepancy]`` and ``[screening]`` have
modules of their own in :mod:`bayescal.config`.
"""

from __future__ import annotations

import hashlib
import json
import os
import tomllib
from datetime import timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import (
    BeforeValidator,
    ByteSize,
    PrivateAttr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from bayescal.clock import format_duration, parse_duration
from bayescal.config.base import (
    IDENTIFIER,
    Duration,
    Instant,
    Section,
    field_doc,
    local_time_problems,
    path_problem,
    raise_problems,
    resolve_path,
)
from bayescal.config.calibration import CalibrationSection
from bayescal.config.data import DataSection
from bayescal.config.design import DesignSection
from bayescal.config.discrepancy import DiscrepancySection
from bayescal.config.messages import format_errors
from bayescal.config.outputs import OutputsSection
from bayescal.config.parameters import DerivedSpec, Parameter, reserved_name_problems
from bayescal.config.predict import PredictSection
from bayescal.config.screening import ScreeningSection
from bayescal.config.simulators import SimulatorSection
from bayescal.config.targets import KIND_UNITS, SENSOR_PREFIX, normal_unit, parse_sensor_target
from bayescal.errors import ConfigError
from bayescal.expressions import Expression
from bayescal.glossary import GLOSSARY
from bayescal.mcmc.nuts import NUTS_MIN_WARMUP
from bayescal.optional import module_installed
from bayescal.units import same_scale

if TYPE_CHECKING:
    from bayescal.design import Prior

__all__ = [
    "NUTS_MIN_WARMUP",
    "STUDY_FILE",
    "CalibrationSection",
    "DesignSection",
    "DiscrepancySection",
    "EmulatorSection",
    "OutputsSection",
    "PeriodsSection",
    "PredictSection",
    "RunnerSection",
    "Study",
    "StudySection",
    "load_study",
    "study_from_dict",
]

STUDY_FILE = "study.toml"


# --------------------------------------------------------------------------- small sections


class StudySection(Section):
    """``[study]``: name, output folder and master seed."""

    name: str = field_doc("Name of the study, used in reports.", "paper-wall", min_length=1)
    output_dir: Path = field_doc(
        "Folder for artefacts, relative to the study folder (or absolute).",
        "out",
        default=Path("out"),
        validate_default=True,
    )
    seed: int = field_doc(
        "Master seed; stages without their own seed derive theirs.", 0, default=0, ge=0
    )
    description: str = field_doc("Free text shown in the report.", "Paper wall, 2012", default="")
    prior_from: Path | None = field_doc(
        "Another calibrated study (its folder or study file, relative to this study's "
        "folder): its posterior becomes the prior of the parameters the two share (a "
        "logit-normal density fitted to its draws on this study's bounds, correlations "
        "kept); the other parameters keep their own priors. The sequential calibration of "
        "the paper's conclusion, and `bayescal update`.",
        "../coheating",
        default=None,
    )

    @field_validator("output_dir")
    @classmethod
    def _inside(cls, value: Path, info: ValidationInfo) -> Path:
        return resolve_path(value, info, "a folder name")

    @field_validator("prior_from")
    @classmethod
    def _other(cls, value: Path | None, info: ValidationInfo) -> Path | None:
        if value is None or value.is_absolute():
            return value
        root = Path((info.context or {}).get("root", Path.cwd()))
        return Path(os.path.normpath(root / value))  # another study: may lie beside this one


def _length(value: object) -> object:
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 2:
            raise ValueError(f"a period needs at least 2 samples, got {value}")
        return value
    return parse_duration(value).to_pytimedelta()


class PeriodsSection(Section):
    """``[periods]``: warm-up, period length and the held-out test window (give one of
    ``test_samples`` and ``test_fraction``). At least two whole training periods must
    lie between the warm-up and the test window."""

    length: Annotated[timedelta | int, BeforeValidator(_length)] = field_doc(
        "Period length: a duration (multiple of data.step) or a number of samples.",
        "1D",
        48,
        default=timedelta(days=1),
    )
    warmup: Duration = field_doc(
        "Stretch at the start that is simulated but not compared (initial conditions); a "
        "multiple of data.step.",
        "1D",
        "0min",
        default=timedelta(days=1),
    )
    train_from: Instant | None = field_doc(
        "No training period starts before this instant (local time of the data); the record "
        "before it is simulated, not compared. `bayescal update` sets it to the previous "
        "test window's start. A test_fraction counts the record from one warm-up before it.",
        "2013-09-11T00:00:00",
        default=None,
    )
    test_samples: int | None = field_doc(
        "Test window at the end, in samples.", 300, default=None, ge=0
    )
    test_fraction: float | None = field_doc(
        "Test window at the end, as a fraction of the record.", 0.2, default=None, ge=0, lt=1
    )

    @model_validator(mode="after")
    def _one_test(self) -> PeriodsSection:
        if (self.test_samples is None) == (self.test_fraction is None):
            both = self.test_samples is not None
            raise ValueError(
                "give exactly one of test_samples and test_fraction, got "
                + (f"both ({self.test_samples}, {self.test_fraction})" if both else "neither")
            )
        if self.warmup < timedelta(0):
            raise ValueError(f"warmup must not be negative, got {self.warmup}")
        return self


class EmulatorSection(Section):
    """``[emulator]``: PCA bases and GP hyperparameters."""

    pca_variance: float = field_doc(
        "Output PCA: keep components up to this variance fraction (or pca_components).",
        0.95,
        default=0.90,
        gt=0,
        le=1,
    )
    pca_components: int | None = field_doc(
        "Output PCA: fixed number of components.", 3, default=None, ge=1
    )
    input_pca_variance: float = field_doc(
        "Boundary-condition PCA: variance fraction kept per series.", 0.9, default=0.90, gt=0, le=1
    )
    history_periods: int = field_doc(
        "Preceding periods whose boundary conditions also enter the variable inputs x "
        "(0: the paper's x, the current period only). A massive wall or room answers to "
        "the weather of the days before; 1 lets the emulator predict periods unlike the "
        "training ones (the wall example's test-window emulator MSE fell from 0.39 to "
        "0.022 (W/m²)²).",
        1,
        default=0,
        ge=0,
        le=7,
    )
    training: Literal["map", "mcmc"] = field_doc(
        "How the GP hyperparameters' MAP is found: 'map' (multi-start L-BFGS-B with the "
        "exact gradient, stopped by its convergence criteria, and a Laplace approximation "
        "for their uncertainty; at 500 runs x 200 periods x 5 bases many times faster than "
        "'mcmc' for the same MAP, docs/benchmarks.md) or 'mcmc' (the paper's "
        "Metropolis-within-Gibbs chains, burn and samples below, best draw refined).",
        "mcmc",
        default="map",
    )
    burn: int = field_doc(
        "training = 'mcmc': hyperparameter MCMC burn-in sweeps per chain (2 chains). The "
        "emulator uses the MAP (best draw refined by L-BFGS-B); on the wall example "
        "2 x (500 + 1000) and 2 x (1000 + 2000) sweeps gave the same MAP and "
        "leave-one-run-out RMSE.",
        500,
        default=500,
        ge=0,
    )
    samples: int = field_doc(
        "Hyperparameter draws kept: MCMC sweeps per chain (training = 'mcmc') or draws "
        "from the Laplace approximation (training = 'map').",
        1000,
        default=1000,
        ge=1,
    )
    algebra: Literal["kronecker", "dense"] = field_doc(
        "Linear algebra: fast Kronecker or the dense reference.", "dense", default="kronecker"
    )
    standardise: Literal["output", "pointwise"] = field_doc(
        "Scale of each output before the PCA: one number per output ('output': a sensor's "
        "noise keeps one size, so its SD is stated in the output's unit) or each sample's SD "
        "over the design runs ('pointwise', the paper: the implied noise then varies with the "
        "time of day). Both centre every sample on its mean over the runs.",
        "pointwise",
        default="output",
    )

    @model_validator(mode="after")
    def _one_rule(self) -> EmulatorSection:
        if self.pca_components is not None and "pca_variance" in self.model_fields_set:
            raise ValueError("give pca_variance or pca_components, not both")
        return self


class RunnerSection(Section):
    """``[runner]``: where simulator runs execute."""

    backend: Literal["serial", "processes", "dask"] = field_doc(
        "Execution backend.", "dask", default="processes"
    )
    jobs: int | None = field_doc("Parallel workers; all cores if omitted.", 4, default=None, ge=1)
    scheduler: str | None = field_doc(
        "Dask scheduler address (dask only); a LocalCluster if omitted.",
        "tcp://10.0.0.5:8786",
        default=None,
    )
    timeout: float | None = field_doc("Time limit per run. [s]", 600.0, default=None, gt=0)
    retries: int = field_doc("Retries of a failed run.", 1, default=0, ge=0)
    max_memory: ByteSize | None = field_doc(
        "Memory the study may use; the estimate of what its sizes imply (runs, record, "
        "samples, basis) is refused beyond it, before anything is allocated. Default: "
        "BAYESCAL_MAX_MEMORY if set, else this machine's memory. [B]",
        "64GiB",
        default=None,
    )
    max_disk: ByteSize | None = field_doc(
        "Disk the output folder may fill; the estimate of what the study writes is refused "
        "beyond it. Default: BAYESCAL_MAX_DISK if set, else the free space of the output "
        "folder's file system plus what the folder holds. [B]",
        "2TiB",
        default=None,
    )

    @model_validator(mode="after")
    def _scheduler_for_dask(self) -> RunnerSection:
        if self.scheduler is not None and self.backend != "dask":
            raise ValueError(f"scheduler applies to backend 'dask', not {self.backend!r}")
        return self


# --------------------------------------------------------------------------- the study


class Study(Section):
    """A validated study file; build it with :func:`load_study`.

    ``data.file``, ``study.output_dir`` and the simulator's paths (model,
    weather or FMU file) are absolute (relative ones were resolved against
    the study folder :attr:`root`); :attr:`path` is the file.
    """

    study: StudySection = field_doc("Name, output folder and seed.")
    data: DataSection = field_doc("Measured data.")
    simulator: SimulatorSection = field_doc("The simulator and its fixed inputs.")
    parameters: dict[str, Parameter] = field_doc("Calibration parameters by name (at least one).")
    outputs: OutputsSection = field_doc("Measured outputs to calibrate on.")
    periods: PeriodsSection = field_doc("Warm-up, periods and test window.")
    design: DesignSection = field_doc("Latin hypercube.", default_factory=DesignSection)
    emulator: EmulatorSection = field_doc("Emulator.", default_factory=EmulatorSection)
    calibration: CalibrationSection = field_doc(
        "Calibration MCMC.", default_factory=CalibrationSection
    )
    discrepancy: DiscrepancySection = field_doc(
        "Difference process.", default_factory=DiscrepancySection
    )
    predict: PredictSection = field_doc("Predictions with bands.", default_factory=PredictSection)
    runner: RunnerSection = field_doc("Simulation runner.", default_factory=RunnerSection)
    derived: dict[str, DerivedSpec] = field_doc(
        "Quantities computed from the parameters at every posterior draw, beside the "
        "simulator's own (the wall's U-value, resistance and areal heat capacity).",
        {"R_walls": {"expression": "0.3 / k_brick + 0.08 / k_eps", "unit": "m²·K/W"}},
        default_factory=dict,
    )
    screening: ScreeningSection = field_doc(
        "Morris screening (bayescal screen).", default_factory=ScreeningSection
    )

    _root: Path = PrivateAttr(default_factory=Path.cwd)
    _path: Path | None = PrivateAttr(default=None)

    @property
    def root(self) -> Path:
        """The study folder."""
        return self._root

    @property
    def path(self) -> Path:
        """The study file (``root / "study.toml"`` for a study built in code)."""
        return self._path if self._path is not None else self._root / STUDY_FILE

    @property
    def boundary_conditions(self) -> tuple[str, ...]:
        """Mapped columns that are neither calibrated nor held-out outputs."""
        measured = {*self.outputs.calibrate, *self.outputs.held_out}
        return tuple(n for n in self.data.columns if n not in measured)

    @property
    def calibrated(self) -> tuple[str, ...]:
        """Names of the parameters calibrated (those without ``screen = true``), in order."""
        return tuple(name for name, p in self.parameters.items() if not p.screen)

    @property
    def candidates(self) -> tuple[str, ...]:
        """Names of the screening candidates (``screen = true``), held at nominal by ``run``."""
        return tuple(name for name, p in self.parameters.items() if p.screen)

    def priors(self) -> dict[str, Prior]:
        """Calibrated parameter name -> prior (:class:`bayescal.design.Prior`), with unit and
        description; screening candidates are left out (:meth:`screening_priors` has all)."""
        return {name: self.parameters[name].to_prior() for name in self.calibrated}

    def screening_priors(self) -> dict[str, Prior]:
        """Every parameter's prior, candidates and calibrated ones, in study order."""
        return {name: parameter.to_prior() for name, parameter in self.parameters.items()}

    def expressions(self) -> dict[str, Expression]:
        """The ``[derived]`` expressions, parsed (names checked against the parameters)."""
        return {
            name: Expression.parse(spec.expression, list(self.parameters), f"derived.{name}")
            for name, spec in self.derived.items()
        }

    @field_validator("parameters")
    @classmethod
    def _parameter_names(cls, value: dict[str, Parameter]) -> dict[str, Parameter]:
        if not value:
            raise ValueError("no parameters; define at least one [parameters.<name>] table")
        bad = [name for name in value if not IDENTIFIER.match(name)]
        if bad:
            raise ValueError(f"parameter names are identifiers (letters, digits, _), got {bad}")
        return value

    @model_validator(mode="after")
    def _cross_checks(self) -> Study:
        problems = _target_problems(self) + _output_problems(self) + _period_problems(self)
        problems += _derived_problems(self)
        problems += reserved_name_problems(self.parameters, self.outputs.calibrate)
        problems += reserved_name_problems(self.derived, self.outputs.calibrate, "derived")
        problems += _sampler_problems(self) + _aggregate_problems(self) + _reuse_problems(self)
        problems += _design_problems(self)
        raise_problems(problems)
        return self

    def discrepancy_lengths(self) -> tuple[int, int, int]:
        """Burn-in, kept iterations before the first convergence check and most kept
        iterations per chain of the discrepancy phase.

        ``[discrepancy] burn`` and ``samples`` where given, else ``[calibration]``'s;
        ``max_samples`` where given (at least ``samples``), else 4 x ``samples``.
        """
        d, cal = self.discrepancy, self.calibration
        samples = cal.samples if d.samples is None else d.samples
        most = 4 * samples if d.max_samples is None else max(d.max_samples, samples)
        return (cal.burn if d.burn is None else d.burn, samples, most)

    def config_hash(self) -> str:
        """SHA-256 (hex) of the canonical JSON of the validated configuration.

        Paths inside the study folder enter relative to it, so moving the
        folder keeps the hash; changing any value changes it.
        """
        dumped = self.model_dump(mode="json")
        keys = [("data", "file"), ("study", "output_dir")]
        keys += [("simulator", key) for key in self.simulator.path_keys]
        for section, key in keys:
            path = Path(dumped[section][key])
            if path.is_absolute() and path.is_relative_to(self.root):
                dumped[section][key] = path.relative_to(self.root).as_posix()
        text = json.dumps(dumped, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
        return hashlib.sha256(text.encode()).hexdigest()


def _target_problems(study: Study) -> list[str]:
    simulator = study.simulator
    problems: list[str] = []
    owner: dict[str, str] = {}
    for name, parameter in study.parameters.items():
        key = f"parameters.{name}"
        kinds: set[str] = set()
        sensors = [t.startswith(SENSOR_PREFIX) for t in parameter.targets]
        if any(sensors) and not all(sensors):
            problems.append(
                f"{key}.targets: mixes a sensor target ('measured.…') with simulator "
                "targets; give the sensor its own parameter"
            )
            continue
        for target, sensor in zip(parameter.targets, sensors, strict=True):
            try:
                if sensor:
                    problems += _sensor_problems(study, key, parameter.unit, target)
                    kind, canonical = None, target
                else:
                    kind = simulator.target_kind(target)
                    canonical = simulator.target_key(target)
            except ValueError as exc:
                problems.append(f"{key}.targets: {exc}")
                continue
            if canonical in owner:
                problems.append(f"{key}.targets: {target!r} is already set by {owner[canonical]!r}")
            owner[canonical] = name
            kinds |= {kind} if kind is not None else set()
        found = sorted(kinds)
        if len(found) > 1:
            problems.append(f"{key}.targets: mixes quantities of different kinds {found}")
        elif found and normal_unit(parameter.unit) not in KIND_UNITS[found[0]][0]:
            problems.append(
                f"{key}.unit: {parameter.unit!r} is not the unit of its targets "
                f"({found[0].replace('_', ' ')}); write values in {KIND_UNITS[found[0]][1]!r}"
            )
    return problems


def _sensor_problems(study: Study, key: str, unit: str, target: str) -> list[str]:
    """Problems of one ``measured.<output>.<offset|gain>`` target.

    A malformed target or an output not calibrated on raises ValueError (reported
    under ``targets``); a wrong unit is returned (reported under ``unit``).
    """
    sensor = parse_sensor_target(target)
    assert sensor is not None  # the caller checked the prefix
    output, prop = sensor
    if output not in study.outputs.calibrate:
        raise ValueError(
            f"'measured.{output}.{prop}': {output!r} is not calibrated on; outputs.calibrate "
            f"lists {', '.join(study.outputs.calibrate)}"
        )
    if prop == "gain":
        if normal_unit(unit) not in KIND_UNITS["dimensionless"][0]:
            return [f'{key}.unit: a gain is dimensionless; write unit = "1", got {unit!r}']
        return []
    quantity = GLOSSARY.get(output)
    if quantity is not None and not same_scale(unit, quantity.dimension):
        return [
            f"{key}.unit: the offset of {output!r} takes its unit ({quantity.unit}), got {unit!r}"
        ]
    return []


def _aggregate_problems(study: Study) -> list[str]:
    """A meter (energy per time step) must be aggregated as a total (``aggregate = 'sum'``).

    The built-in wall and box give interval means of any output (``IntervalMeans``);
    a total of a power or temperature is refused where the column is read.
    """
    problems = []
    outputs = getattr(study.simulator, "outputs", None)
    for name in (*study.outputs.calibrate, *study.outputs.held_out):
        column = study.data.columns.get(name)
        if column is None:
            continue
        meter = getattr(outputs.get(name), "meter", None) if isinstance(outputs, dict) else None
        if meter is not None and column.aggregate != "sum":
            problems.append(
                f"data.columns.{name}.aggregate: simulator.outputs.{name} is the meter "
                f"{meter!r} (energy per time step); set aggregate = 'sum', "
                f"got {column.aggregate!r}"
            )
    return problems


def _output_problems(study: Study) -> list[str]:
    problems = study.outputs.phase_problems(study.discrepancy.enabled)
    produced, sim = study.simulator.output_names(), study.simulator.type
    for name in study.outputs.calibrate:
        if name not in study.data.columns:
            problems.append(
                f"outputs.calibrate: {name!r} is not mapped in [data.columns] (mapped: "
                f"{', '.join(study.data.columns)})"
            )
        if produced and name not in produced:
            problems.append(
                f"outputs.calibrate: the {sim} simulator does not produce {name!r}; it "
                f"produces {', '.join(produced)}"
            )
    for name in study.simulator.input_names():
        if name not in study.data.columns:
            problems.append(
                f"data.columns: the {sim} simulator needs the boundary condition {name!r}; "
                "map it to a column of the file"
            )
        elif name in study.outputs.calibrate:
            problems.append(f"outputs.calibrate: {name!r} is an input of the {sim} simulator")
    problems += _held_out_problems(study)
    for name in study.outputs.errors:
        if name not in study.outputs.calibrate and name not in study.outputs.held_out:
            problems.append(
                f"outputs.errors.{name}: {name!r} is neither a calibrated nor a held-out output "
                f"(outputs.calibrate: {', '.join(study.outputs.calibrate)})"
            )
            continue
        try:
            study.outputs.noise_sd(name)
        except ConfigError as exc:
            problems.append(str(exc.message))
        problems += _relative_problems(study, name)
    if study.calibration.sampler == "nuts" and (
        len(study.outputs.calibrate) > 1
        or any(e.model != "white" for e in study.outputs.errors.values())
    ):
        problems.append(
            "calibration.sampler: 'nuts' samples one output with white errors; use 'mwg' "
            "for several outputs or AR(1) errors"
        )
    return problems


def _relative_problems(study: Study, name: str) -> list[str]:
    """What ``relative = true`` (errors proportional to the level) allows."""
    spec = study.outputs.errors[name]
    where = f"outputs.errors.{name}"
    if not spec.relative:
        if spec.floor is not None:
            return [f"{where}.floor is for relative errors; add relative = true or remove it"]
        return []
    problems = []
    if name in study.outputs.held_out:
        problems.append(
            f"{where}: relative errors apply to calibrated outputs; a held-out sensor's "
            "band uses its sd in the output's unit"
        )
    if study.discrepancy.enabled:
        problems.append(
            f"{where}: relative errors do not combine with the difference-process phase "
            "([discrepancy] enabled); use discrepancy = true in this table instead"
        )
    try:
        floor = study.outputs.floor(name)
    except ConfigError as exc:
        return [*problems, str(exc.message)]
    if floor is not None and not floor > 0.0:
        problems.append(f"{where}.floor must be > 0, got {spec.floor!r}")
    return problems


def _held_out_problems(study: Study) -> list[str]:
    """What ``[outputs] held_out`` needs: mapped, simulated, not calibrated, an accuracy."""
    problems = []
    produced, sim = study.simulator.output_names(), study.simulator.type
    for name in study.outputs.held_out:
        where = f"outputs.held_out: {name!r}"
        if name in study.outputs.calibrate:
            problems.append(f"{where} is also calibrated on; a held-out sensor is never fitted")
        if name not in study.data.columns:
            problems.append(f"{where} is not mapped in [data.columns]")
        if produced and name not in produced:
            problems.append(
                f"{where}: the {sim} simulator does not produce it; add it to the simulator's "
                f"outputs (it produces {', '.join(produced)})"
            )
        spec = study.outputs.errors.get(name)
        if spec is None or spec.sd is None:
            problems.append(
                f"{where} needs the sensor's accuracy for its band: [outputs.errors.{name}] "
                "sd = '<number> <unit>'"
            )
        elif spec.model != "white" or spec.discrepancy:
            problems.append(
                f"outputs.errors.{name}: a held-out sensor takes only sd (its band's noise); "
                "model and discrepancy apply to calibrated outputs"
            )
    if study.outputs.held_out and study.predict.method != "simulator":
        problems.append(
            "outputs.held_out: held-out sensors are predicted by re-running the simulator; "
            "set [predict] method = 'simulator'"
        )
    return problems


def _derived_problems(study: Study) -> list[str]:
    problems = []
    for name, spec in study.derived.items():
        if not IDENTIFIER.match(name) or name in study.parameters:
            problems.append(f"derived.{name}: the name must be an identifier and not a parameter")
        try:
            Expression.parse(spec.expression, list(study.parameters), f"derived.{name}")
        except ConfigError as exc:
            problems.append(exc.message)
    return problems


def _period_problems(study: Study) -> list[str]:
    step, periods = study.data.step, study.periods
    checks = {"periods.warmup": periods.warmup}
    if isinstance(periods.length, timedelta):
        checks["periods.length"] = periods.length
    problems = [
        f"{key}: {format_duration(value)} is not a multiple of data.step {format_duration(step)}"
        for key, value in checks.items()
        if value % step
    ]
    if isinstance(periods.length, timedelta) and periods.length < 2 * step:
        problems.append(f"periods.length: {format_duration(periods.length)} is under 2 steps")
    zone, train_from = study.data.zone, {"periods.train_from": periods.train_from}
    return problems + local_time_problems(train_from, zone)


#: Warm-up iterations NUTS needs at least (its window adaptation fails on fewer).


def _reuse_problems(study: Study) -> list[str]:
    """What ``[design] reuse_screening = true`` cannot be combined with."""
    if not study.design.reuse_screening:
        return []
    key = "design.reuse_screening"
    if study.screening.method != "sobol":
        return [
            f"{key}: only a Sobol screening's Latin hypercube can join the design, and "
            f"[screening] method is {study.screening.method!r} (Morris trajectories move one "
            "parameter at a time on a coarse grid); set method = 'sobol' and run `bayescal "
            "screen` again, or set reuse_screening = false"
        ]
    why = {
        "calibration.sampler = 'nuts'": study.calibration.sampler == "nuts",
        "[discrepancy] enabled": study.discrepancy.enabled,
        "[study] prior_from": study.study.prior_from is not None,
    }
    return [
        f"{key}: cannot be combined with {what} (it does not hold the screened-out "
        "parameters at their nominal values); set reuse_screening = false"
        for what, found in why.items()
        if found
    ]


def _design_problems(study: Study) -> list[str]:
    """``[design] runs`` and ``max_runs`` against the calibrated parameters (and the
    screening's runs at the head of the design with ``reuse_screening``)."""
    design, t = study.design, len(study.calibrated)
    reuse = design.reuse_screening and study.screening.method == "sobol"
    reused = study.screening.sobol_runs(len(study.parameters)) if reuse else 0
    alone = reuse and design.sequential and design.runs == 0  # the screening's runs alone
    problems, need = [], max(t + 2, 2)
    fewest = max(need - reused, 1) if reuse else need  # the screening's runs count
    if reuse and not alone and design.runs < fewest:
        problems.append(
            f"design.runs: {design.runs} new runs after the screening's {reused} for {t} "
            f"calibrated parameters; at least {fewest} {'is' if fewest == 1 else 'are'} needed "
            "(or 0 with sequential = true)"
        )
    elif not reuse and design.runs < need:
        calibrated = "calibrated " if study.candidates else ""
        problems.append(f"design.runs: {design.runs} runs for {t} {calibrated}parameters; "
                        f"at least {need} are needed")  # fmt: skip
    if not design.sequential:
        return problems
    cap = design.run_cap(reused)
    if not reuse and cap < design.runs:
        problems.append(
            f"design.max_runs: {cap} is below design.runs "
            f"({design.runs}), the first design of the sequential design"
        )
    first = reused + design.runs
    if reuse and (cap < first or (alone and cap == first)):
        problems.append(
            f"design.max_runs: {cap} {'is below' if cap < first else 'leaves no batch after'} "
            f"the first design's {first} runs (the screening's {reused} + design.runs "
            f"{design.runs}): with reuse_screening it counts the screening's runs too; set it "
            f"above {first}"
        )
    return problems


def _sampler_problems(study: Study) -> list[str]:
    """What ``[calibration] sampler = "nuts"`` needs, checked before any stage runs."""
    cal = study.calibration
    if cal.sampler != "nuts":
        return []
    problems = []
    missing = [m for m in ("jax", "blackjax") if not module_installed(m)]
    if missing:
        problems.append(
            f"calibration.sampler: 'nuts' needs {' and '.join(missing)}, which "
            f"{'is' if len(missing) == 1 else 'are'} not installed; "
            'pip install "bayescal[hmc]", or set sampler = "mwg"'
        )
    if cal.burn < NUTS_MIN_WARMUP:
        problems.append(
            f"calibration.burn: {cal.burn} warm-up iterations for sampler 'nuts'; its step-size "
            f"adaptation needs at least {NUTS_MIN_WARMUP} (500 is a good choice)"
        )
    if study.emulator.algebra != "kronecker":
        problems.append(
            f"calibration.sampler: 'nuts' evaluates the likelihood by the Kronecker route, "
            f"got emulator.algebra = {study.emulator.algebra!r}; set it to 'kronecker' or "
            "use sampler = 'mwg'"
        )
    return problems


# --------------------------------------------------------------------------- loading


def load_study(path: str | os.PathLike[str]) -> Study:
    """Read and validate a study.

    Parameters
    ----------
    path
        ``study.toml`` or the folder holding it.

    Raises
    ------
    ConfigError
        For a missing file, a TOML syntax error (with its line) or any invalid
        value; the message lists every problem found, on one line.
    """
    given = Path(path)
    file = given / STUDY_FILE if given.is_dir() else given
    problem = path_problem(file)
    if problem is not None:
        if problem == "file not found" and given.is_dir():
            problem = f"no {STUDY_FILE} in folder {given}"
        raise ConfigError(problem, hint="give the study file or its folder", source=str(file))
    try:
        raw = tomllib.loads(_study_text(file.read_bytes()))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not UTF-8 text (byte {exc.start})", source=str(file)) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", source=str(file)) from None
    study = study_from_dict(raw, root=file.resolve().parent, source=str(file))
    study._path = file.resolve()
    return study


def _study_text(data: bytes) -> str:
    """The text of a study file: UTF-8, with or without the byte-order mark that Windows
    editors write; UTF-16 with its byte-order mark (Notepad's "Unicode") too."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return data.decode("utf-16")
    return data.decode("utf-8-sig")


def study_from_dict(raw: dict[str, Any], *, root: Path, source: str = STUDY_FILE) -> Study:
    """Validate the parsed content of a study file.

    Parameters
    ----------
    raw
        The parsed TOML.
    root
        Folder that relative paths start from.
    source
        Name used in error messages.
    """
    try:
        study = Study.model_validate(raw, context={"root": Path(root)})
    except ValidationError as exc:
        raise ConfigError("; ".join(format_errors(exc, Study)), source=source) from None
    study._root = Path(root)
    return study
