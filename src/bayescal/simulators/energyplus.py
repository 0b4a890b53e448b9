"""EnergyPlus as a bayescal simulator, through the ``pyenergyplus-lbnl`` package.

:class:`EnergyPlusSimulator` runs an EnergyPlus model (epJSON, or IDF
converted once to epJSON) for one parameter set and one forcing:

1. the model is copied and edited as JSON: each calibration parameter sets
   one or more numeric fields of named objects (``Material AeratedConcrete
   Conductivity``); ``Timestep``, ``HeatBalanceAlgorithm``, ``RunPeriod``
   and ``SimulationControl`` are set by the adapter, and the model's own
   reports (``Output:Variable``, ``Output:Meter``, tables...) are replaced by
   the requested series at every time step in ``eplusout.sql``
   (:mod:`bayescal.simulators.energyplus_output`);
2. every forcing series mapped to a ``Schedule:File`` is written as a
   one-year CSV with one row per EnergyPlus time step, and the weather comes
   from an EPW written from the forcing (:mod:`bayescal.simulators.epw`) or
   from a given file;
3. EnergyPlus runs in a fresh folder (under ``workdir``, or the system's
   temporary folder), in a child Python process (one ``EnergyPlusAPI`` state
   per run, killed at ``timeout``);
4. ``eplusout.err`` is checked: any ``** Severe **`` or ``** Fatal **``
   message, or a run that did not complete successfully, raises
   :class:`~bayescal.errors.SimulatorError` with the first messages;
5. the requested variables and meters are read from ``eplusout.sql`` and put
   on the forcing's clock: values at the clock instants, or sums or means
   over the clock intervals (``aggregate``); then the run's folder is
   deleted, unless ``keep_outputs``.

Why a child process
-------------------
Several runs in one process with a new state each give identical results
(checked) and save about 0.5 s per run (process start, library load and
input-schema set-up: the wall over 1500 half-hourly steps, CTF, took 0.21 s
in-process against 0.71 s in a child process, minima of 4 runs on a loaded
2-core machine). A child process is the default anyway: it can be killed
when it exceeds the timeout (an in-process run can only be asked to stop
from a callback at its next time step), a crash or ``exit`` inside the
native library cannot take the caller down, and parallel runs from threads
(Dask) do not share the library's global data. ``isolation="in-process"``
is offered for long designs run from worker processes.

Clock and time convention
-------------------------
EnergyPlus works in local standard time (UTC + ``time_zone`` of the model's
``Site:Location``, or of the EPW's ``LOCATION`` line when a weather file is
given). The run period covers whole days, from the day holding
``start - warmup_days`` (minus one EnergyPlus time step) to the day holding
the last sample; the forcing and the warm-up must lie in one calendar year.
Schedule rows hold the value for the time step *ending* at the row's time:
row ``k`` is the forcing, interpolated linearly, at ``(k + 1) * dt`` after
1 January 00:00 (``dt`` the EnergyPlus time step); before the first sample
and after the last the values are held. EnergyPlus reports each time step's
result at its end, so sample ``i`` of an output is the value reported for
the time step ending at ``t_i`` (interpolated linearly between report times
when ``t_i`` is not on the EnergyPlus grid).

Warm-up
-------
During ``warmup_days`` before the first sample the schedules hold the first
sample's values, and EnergyPlus's own warm-up repeats the first simulated
day until it converges: the model starts close to steady state for the
first sample's boundary conditions, like the built-in wall.

The paper's wall
----------------
:func:`paper_wall_simulator` wraps ``models/paper_wall.epJSON``: a 1 m² wall
(glass-fibre board 27 mm | aerated concrete 150 mm | glass-fibre board
27 mm) in a 1 m³ zone. The outside face temperature is imposed exactly by
``SurfaceProperty:OtherSideCoefficients`` (film coefficient 0: the schedule
*is* the surface temperature). EnergyPlus has no object that imposes an
inside face temperature, so, as the paper did with ESP-r, the zone air
temperature is imposed (an unlimited ideal-loads system with a single
setpoint equal to the measured inside surface temperature) and the inside
convection coefficient is set to 1e5 W/(m²·K), so that the face follows the
air to ``q / h`` (< 1e-4 K). The inside surface heat balance of a time step
uses the zone air temperature of the *previous* time step, so the setpoint
schedule is written one time step ahead (``lead_steps=1``); without it the
inside face lags by one step (checked: 0.04 K and 0.03 W/m² worse on the
sinusoid test). The output is ``Surface Inside Face Conduction Heat
Transfer Rate per Area``, which is positive from the wall into the room, as
``heat_flux_in``.

Where the parts live
--------------------
:mod:`bayescal.simulators.energyplus_model` reads a model and finds its
objects and fields; :mod:`bayescal.simulators.energyplus_run` runs
EnergyPlus and checks ``eplusout.err``; :mod:`bayescal.simulators.energyplus_box`
builds the Annex 58 test box from the shipped model.
"""

from __future__ import annotations

import calendar
import copy
import hashlib
import json
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from bayescal.errors import DataError, SimulatorError
from bayescal.simulators.base import Forcing, check_parameters
from bayescal.simulators.energyplus_model import (
    energyplus_field_key,
    find_object,
    first_object,
    load_model,
    objects_of,
)
from bayescal.simulators.energyplus_output import (
    OutputSpec,
    parse_output,
    read_output,
    request_outputs,
)
from bayescal.simulators.energyplus_run import (
    check_errors,
    require_pyenergyplus,
    run_energyplus,
    run_energyplus_in_process,
)
from bayescal.simulators.epw import (
    EpwSite,
    local_year,
    read_epw_site,
    seconds_in_year,
    write_epw,
)

MODELS = Path(__file__).resolve().parent / "models"
PAPER_WALL_MODEL = MODELS / "paper_wall.epJSON"
ALGORITHMS = ("ConductionTransferFunction", "ConductionFiniteDifference")
# EnergyPlus replaces any Timestep below 20 per hour by 20 with the finite-difference algorithm.
_CONDFD_MIN_TIMESTEPS = 20
_WHO = "EnergyPlusSimulator"
_DAY = 86400.0


@dataclass(frozen=True)
class FieldTarget:
    """A numeric field of a named object, set by a calibration parameter.

    Parameters
    ----------
    object
        Object type, e.g. ``"Material"``.
    name
        Object name, e.g. ``"AeratedConcrete"`` (case-insensitive).
    field
        Field, as the IDD names it (``"Specific Heat"``) or as epJSON does
        (``"specific_heat"``).
    """

    object: str
    name: str
    field: str

    @property
    def key(self) -> str:
        """The epJSON key of the field."""
        return energyplus_field_key(self.field)

    def __str__(self) -> str:
        return f"{self.object} {self.name!r} field {self.field!r}"


@dataclass(frozen=True)
class ScheduleInput:
    """A forcing series written to a ``Schedule:File``.

    Parameters
    ----------
    schedule
        Name of the ``Schedule:File`` object in the model.
    lead_steps
        Write the series this many EnergyPlus time steps ahead (see the paper
        wall's inside air temperature in the module notes).
    """

    schedule: str
    lead_steps: int = 0


class EnergyPlusSimulator:
    """An EnergyPlus model run through ``pyenergyplus`` (see the module notes).

    Parameters
    ----------
    model_path
        The model, ``.epJSON`` or ``.idf`` (converted once, at construction,
        with EnergyPlus's ``--convert-only``).
    parameters
        Calibration parameter name -> field(s) it sets: a mapping
        ``{"object": ..., "name": ..., "field": ...}``, a :class:`FieldTarget`
        or a list of them. The nominal value is the model's value of the
        first field.
    schedules
        Forcing series (glossary name) -> ``Schedule:File`` name, or a
        mapping ``{"schedule": name, "lead_steps": n}``.
    outputs
        Output name -> ``(variable, key)``, ``(variable, key, scale)``, a
        mapping ``{"variable", "key"}`` or ``{"meter"}`` (with optional
        ``scale`` and ``aggregate``) or an :class:`OutputSpec`.
    weather
        ``"from-forcing"`` (an EPW written from the forcing, absent series
        filled as in :mod:`bayescal.simulators.epw`) or the path of an EPW
        (read once; its content travels with the simulator to the workers).
    timesteps_per_hour
        EnergyPlus time steps per hour, a divisor of 60; default: the model's
        ``Timestep``, at least 20 with the finite-difference algorithm. [1/h]
    algorithm
        ``"ConductionTransferFunction"`` or ``"ConductionFiniteDifference"``
        (sets ``HeatBalanceAlgorithm``); ``None`` keeps the model's.
    warmup_days
        Whole days simulated before the first sample, with the first sample's
        schedule values. [d]
    min_warmup_days
        If given, EnergyPlus's ``Building`` minimum number of warm-up days. [d]
    weather_records_per_hour
        Records per hour of the EPW written from the forcing: 1 (EnergyPlus
        then interpolates linearly between the hourly values) or
        ``timesteps_per_hour`` (EnergyPlus rejects any other sub-hourly file;
        the weather then follows the forcing to the EPW's rounding). [1/h]
    timeout
        A run taking longer is stopped and raises :class:`SimulatorError`. [s]
    isolation
        ``"subprocess"`` (default: a child process per run, killed at the
        timeout) or ``"in-process"`` (about 0.5 s faster per run once the
        library is loaded; the timeout is checked at each zone time step
        only; not for several runs at once from threads of one process).
    workdir
        Folder in which each run gets a new subfolder (default: the system's
        temporary folder).
    keep_outputs
        Keep each run's folder (model, schedules, EnergyPlus's output files
        and ``parameters.json``) instead of deleting it once its series are
        read; for debugging. Only the requested series, on the study clock,
        leave the run otherwise.
    """

    def __init__(
        self,
        model_path: str | Path,
        *,
        parameters: Mapping[str, Any] | None = None,
        schedules: Mapping[str, str | Mapping[str, Any] | ScheduleInput] | None = None,
        outputs: Mapping[str, Sequence[Any] | Mapping[str, Any] | OutputSpec],
        weather: str | Path = "from-forcing",
        timesteps_per_hour: int | None = None,
        algorithm: Literal["ConductionTransferFunction", "ConductionFiniteDifference"]
        | None = None,
        warmup_days: int = 3,
        min_warmup_days: int | None = None,
        weather_records_per_hour: int = 1,
        timeout: float = 600.0,
        isolation: Literal["subprocess", "in-process"] = "subprocess",
        workdir: str | Path | None = None,
        keep_outputs: bool = False,
    ) -> None:
        require_pyenergyplus()
        self._model_path = Path(model_path)
        self._model = load_model(self._model_path)
        self._targets = {n: _parse_targets(n, spec) for n, spec in (parameters or {}).items()}
        self._nominal = {n: _nominal_value(self._model, t[0]) for n, t in self._targets.items()}
        self._schedules = {n: _parse_schedule(n, s) for n, s in (schedules or {}).items()}
        for spec in self._schedules.values():
            find_object(self._model, "Schedule:File", spec.schedule)
        if not outputs:
            raise SimulatorError(f"{_WHO} needs at least one output, got {outputs!r}")
        self._outputs = {n: parse_output(n, o) for n, o in outputs.items()}
        self._algorithm = _check_algorithm(algorithm)
        self._tph = _timesteps_per_hour(self._model, timesteps_per_hour, self._effective_algorithm)
        self._weather = weather if weather == "from-forcing" else Path(weather)
        self._weather_site: EpwSite | None = None
        if isinstance(self._weather, Path):
            if not self._weather.is_file():
                raise SimulatorError(f"weather file {str(self._weather)!r} does not exist")
            self._weather_site = read_epw_site(self._weather)
        self._warmup_days = _non_negative_int(warmup_days, "warmup_days")
        self._min_warmup_days = min_warmup_days
        if weather_records_per_hour not in (1, self._tph):
            raise SimulatorError(
                f"weather_records_per_hour must be 1 or the number of time steps per hour "
                f"({self._tph}), got {weather_records_per_hour!r}",
                hint="EnergyPlus reads a sub-hourly EPW only at its own time step",
            )
        self._records_per_hour = weather_records_per_hour
        if not (np.isfinite(timeout) and timeout > 0):
            raise SimulatorError(f"timeout must be a positive number of seconds, got {timeout!r}")
        self._timeout = float(timeout)
        if isolation not in ("subprocess", "in-process"):
            raise SimulatorError(
                f"isolation must be 'subprocess' or 'in-process', got {isolation!r}"
            )
        self._isolation = isolation
        self._workdir = None if workdir is None else Path(workdir)
        self._keep_outputs = bool(keep_outputs)
        # The weather file travels with the simulator (to worker processes and remote Dask
        # workers, which need not see the same file system) and is written into each run.
        self._weather_bytes = (
            self._weather.read_bytes() if isinstance(self._weather, Path) else None
        )
        self._weather_sha256 = (
            hashlib.sha256(self._weather_bytes).hexdigest() if self._weather_bytes else None
        )

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the calibration parameters ``simulate`` accepts."""
        return tuple(self._targets)

    @property
    def input_names(self) -> tuple[str, ...]:
        """Glossary names of the forcing series written to schedules."""
        return tuple(self._schedules)

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the series ``simulate`` returns."""
        return tuple(self._outputs)

    @property
    def nominal(self) -> dict[str, float]:
        """The model's values of the calibration parameters."""
        return dict(self._nominal)

    @property
    def timesteps_per_hour(self) -> int:
        """EnergyPlus time steps per hour used by the runs. [1/h]"""
        return self._tph

    @property
    def _effective_algorithm(self) -> str:
        if self._algorithm is not None:
            return self._algorithm
        return str(
            first_object(self._model, "HeatBalanceAlgorithm").get("algorithm", ALGORITHMS[0])
        )

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        """Run EnergyPlus once.

        Parameters
        ----------
        parameters
            Calibration parameter values in the model's units (SI); names
            not given keep the model's values.
        forcing
            Boundary conditions on the study clock.

        Returns
        -------
        dict
            Output name -> series of length ``forcing.n``.
        """
        check_parameters(parameters, self.parameter_names, _WHO)
        forcing.require(list(self.input_names), _WHO)
        values = {**self._nominal, **{k: float(v) for k, v in parameters.items()}}
        if self._workdir is not None:
            self._workdir.mkdir(parents=True, exist_ok=True)
        folder = Path(tempfile.mkdtemp(prefix="bayescal-eplus-", dir=self._workdir))
        try:
            if self._keep_outputs:
                (folder / "parameters.json").write_text(json.dumps(values), encoding="utf-8")
            return self._run_in(folder, values, forcing)
        finally:
            if not self._keep_outputs:
                shutil.rmtree(folder, ignore_errors=True)

    def fingerprint(self) -> str:
        """Hash of what decides the results (for the runner's cache).

        The model's content, the targets and nominal values, schedules,
        outputs, algorithm, time steps, warm-up and the weather file's content
        enter; where the model or the weather file lie, where runs happen and
        whether their folders are kept, the timeout and the isolation do not,
        so moving a study or keeping outputs keeps its cached runs.
        """
        state = {
            "model": self._model,
            "targets": {n: [list(vars(t).values()) for t in ts] for n, ts in self._targets.items()},
            "nominal": self._nominal,
            "schedules": {n: list(vars(s).values()) for n, s in self._schedules.items()},
            "outputs": {n: list(vars(o).values()) for n, o in self._outputs.items()},
            "algorithm": self._algorithm,
            "timesteps_per_hour": self._tph,
            "weather": self._weather_sha256 or str(self._weather),
            "warmup_days": self._warmup_days,
            "min_warmup_days": self._min_warmup_days,
            "records_per_hour": self._records_per_hour,
        }
        text = json.dumps(state, sort_keys=True, separators=(",", ":"), default=str)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    def _run_in(
        self, folder: Path, values: Mapping[str, float], forcing: Forcing
    ) -> dict[str, np.ndarray]:
        site = self._site()
        intervals = any(spec.aggregate != "point" for spec in self._outputs.values())
        lookback = forcing.step if intervals else 0.0
        clock = _Clock.make(forcing, site.time_zone, self._tph, self._warmup_days, lookback)
        model = copy.deepcopy(self._model)
        for name, targets in self._targets.items():
            for target in targets:
                find_object(model, target.object, target.name)[target.key] = values[name]
        self._configure(model, clock)
        for series, spec in self._schedules.items():
            _write_schedule(model, folder, spec, clock, clock.seconds, forcing[series])
        if self._weather_bytes is not None:
            weather = folder / "weather.epw"
            weather.write_bytes(self._weather_bytes)
        else:
            weather = write_epw(
                folder / "weather.epw", forcing, site, records_per_hour=self._records_per_hour
            )
        model_file = folder / "model.epJSON"
        model_file.write_text(json.dumps(model), encoding="utf-8")
        out = folder / "out"
        arguments = ["-w", str(weather), "-d", str(out), str(model_file)]
        if self._isolation == "subprocess":
            run_energyplus(arguments, self._timeout, folder)
        else:
            run_energyplus_in_process(arguments, self._timeout)
        check_errors(out / "eplusout.err", source=str(self._model_path))
        sql = out / "eplusout.sql"
        return {
            name: read_output(sql, spec, clock.year, clock.seconds, forcing.step)
            for name, spec in self._outputs.items()
        }

    def _site(self) -> EpwSite:
        if self._weather_site is not None:
            return self._weather_site
        location = first_object(self._model, "Site:Location")
        return EpwSite(
            latitude=float(location.get("latitude", 0.0)),
            longitude=float(location.get("longitude", 0.0)),
            time_zone=float(location.get("time_zone", 0.0)),
            elevation=float(location.get("elevation", 0.0)),
        )

    def _configure(self, model: dict[str, Any], clock: _Clock) -> None:
        """Set time step, algorithm, run period, controls and outputs of ``model``."""
        model["Timestep"] = {"Timestep 1": {"number_of_timesteps_per_hour": self._tph}}
        if self._algorithm is not None:
            settings = first_object(model, "HeatBalanceAlgorithm")
            model["HeatBalanceAlgorithm"] = {
                "HeatBalanceAlgorithm 1": {**settings, "algorithm": self._algorithm}
            }
        controls = first_object(model, "SimulationControl")
        controls.update(
            run_simulation_for_sizing_periods="No",
            run_simulation_for_weather_file_run_periods="Yes",
        )
        model["SimulationControl"] = {"SimulationControl 1": controls}
        if self._min_warmup_days is not None:
            for building in objects_of(model, "Building").values():
                building["minimum_number_of_warmup_days"] = int(self._min_warmup_days)
        model["RunPeriod"] = {"bayescal run period": clock.run_period()}
        request_outputs(model, self._outputs)


def paper_wall_simulator(
    *,
    algorithm: Literal[
        "ConductionTransferFunction", "ConductionFiniteDifference"
    ] = "ConductionTransferFunction",
    parameters: Mapping[str, Any] | None = None,
    **options: Any,
) -> EnergyPlusSimulator:
    """The paper's wall in EnergyPlus, driven by its two surface temperatures.

    Parameters
    ----------
    algorithm
        EnergyPlus conduction algorithm.
    parameters
        Calibration parameters; default ``k_cb``, ``cp_cb`` (aerated concrete
        conductivity [W/(m·K)] and specific heat [J/(kg·K)]), ``cp_fb`` and
        ``k_fb`` (glass-fibre boards, both of them).
    **options
        Further :class:`EnergyPlusSimulator` arguments (``timesteps_per_hour``,
        ``timeout``...).

    Returns
    -------
    EnergyPlusSimulator
        Inputs ``temp_surf_out`` and ``temp_surf_in`` [°C]; output
        ``heat_flux_in`` (positive wall -> room) [W/m²].
    """
    if parameters is None:
        parameters = {
            "k_cb": {"object": "Material", "name": "AeratedConcrete", "field": "Conductivity"},
            "cp_cb": {"object": "Material", "name": "AeratedConcrete", "field": "Specific Heat"},
            "cp_fb": {"object": "Material", "name": "GlassFibreBoard", "field": "Specific Heat"},
            "k_fb": {"object": "Material", "name": "GlassFibreBoard", "field": "Conductivity"},
        }
    return EnergyPlusSimulator(
        PAPER_WALL_MODEL,
        parameters=parameters,
        schedules={
            "temp_surf_out": "TempSurfOut",
            "temp_surf_in": ScheduleInput("TempAirIn", lead_steps=1),
        },
        outputs={
            "heat_flux_in": ("Surface Inside Face Conduction Heat Transfer Rate per Area", "Wall")
        },
        algorithm=algorithm,
        **options,
    )


# --------------------------------------------------------------------------- constructor arguments


def _parse_targets(name: str, spec: Any) -> tuple[FieldTarget, ...]:
    items = [spec] if isinstance(spec, Mapping | FieldTarget) else list(spec)
    targets = []
    for item in items:
        if isinstance(item, FieldTarget):
            targets.append(item)
        elif isinstance(item, Mapping) and set(item) == {"object", "name", "field"}:
            targets.append(FieldTarget(str(item["object"]), str(item["name"]), str(item["field"])))
        else:
            raise SimulatorError(
                f"parameter {name!r}: a target must have the keys object, name and field, "
                f"got {item!r}",
                hint='e.g. {"object": "Material", "name": "Concrete", "field": "Conductivity"}',
            )
    if not targets:
        raise SimulatorError(f"parameter {name!r} sets no field")
    return tuple(targets)


def _nominal_value(model: Mapping[str, Any], target: FieldTarget) -> float:
    fields = find_object(model, target.object, target.name)
    value = fields.get(target.key)
    numeric = [k for k, v in fields.items() if isinstance(v, int | float)]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SimulatorError(
            f"{target} is {value!r} in the model, expected a number",
            hint=f"numeric fields of that object: {sorted(numeric)}",
        )
    return float(value)


def _parse_schedule(series: str, spec: Any) -> ScheduleInput:
    if isinstance(spec, ScheduleInput):
        return spec
    if isinstance(spec, str):
        return ScheduleInput(spec)
    if isinstance(spec, Mapping) and "schedule" in spec:
        return ScheduleInput(str(spec["schedule"]), int(spec.get("lead_steps", 0)))
    raise SimulatorError(
        f"schedule for {series!r} must be a Schedule:File name or "
        f'{{"schedule": name, "lead_steps": n}}, got {spec!r}'
    )


def _check_algorithm(algorithm: str | None) -> str | None:
    if algorithm is not None and algorithm not in ALGORITHMS:
        raise SimulatorError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")
    return algorithm


def _timesteps_per_hour(model: Mapping[str, Any], requested: int | None, algorithm: str) -> int:
    if requested is None:
        timestep = first_object(model, "Timestep")
        requested = int(timestep.get("number_of_timesteps_per_hour", 6))
        if algorithm == "ConductionFiniteDifference":
            requested = max(requested, _CONDFD_MIN_TIMESTEPS)
    if not isinstance(requested, int) or requested < 1 or 60 % requested:
        raise SimulatorError(
            f"timesteps_per_hour must divide 60, got {requested!r}",
            hint="use 1, 2, 3, 4, 5, 6, 10, 12, 15, 20, 30 or 60",
        )
    if algorithm == "ConductionFiniteDifference" and requested < _CONDFD_MIN_TIMESTEPS:
        raise SimulatorError(
            f"ConductionFiniteDifference needs at least {_CONDFD_MIN_TIMESTEPS} time steps per "
            f"hour, got {requested}"
        )
    return requested


def _non_negative_int(value: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise SimulatorError(f"{what} must be a non-negative integer, got {value!r}")
    return value


# --------------------------------------------------------------------------- clock and files


@dataclass(frozen=True)
class _Clock:
    """The run's calendar: year, EnergyPlus time step and the forcing instants in it."""

    year: int
    step: float  # EnergyPlus time step [s]
    seconds: np.ndarray  # forcing instants, s since 1 January 00:00 local standard time
    first_day: int  # run period, 0-based day of year
    last_day: int

    @classmethod
    def make(
        cls, forcing: Forcing, time_zone: float, tph: int, warmup_days: int, lookback: float = 0.0
    ) -> _Clock:
        """The calendar of a run; ``lookback`` [s]: the first sample's interval before it."""
        try:
            year = local_year(forcing, time_zone)
        except DataError as exc:
            raise SimulatorError(exc.message, hint=exc.hint) from None
        seconds = seconds_in_year(forcing, year, time_zone)
        step = 3600.0 / tph
        begin = seconds[0] - warmup_days * _DAY - max(step, lookback)
        if begin < 0:
            raise SimulatorError(
                f"the run would start {-begin / _DAY:.2f} days before 1 January {year} "
                "(warm-up days and one time step before the first sample)",
                hint="reduce warmup_days or start the forcing later in the year",
            )
        return cls(year, step, seconds, int(begin // _DAY), int((seconds[-1] - 1.0) // _DAY))

    @property
    def days_in_year(self) -> int:
        return 366 if calendar.isleap(self.year) else 365

    @property
    def grid(self) -> np.ndarray:
        """End of every EnergyPlus time step of the year. [s]"""
        return np.arange(1, round(self.days_in_year * _DAY / self.step) + 1) * self.step

    def run_period(self) -> dict[str, Any]:
        first = np.datetime64(f"{self.year:04d}-01-01") + np.timedelta64(self.first_day, "D")
        last = np.datetime64(f"{self.year:04d}-01-01") + np.timedelta64(self.last_day, "D")
        (m1, d1), (m2, d2) = (tuple(int(x) for x in str(d)[5:10].split("-")) for d in (first, last))
        return {
            "begin_month": m1,
            "begin_day_of_month": d1,
            "begin_year": self.year,
            "end_month": m2,
            "end_day_of_month": d2,
            "end_year": self.year,
            "use_weather_file_holidays_and_special_days": "No",
            "use_weather_file_daylight_saving_period": "No",
            "apply_weekend_holiday_rule": "No",
            "use_weather_file_rain_indicators": "No",
            "use_weather_file_snow_indicators": "No",
        }


def _write_schedule(
    model: dict[str, Any],
    folder: Path,
    spec: ScheduleInput,
    clock: _Clock,
    seconds: np.ndarray,
    values: np.ndarray,
) -> None:
    """Write one ``Schedule:File`` CSV (one row per time step) and point the object at it."""
    grid = clock.grid + spec.lead_steps * clock.step
    path = folder / f"schedule-{energyplus_field_key(spec.schedule)}.csv"
    rows = np.interp(grid, seconds, values).tolist()
    path.write_text("\n".join(map("{:.6f}".format, rows)) + "\n", encoding="ascii")
    fields = find_object(model, "Schedule:File", spec.schedule)
    fields.update(
        file_name=str(path.resolve()),
        column_number=1,
        rows_to_skip_at_top=0,
        number_of_hours_of_data=clock.days_in_year * 24,
        column_separator="Comma",
        interpolate_to_timestep="No",
        minutes_per_item=round(clock.step / 60.0),
    )
