"""The study file: ``study.toml`` validated into frozen pydantic models.

A study is a folder holding ``study.toml``; relative paths in it start at that
folder. :func:`load_study` reads the file with :mod:`tomllib`, validates it
into :class:`Study` and turns every problem into one
:class:`~bayescal.errors.ConfigError` whose message lists each problem with
its key path, the value received and what was expected, on one line.

Every field carries a description (with its unit in brackets) and examples;
the study-file reference is generated from these models. The ``[simulator]``
sections live in :mod:`bayescal.config_simulators` (re-exported here); a new
simulator type is one more class in its :data:`SimulatorSection`.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import os
import tomllib
import types
from datetime import date, datetime, timedelta, tzinfo
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin

import pandas as pd
from pydantic import (
    BaseModel,
    BeforeValidator,
    Field,
    PrivateAttr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from bayescal.clock import format_duration, parse_duration, parse_time_zone
from bayescal.config_simulators import (
    _KIND_UNITS,
    _NAME,
    SENSOR_PREFIX,
    BoxSimulator,
    CommandOutputs,
    CommandSection,
    EnergyPlusOutput,
    EnergyPlusSchedule,
    EnergyPlusSection,
    FmuSection,
    LayerSpec,
    SimulatorSection,
    WallSimulator,
    _f,
    _fail,
    _normal_unit,
    _resolve,
    _Section,
    parse_sensor_target,
)
from bayescal.data.measured import column_problems
from bayescal.errors import ConfigError
from bayescal.glossary import GLOSSARY
from bayescal.optional import module_installed
from bayescal.units import same_scale

__all__ = [  # the [simulator] sections are re-exported from bayescal.config_simulators
    "FORMATS",
    "STUDY_FILE",
    "BetaPrior",
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
    "Prior",
    "RunnerSection",
    "SimulatorSection",
    "Study",
    "StudySection",
    "UniformPrior",
    "WallSimulator",
    "format_errors",
    "load_study",
    "study_from_dict",
]

STUDY_FILE = "study.toml"
FORMATS = ("csv", "parquet", "epw", "modelica")
_EXTENSIONS = {".csv": "csv", ".tsv": "csv", ".parquet": "parquet", ".pq": "parquet"}
_EXTENSIONS |= {".epw": "epw", ".txt": "modelica", ".mos": "modelica"}


# --------------------------------------------------------------------------- helpers


def _duration(value: object) -> timedelta:
    return parse_duration(value).to_pytimedelta()


def _instant(value: object) -> datetime:
    result = _parse_instant(value)
    if not 1678 <= result.year <= 2261:  # the range of nanosecond timestamps
        raise ValueError(f"expected a date-time between the years 1678 and 2261, got {value!r}")
    return result


def _parse_instant(value: object) -> datetime:
    if isinstance(value, datetime):
        return value
    if isinstance(value, date):
        return datetime(value.year, value.month, value.day)
    try:
        if not isinstance(value, str):
            raise TypeError
        return pd.Timestamp(value).to_pydatetime()
    except (ValueError, TypeError):
        raise ValueError(
            f"expected a date-time such as '2013-08-21T00:00:00', got {value!r}"
        ) from None


Duration = Annotated[timedelta, BeforeValidator(_duration)]
"""A duration written with a unit: ``"30min"``, ``"1h"``, ``"1D"``."""
Instant = Annotated[datetime, BeforeValidator(_instant)]
"""A date-time; naive values are local times of ``[data].time_zone``."""


# --------------------------------------------------------------------------- [study], [data]


class StudySection(_Section):
    """``[study]``: name, output folder and master seed."""

    name: str = _f("Name of the study, used in reports.", "paper-wall", min_length=1)
    output_dir: Path = _f(
        "Folder for artefacts, relative to the study folder (or absolute).",
        "out",
        default=Path("out"),
        validate_default=True,
    )
    seed: int = _f("Master seed; stages without their own seed derive theirs.", 0, default=0, ge=0)
    description: str = _f("Free text shown in the report.", "Paper wall, 2012", default="")

    @field_validator("output_dir")
    @classmethod
    def _inside(cls, value: Path, info: ValidationInfo) -> Path:
        return _resolve(value, info, "a folder name")


class ColumnSpec(_Section):
    """``[data.columns.<glossary name>]``: where a series comes from and its unit."""

    source: str | int = _f(
        "Column name (CSV, Parquet, EPW field name) or integer index (Modelica: 1..COLS-1, "
        "column 0 being time; EPW: field number).",
        "T_in",
        14,
    )
    unit: str = _f(
        "Unit in the file; of the glossary quantity's dimension (°F for a temperature is "
        "fine, kW is not). See bayescal.units.",
        "degC",
        "W/m2",
    )
    scale: float = _f(
        "Factor applied before unit conversion. [-]", 0.98, default=1.0, allow_inf_nan=False
    )
    sign: Literal[1, -1] = _f(
        "-1 flips the sign after conversion (a flux measured with the opposite convention).",
        -1,
        default=1,
    )

    @field_validator("source", mode="before")
    @classmethod
    def _source(cls, value: object) -> object:
        if isinstance(value, bool) or not isinstance(value, str | int):
            raise ValueError(f"expected a column name or an integer index, got {value!r}")
        return value


class DataSection(_Section):
    """``[data]``: the measured-data file, its clock and its columns."""

    file: Path = _f("Data file, relative to the study folder (or absolute).", "data/wall.csv")
    format: Literal["csv", "parquet", "epw", "modelica"] = _f(
        "File format; by default from the extension (.csv/.tsv, .parquet/.pq, .epw, "
        ".txt/.mos = Modelica CombiTimeTable).",
        "csv",
    )
    time_column: str | None = _f("Timestamp column (csv, parquet: required).", "time", default=None)
    time_format: str | None = _f(
        "strftime format of the timestamps (csv, parquet); ISO 8601 if omitted.",
        "%d/%m/%Y %H:%M",
        default=None,
    )
    time_zone: str = _f(
        "Zone of naive timestamps and of start, end, epoch: IANA name or fixed offset. The "
        "clock inside is UTC. Not for EPW (the file has its own).",
        "UTC+01:00",
        "Europe/Brussels",
        default="UTC",
    )
    epoch: Instant | None = _f(
        "Modelica tables: the instant of t = 0 (column 0 is seconds since it).",
        "2013-01-01T00:00:00",
        default=None,
    )
    table: str | None = _f("Modelica: table name in a file with several.", "data", default=None)
    delimiter: str = _f("CSV field separator.", ";", default=",", min_length=1, max_length=1)
    decimal: Literal[".", ","] = _f("CSV decimal mark.", ",", default=".")
    step: Duration = _f(
        "Step of the study clock. Finer data are averaged over centred windows "
        "[t - step/2, t + step/2); coarser data are an error.",
        "30min",
        "10min",
    )
    max_gap_interpolate: Duration = _f(
        "Gaps up to this length are interpolated linearly; longer ones are reported and "
        "their periods dropped. Default: never interpolate.",
        "1h",
        default=timedelta(0),
    )
    start: Instant | None = _f(
        "First clock instant: crops the record and fixes the grid (default: the grid is "
        "anchored at local midnight).",
        "2013-08-21T00:00:00",
        default=None,
    )
    end: Instant | None = _f("End of the record, exclusive.", "2013-09-30T00:00:00", default=None)
    columns: dict[str, ColumnSpec] = _f(
        "Glossary name -> file column. Outputs in [outputs].calibrate are measurements, "
        "every other column a boundary condition.",
        {"heat_flux_in": {"source": "q_in", "unit": "W/m2"}},
        min_length=1,
    )

    @model_validator(mode="before")
    @classmethod
    def _infer_format(cls, data: Any) -> Any:
        if isinstance(data, dict) and "format" not in data and isinstance(data.get("file"), str):
            suffix = Path(data["file"]).suffix.lower()
            if suffix not in _EXTENSIONS:
                raise ValueError(
                    f"cannot tell the format of {data['file']!r} from its extension; set "
                    f"data.format to one of {', '.join(map(repr, FORMATS))}"
                )
            return {**data, "format": _EXTENSIONS[suffix]}
        return data

    @field_validator("file")
    @classmethod
    def _file(cls, value: Path, info: ValidationInfo) -> Path:
        return _resolve(value, info, "a file name")

    @field_validator("time_zone")
    @classmethod
    def _zone(cls, value: str) -> str:
        parse_time_zone(value)
        return value

    @field_validator("step", "max_gap_interpolate")
    @classmethod
    def _not_negative(cls, value: timedelta, info: ValidationInfo) -> timedelta:
        if value < timedelta(0) or (info.field_name == "step" and not value):
            raise ValueError(
                f"must be {'positive' if info.field_name == 'step' else '>= 0'}, "
                f"got {format_duration(value)}"
            )
        return value

    @model_validator(mode="after")
    def _consistent(self) -> DataSection:
        problems = self._format_problems()
        for name, spec in self.columns.items():
            problems += column_problems(f"data.columns.{name}", name, spec, self.format)
        _fail(problems)
        return self

    def _format_problems(self) -> list[str]:
        fmt, given = self.format, self.model_fields_set
        problems = []
        if fmt in ("csv", "parquet") and self.time_column is None:
            problems.append(f"data.time_column: required for format {fmt!r}")
        if fmt == "modelica" and self.epoch is None:
            problems.append("data.epoch: required for Modelica tables (the instant of t = 0)")
        only = {"time_column": "csv parquet", "time_format": "csv parquet", "delimiter": "csv"}
        only |= {"decimal": "csv", "epoch": "modelica", "table": "modelica"}
        for key, formats in only.items():
            if key in given and fmt not in formats.split():
                problems.append(
                    f"data.{key}: only applies to format {formats.replace(' ', ' or ')}"
                )
        if fmt == "epw" and "time_zone" in given:
            problems.append("data.time_zone: EPW files carry their own time zone; remove it")
        if self.start and self.end and _utc(self.start, self.zone) >= _utc(self.end, self.zone):
            problems.append(f"data.end: {self.end} is not after data.start {self.start}")
        if self.delimiter == self.decimal:
            problems.append(f"data.decimal: {self.decimal!r} is also the delimiter")
        return problems

    @property
    def zone(self) -> tzinfo:
        """The parsed time zone."""
        return parse_time_zone(self.time_zone)


def _utc(value: datetime, zone: tzinfo) -> pd.Timestamp:
    ts = pd.Timestamp(value)
    return ts.tz_convert("UTC") if ts.tz is not None else ts.tz_localize(zone).tz_convert("UTC")


# --------------------------------------------------------------------------- [parameters]


class UniformPrior(_Section):
    """Uniform prior on ``[lower, upper]``."""

    distribution: Literal["uniform"] = _f("Prior family.", "uniform")
    lower: float = _f("Lower bound, in the parameter's unit.", 0.08, allow_inf_nan=False)
    upper: float = _f("Upper bound, in the parameter's unit.", 0.16, allow_inf_nan=False)

    @model_validator(mode="after")
    def _bounds(self) -> UniformPrior:
        if not self.lower < self.upper:
            raise ValueError(f"lower bound {self.lower} >= upper bound {self.upper}")
        return self


class BetaPrior(UniformPrior):
    """Beta(a, b) prior stretched over ``[lower, upper]``."""

    distribution: Literal["beta"] = _f("Prior family.", "beta")  # type: ignore[assignment]
    a: float = _f("First shape parameter. [-]", 1.0, gt=0)
    b: float = _f("Second shape parameter. [-]", 2.0, gt=0)


Prior = Annotated[Union[UniformPrior, BetaPrior], Field(discriminator="distribution")]  # noqa: UP007


class Parameter(_Section):
    """``[parameters.<name>]``: one calibration parameter."""

    unit: str = _f("Unit of nominal and bounds: the SI unit of the targets.", "W/(m·K)", "1")
    nominal: float = _f("Nominal (catalogue) value, inside the bounds.", 0.12)
    prior: Prior = _f(
        "Prior: {distribution = 'uniform', lower, upper} or {distribution = 'beta', lower, "
        "upper, a, b}.",
        {"distribution": "uniform", "lower": 0.08, "upper": 0.16},
    )
    targets: list[str] = _f(
        "What the value sets: 'layer.property' or r_si, r_se, solar_absorptance (wall); a "
        "constant name (box); 'ObjectType:ObjectName:Field' (energyplus; a name holding ':' "
        "in double quotes); a template placeholder (command); an FMU variable (fmu); "
        "'measured.<output>.offset' or '.gain' (any simulator: a sensor model, reading = "
        "gain * simulated + offset). Several targets share one value.",
        ["concrete.conductivity"],
        ["board_out.specific_heat", "board_in.specific_heat"],
        ["Material:AeratedConcrete:Conductivity"],
        min_length=1,
    )
    description: str = _f("Text for reports.", "conductivity of the blocks", default="")

    @model_validator(mode="after")
    def _nominal_inside(self) -> Parameter:
        lower, upper = self.prior.lower, self.prior.upper
        if not lower <= self.nominal <= upper:
            raise ValueError(
                f"nominal {self.nominal} is outside the prior bounds [{lower}, {upper}]"
            )
        return self


# --------------------------------------------------------------------------- other sections


class OutputsSection(_Section):
    """``[outputs]``: the measured outputs to calibrate on."""

    calibrate: list[str] = _f(
        "Glossary names of measured outputs, mapped in [data.columns] and produced by the "
        "simulator.",
        ["heat_flux_in"],
        min_length=1,
    )


def _length(value: object) -> object:
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 2:
            raise ValueError(f"a period needs at least 2 samples, got {value}")
        return value
    return _duration(value)


class PeriodsSection(_Section):
    """``[periods]``: warm-up, period length and the held-out test window (give one of
    ``test_samples`` and ``test_fraction``)."""

    length: Annotated[timedelta | int, BeforeValidator(_length)] = _f(
        "Period length: a duration (multiple of data.step) or a number of samples.",
        "1D",
        48,
        default=timedelta(days=1),
    )
    warmup: Duration = _f(
        "Stretch at the start that is simulated but not compared (initial conditions); a "
        "multiple of data.step.",
        "1D",
        "0min",
        default=timedelta(days=1),
    )
    test_samples: int | None = _f("Test window at the end, in samples.", 300, default=None, ge=0)
    test_fraction: float | None = _f(
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


class DesignSection(_Section):
    """``[design]``: the Latin hypercube of simulator runs."""

    runs: int = _f("Number of runs R (at least parameters + 2).", 30, default=30, ge=2)
    seed: int | None = _f("Seed; derived from [study].seed if omitted.", 1, default=None, ge=0)
    optimization: Literal["none", "random-cd", "lloyd"] = _f(
        "Space-filling optimisation of scipy.stats.qmc.LatinHypercube.", "none", default="random-cd"
    )


class EmulatorSection(_Section):
    """``[emulator]``: PCA bases and GP hyperparameters."""

    pca_variance: float = _f(
        "Output PCA: keep components up to this variance fraction (or pca_components).",
        0.95,
        default=0.90,
        gt=0,
        le=1,
    )
    pca_components: int | None = _f(
        "Output PCA: fixed number of components.", 3, default=None, ge=1
    )
    input_pca_variance: float = _f(
        "Boundary-condition PCA: variance fraction kept per series.", 0.9, default=0.90, gt=0, le=1
    )
    history_periods: int = _f(
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
    burn: int = _f(
        "Hyperparameter MCMC burn-in sweeps per chain (2 chains). The emulator uses the "
        "MAP (best draw refined by L-BFGS-B); on the wall example 2 x (500 + 1000) and "
        "2 x (1000 + 2000) sweeps gave the same MAP and leave-one-run-out RMSE.",
        500,
        default=500,
        ge=0,
    )
    samples: int = _f("Hyperparameter MCMC sweeps kept per chain.", 1000, default=1000, ge=1)
    algebra: Literal["kronecker", "dense"] = _f(
        "Linear algebra: fast Kronecker or the dense reference.", "dense", default="kronecker"
    )

    @model_validator(mode="after")
    def _one_rule(self) -> EmulatorSection:
        if self.pca_components is not None and "pca_variance" in self.model_fields_set:
            raise ValueError("give pca_variance or pca_components, not both")
        return self


class CalibrationSection(_Section):
    """``[calibration]``: MCMC for theta* and the precisions."""

    chains: int = _f("Independent chains (>= 4 for R-hat).", 4, default=4, ge=4)
    burn: int = _f("Burn-in iterations per chain.", 2000, default=2000, ge=0)
    samples: int = _f("Iterations kept per chain.", 5000, default=5000, ge=1)
    seed: int | None = _f("Seed; derived from [study].seed if omitted.", 2, default=None, ge=0)
    sampler: Literal["mwg", "nuts"] = _f(
        "MCMC sampler: 'mwg' (Metropolis-within-Gibbs) or 'nuts' (No-U-Turn with JAX, in a "
        'spawned process; needs `pip install "bayescal[hmc]"`; burn is its warm-up, 500 '
        "burn + 1000 samples are plenty; no checkpoints). 'mwg' is the default: on the "
        "virtual wall (30 runs x 25 days, benchmarks/bench_hmc.py) NUTS drew about 3.8x "
        "the bulk ESS of theta* per CPU second while sampling, but its fixed cost (JIT "
        "compilation 5-6.5 CPU s, process start-up 2 s) left a whole default-length "
        "calibration no faster (min ESS per CPU second 386 vs 389, about 10 s each), and "
        "'mwg' needs no extra package and resumes from checkpoints.",
        "nuts",
        default="mwg",
    )


class DiscrepancySection(_Section):
    """``[discrepancy]``: the difference process Delta(x) (the paper's eqs. 18–25)."""

    enabled: bool = _f("Estimate Delta(x).", True, default=False)
    realisations: int = _f("Posterior realisations b per update.", 50, default=50, ge=2)
    update_interval: int = _f("MCMC iterations between updates.", 100, default=100, ge=1)
    burn: int | None = _f(
        "Burn-in iterations per chain of the discrepancy phase (Metropolis-within-Gibbs "
        "with Delta updates, whatever [calibration] sampler says); [calibration] burn if "
        "omitted. Set it when the calibration uses 'nuts', whose short runs are too short "
        "for random-walk chains.",
        4000,
        default=None,
        ge=0,
    )
    samples: int | None = _f(
        "Iterations kept per chain of the discrepancy phase; [calibration] samples if omitted.",
        10000,
        default=None,
        ge=1,
    )


class PredictSection(_Section):
    """``[predict]``: calibrated predictions on the training and test windows."""

    draws: int = _f(
        "Posterior draws (thinned evenly over all chains) propagated through the emulator.",
        300,
        default=300,
        ge=20,
    )
    level: float = _f("Probability of the prediction band. [-]", 0.95, default=0.95, gt=0, lt=1)
    method: Literal["emulator", "simulator"] = _f(
        "Calibrated predictions from the emulator at `draws` posterior draws, or from "
        "the simulator re-run at `runs` posterior draws (exact physics, honest on test "
        "periods whose conditions the training periods did not span; costs `runs` runs). "
        "With a discrepancy, the corrected prediction adds Delta to the same kind of "
        "prediction (for 'simulator': runs at draws of the Delta phase's theta*).",
        "simulator",
        default="emulator",
    )
    runs: int = _f(
        "Posterior draws at which the simulator is re-run (method = 'simulator').",
        50,
        default=50,
        ge=10,
    )


class RunnerSection(_Section):
    """``[runner]``: where simulator runs execute."""

    backend: Literal["serial", "processes", "dask"] = _f(
        "Execution backend.", "dask", default="processes"
    )
    jobs: int | None = _f("Parallel workers; all cores if omitted.", 4, default=None, ge=1)
    scheduler: str | None = _f(
        "Dask scheduler address (dask only); a LocalCluster if omitted.",
        "tcp://10.0.0.5:8786",
        default=None,
    )
    timeout: float | None = _f("Time limit per run. [s]", 600.0, default=None, gt=0)
    retries: int = _f("Retries of a failed run.", 1, default=0, ge=0)

    @model_validator(mode="after")
    def _scheduler_for_dask(self) -> RunnerSection:
        if self.scheduler is not None and self.backend != "dask":
            raise ValueError(f"scheduler applies to backend 'dask', not {self.backend!r}")
        return self


# --------------------------------------------------------------------------- the study


class Study(_Section):
    """A validated study file; build it with :func:`load_study`.

    ``data.file``, ``study.output_dir`` and the simulator's paths (model,
    weather or FMU file) are absolute (relative ones were resolved against
    the study folder :attr:`root`); :attr:`path` is the file.
    """

    study: StudySection = _f("Name, output folder and seed.")
    data: DataSection = _f("Measured data.")
    simulator: SimulatorSection = _f("The simulator and its fixed inputs.")
    parameters: dict[str, Parameter] = _f("Calibration parameters by name (at least one).")
    outputs: OutputsSection = _f("Measured outputs to calibrate on.")
    periods: PeriodsSection = _f("Warm-up, periods and test window.")
    design: DesignSection = _f("Latin hypercube.", default_factory=DesignSection)
    emulator: EmulatorSection = _f("Emulator.", default_factory=EmulatorSection)
    calibration: CalibrationSection = _f("Calibration MCMC.", default_factory=CalibrationSection)
    discrepancy: DiscrepancySection = _f("Difference process.", default_factory=DiscrepancySection)
    predict: PredictSection = _f("Predictions with bands.", default_factory=PredictSection)
    runner: RunnerSection = _f("Simulation runner.", default_factory=RunnerSection)

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
        """Mapped columns that are not calibrated outputs."""
        return tuple(n for n in self.data.columns if n not in self.outputs.calibrate)

    @field_validator("parameters")
    @classmethod
    def _parameter_names(cls, value: dict[str, Parameter]) -> dict[str, Parameter]:
        if not value:
            raise ValueError("no parameters; define at least one [parameters.<name>] table")
        bad = [name for name in value if not _NAME.match(name)]
        if bad:
            raise ValueError(f"parameter names are identifiers (letters, digits, _), got {bad}")
        return value

    @model_validator(mode="after")
    def _cross_checks(self) -> Study:
        problems = _target_problems(self) + _output_problems(self) + _period_problems(self)
        problems += _sampler_problems(self)
        if self.design.runs < len(self.parameters) + 2:
            problems.append(
                f"design.runs: {self.design.runs} runs for {len(self.parameters)} parameters; "
                f"at least {len(self.parameters) + 2} are needed"
            )
        _fail(problems)
        return self

    def discrepancy_lengths(self) -> tuple[int, int]:
        """Burn-in and kept iterations per chain of the discrepancy phase.

        ``[discrepancy] burn`` and ``samples`` where given, else ``[calibration]``'s.
        """
        d, cal = self.discrepancy, self.calibration
        return (
            cal.burn if d.burn is None else d.burn,
            cal.samples if d.samples is None else d.samples,
        )

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
        elif found and _normal_unit(parameter.unit) not in _KIND_UNITS[found[0]][0]:
            problems.append(
                f"{key}.unit: {parameter.unit!r} is not the unit of its targets "
                f"({found[0].replace('_', ' ')}); write values in {_KIND_UNITS[found[0]][1]!r}"
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
        if _normal_unit(unit) not in _KIND_UNITS["dimensionless"][0]:
            return [f'{key}.unit: a gain is dimensionless; write unit = "1", got {unit!r}']
        return []
    quantity = GLOSSARY.get(output)
    if quantity is not None and not same_scale(unit, quantity.dimension):
        return [
            f"{key}.unit: the offset of {output!r} takes its unit ({quantity.unit}), got {unit!r}"
        ]
    return []


def _output_problems(study: Study) -> list[str]:
    problems = []
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
    return problems


#: Warm-up iterations NUTS needs at least (its window adaptation fails on fewer).
NUTS_MIN_WARMUP = 20


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
    if not file.is_file():
        what = f"no {STUDY_FILE} in folder {given}" if given.is_dir() else "file not found"
        raise ConfigError(what, hint="give the study file or its folder", source=str(file))
    try:
        raw = tomllib.loads(file.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not UTF-8 text (byte {exc.start})", source=str(file)) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", source=str(file)) from None
    study = study_from_dict(raw, root=file.resolve().parent, source=str(file))
    study._path = file.resolve()
    return study


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
        raise ConfigError("; ".join(format_errors(exc)), source=source) from None
    study._root = Path(root)
    return study


# --------------------------------------------------------------------------- error messages

_TYPE_LABELS = frozenset({"str", "int", "float", "bool", "timedelta", "datetime", "none"})


def _members(node: Any) -> list[Any]:
    if get_origin(node) in (Union, types.UnionType):
        return [m for m in get_args(node) if m is not type(None)]
    return [node]


def _tag_of(member: Any) -> tuple[Any, ...]:
    """Literal values of a union member's discriminator field (``("wall",)``)."""
    if isinstance(member, type) and issubclass(member, BaseModel):
        for field in member.model_fields.values():
            if get_origin(field.annotation) is Literal:
                return get_args(field.annotation)
    return ()


def _walk(loc: tuple[int | str, ...]) -> tuple[list[int | str], Any]:
    """The key path shown for an error location, and the type found there.

    Union branch labels that pydantic inserts (``"wall"``, ``"int"``) are skipped.
    """
    node: Any = Study
    shown: list[int | str] = []
    for part in loc:
        members = _members(node)
        if len(members) > 1:
            tagged = [m for m in members if part in _tag_of(m)]
            if tagged or (isinstance(part, str) and (part in _TYPE_LABELS or "[" in part)):
                node = tagged[0] if tagged else None
                continue
        node = members[0]
        shown.append(part)
        if isinstance(node, type) and issubclass(node, BaseModel):
            field = node.model_fields.get(str(part))
            node = field.annotation if field is not None else None
        elif get_origin(node) in (dict, list):
            node = get_args(node)[-1]
        else:
            node = None
    return shown, node


def _join(parts: list[int | str]) -> str:
    text = ""
    for part in parts:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _unknown_key(loc: tuple[int | str, ...]) -> str:
    shown, parent = _walk(loc[:-1])
    full = _join([*shown, loc[-1]])
    if not (isinstance(parent, type) and issubclass(parent, BaseModel)):
        return f"unknown key {full!r}"
    valid = list(parent.model_fields)
    close = difflib.get_close_matches(str(loc[-1]), valid, n=1)
    if close:
        return f"unknown key {full!r}; did you mean {_join([*shown, close[0]])!r}?"
    return f"unknown key {full!r}; valid keys here: {', '.join(valid)}"


def format_errors(exc: ValidationError) -> list[str]:
    """One message per pydantic error: key path, value received, what was expected."""
    messages: list[str] = []
    for err in exc.errors(include_url=False):
        loc, kind, ctx = tuple(err["loc"]), err["type"], err.get("ctx") or {}
        shown, node = _walk(loc)
        path = _join(shown)
        if kind == "cross_check":  # messages carry their own full key paths
            message = str(ctx["text"])
        elif kind == "extra_forbidden":
            message = _unknown_key(loc)
        elif kind == "missing":
            message = f"{path}: missing required key"
        elif kind in ("union_tag_not_found", "union_tag_invalid"):
            key = str(ctx.get("discriminator", "")).strip("'")
            tags = ", ".join(repr(t) for m in _members(node) for t in _tag_of(m))
            got = f"unknown value {ctx['tag']!r}" if "tag" in ctx else "missing"
            message = f"{_join([*shown, key])}: {got}; expected one of {tags}"
        else:
            text = str(err["msg"]).removeprefix("Value error, ")
            text = text[:1].lower() + text[1:]
            if kind != "value_error" and not isinstance(err.get("input"), dict | list):
                text += f", got {err.get('input')!r}"
            message = f"{path}: {text}" if path else text
        if message not in messages:
            messages.append(message)
    return messages
