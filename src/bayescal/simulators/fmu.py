"""Functional Mock-up Units (co-simulation, FMI 2.0 and 3.0) as simulators, through FMPy.

A :class:`FmuSimulator` maps calibration parameters to FMU variables, forcing
series to FMU inputs and FMU variables to outputs, and runs the FMU over the
forcing's clock with its own communication loop:

* FMU time of the forcing's first sample is ``start_time``; the
  communication step is the forcing step divided by ``substeps``;
* before each step the inputs are set to the forcing values at the
  communication point (linear interpolation between samples at sub-steps);
  an FMI 2.0 FMU that declares ``canInterpolateInputs`` also receives the
  slope of each input over the step (``fmi2SetRealInputDerivatives``), so it
  sees the same piecewise-linear boundary conditions as the built-in
  simulators. Other FMUs hold the input constant over a communication step
  (zero-order hold); raise ``substeps`` to reduce the difference;
* after the step that ends at a sample instant the inputs are set to that
  sample's values and then the outputs are read, so outputs with direct
  feedthrough use the input at the same instant.

The FMU file is extracted once per process and reused; the simulator object
holds only the path and the mappings, so it pickles cheaply to worker
processes. FMPy changes the working directory while it loads an FMU's shared
library, so run FMUs in separate processes, not threads.

Units: values are passed unchanged unless ``units`` names the unit an FMU
input or output uses (one of :func:`bayescal.units.known_units`), in which
case inputs are converted from, and outputs to, bayescal's internal units
(e.g. ``{"T_out": "K"}`` for a Modelica FMU). Parameters are never converted.
"""

from __future__ import annotations

import atexit
import difflib
import math
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.errors import ConfigError, DataError, SimulatorError
from bayescal.simulators.base import Forcing, check_parameters
from bayescal.units import to_internal

_REAL_TYPES = ("Real", "Float64")
_EXTRACTED: dict[tuple[str, int, int], tuple[str, Any]] = {}  # per-process cache
_LOG_KEEP = 5  # FMU log messages kept for error messages


def _fmpy() -> Any:
    try:
        import fmpy
    except ImportError as exc:
        raise SimulatorError(
            "FMU simulators need the FMPy package, which is not installed",
            hint="pip install 'bayescal[fmu]'",
        ) from exc
    return fmpy


def _open_fmu(path: str) -> tuple[str, Any]:
    """Extracted folder and model description of an FMU, cached per process."""
    fmpy = _fmpy()
    try:
        st = os.stat(path)
    except OSError as exc:
        raise SimulatorError(f"cannot read FMU: {exc.strerror}", source=path) from None
    key = (path, st.st_size, st.st_mtime_ns)
    if key not in _EXTRACTED:
        try:
            if os.path.isdir(path):
                unzipdir = path
            else:
                unzipdir = str(fmpy.extract(path))
                atexit.register(shutil.rmtree, unzipdir, True)
            description = fmpy.read_model_description(unzipdir, validate=True)
        except Exception as exc:  # FMPy raises bare Exceptions for invalid files
            raise SimulatorError(
                f"not a valid FMU: {' '.join(str(exc).split())}", source=path
            ) from exc
        _EXTRACTED[key] = (unzipdir, description)
    return _EXTRACTED[key]


def _platform_dir(description: Any) -> str:
    fmpy = _fmpy()
    return str(fmpy.platform if description.fmiVersion == "2.0" else fmpy.platform_tuple)


class _Log:
    """Collects the FMU's last log messages (FMI 2 and FMI 3 logger signatures)."""

    def __init__(self) -> None:
        self.messages: list[str] = []

    def __call__(self, *args: Any) -> None:
        message = args[-1]
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        self.messages = [*self.messages[-(_LOG_KEEP - 1) :], text]

    def tail(self) -> str:
        return " | ".join(self.messages)


class _Fmi2:
    """FMI 2.0 co-simulation calls used by the loop."""

    def __init__(self, fmu: Any, interpolates: bool):
        self.fmu = fmu
        self.interpolates = interpolates

    def begin(
        self, t0: float, t1: float, tol: float | None, vrs: list[int], v: list[float]
    ) -> None:
        self.fmu.setupExperiment(tolerance=tol, startTime=t0, stopTime=t1)
        if vrs:
            self.fmu.setReal(vrs, v)
        self.fmu.enterInitializationMode()

    def end_init(self) -> None:
        self.fmu.exitInitializationMode()

    def set(self, vrs: list[int], values: list[float]) -> None:
        if vrs:
            self.fmu.setReal(vrs, values)

    def slopes(self, vrs: list[int], values: list[float]) -> None:
        if vrs and self.interpolates:
            self.fmu.setRealInputDerivatives(vrs, [1] * len(vrs), values)

    def step(self, t: float, h: float) -> None:
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def get(self, vrs: list[int]) -> list[float]:
        return list(self.fmu.getReal(vrs))


class _Fmi3(_Fmi2):
    """FMI 3.0 co-simulation calls used by the loop (no input interpolation)."""

    def begin(
        self, t0: float, t1: float, tol: float | None, vrs: list[int], v: list[float]
    ) -> None:
        if vrs:
            self.fmu.setFloat64(vrs, v)
        self.fmu.enterInitializationMode(tolerance=tol, startTime=t0, stopTime=t1)

    def set(self, vrs: list[int], values: list[float]) -> None:
        if vrs:
            self.fmu.setFloat64(vrs, values)

    def slopes(self, vrs: list[int], values: list[float]) -> None:
        return None

    def step(self, t: float, h: float) -> None:
        _, terminate, early, last = self.fmu.doStep(
            currentCommunicationPoint=t, communicationStepSize=h
        )
        if terminate or (early and last < t + h):
            raise SimulatorError(f"the FMU stopped the simulation at t = {last!r} s")

    def get(self, vrs: list[int]) -> list[float]:
        return list(self.fmu.getFloat64(vrs))


class FmuSimulator:
    """A co-simulation FMU (FMI 2.0 or 3.0) run through FMPy.

    Parameters
    ----------
    fmu
        Path of the ``.fmu`` file (or of an extracted FMU folder).
    parameters
        Calibration parameter -> FMU variable name, or a list of names that
        all receive the value (e.g. the same conductivity in two layers).
    inputs
        FMU input variable -> forcing series name.
    outputs
        Output name -> FMU variable read at each sample instant.
    start_values
        Further FMU variables fixed for every run (variable -> value).
    units
        FMU input or output variable -> the unit it uses; converted from and
        to bayescal's internal units. Variables not listed are not converted.
    start_time
        FMU time of the forcing's first sample. [s]
    substeps
        Communication steps per forcing step.
    tolerance
        Relative tolerance passed to the FMU's solver (``None``: its default).
    name
        Short name used in messages (default: the FMU's model name).
    """

    def __init__(
        self,
        fmu: str | os.PathLike[str],
        *,
        parameters: Mapping[str, str | Sequence[str]],
        inputs: Mapping[str, str],
        outputs: Mapping[str, str],
        start_values: Mapping[str, float] | None = None,
        units: Mapping[str, str] | None = None,
        start_time: float = 0.0,
        substeps: int = 1,
        tolerance: float | None = None,
        name: str | None = None,
    ):
        self.path = str(Path(fmu).resolve())
        self._parameters = {
            p: (v,) if isinstance(v, str) else tuple(v) for p, v in parameters.items()
        }
        self._inputs = dict(inputs)
        self._outputs = dict(outputs)
        try:
            self.start_values = {k: float(v) for k, v in (start_values or {}).items()}
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"FMU start values must be numbers: {exc}") from None
        self.units = dict(units or {})
        if not outputs:
            raise ConfigError("an FMU simulator needs at least one output")
        if not (isinstance(substeps, int) and substeps >= 1):
            raise ConfigError(f"substeps must be a positive integer, got {substeps!r}")
        if not math.isfinite(start_time):
            raise ConfigError(f"start_time must be finite, got {start_time!r}")
        self.start_time = float(start_time)
        self.substeps = substeps
        self.tolerance = tolerance
        _, description = _open_fmu(self.path)
        self.name = name or str(description.modelName)
        self._validate(description)

    # -- Simulator protocol -------------------------------------------------

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the calibration parameters."""
        return tuple(self._parameters)

    @property
    def input_names(self) -> tuple[str, ...]:
        """Forcing series the FMU's inputs are fed from."""
        return tuple(dict.fromkeys(self._inputs.values()))

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the returned series."""
        return tuple(self._outputs)

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        """Run the FMU over the forcing's clock.

        Parameters
        ----------
        parameters
            Calibration parameter values, in the units of the FMU variables
            they set; missing ones keep the FMU's start values.
        forcing
            Boundary conditions on the study clock.

        Returns
        -------
        dict
            Output name -> series of length ``forcing.n``.

        Raises
        ------
        SimulatorError
            For bad parameter values, a missing forcing series, or an FMU that
            fails (the message names the FMU, the FMI call and its last log
            messages).
        """
        check_parameters(parameters, self.parameter_names, self.name)
        forcing.require(self.input_names, who=self.name)
        if forcing.n == 0:
            raise SimulatorError(f"{self.name}: the forcing has no samples")
        unzipdir, description = _open_fmu(self.path)
        lookup = {v.name: v for v in description.modelVariables}
        start = dict(self.start_values)
        for par, value in parameters.items():
            start.update({var: float(value) for var in self._parameters[par]})
        u = self._input_table(forcing)
        log = _Log()
        fmu = self._instantiate(unzipdir, description, log)
        try:
            y = self._loop(fmu, description, lookup, start, u, forcing.step)
        except SimulatorError as exc:
            raise self._error(exc.message, log) from exc
        except Exception as exc:  # FMPy's FMICallException and bare Exceptions
            raise self._error(" ".join(str(exc).split()), log) from exc
        finally:
            fmu.freeInstance()
        return self._output_table(y)

    # -- construction helpers ----------------------------------------------

    def _validate(self, description: Any) -> None:
        where = f"FMU {self.name!r} ({self.path})"
        if description.coSimulation is None:
            raise SimulatorError(f"{where} has no co-simulation interface; only those are run")
        if description.fmiVersion != "2.0" and not description.fmiVersion.startswith("3."):
            raise SimulatorError(f"{where} is FMI {description.fmiVersion}; FMI 2.0 or 3.0 needed")
        unzipdir, _ = _open_fmu(self.path)
        library = (
            Path(unzipdir)
            / "binaries"
            / _platform_dir(description)
            / (description.coSimulation.modelIdentifier + _fmpy().sharedLibraryExtension)
        )
        if not library.is_file():
            raise SimulatorError(
                f"{where} has no binary for this platform ({_platform_dir(description)})",
                hint="export the FMU for this platform or with source code",
            )
        lookup = {v.name: v for v in description.modelVariables}
        for par, targets in self._parameters.items():
            if not (par.isascii() and par.isidentifier()):
                raise ConfigError(f"parameter name {par!r} is not a valid name")
            for var in targets:
                self._check_settable(lookup, var, f"parameter {par!r}")
        for var in self.start_values:
            self._check_settable(lookup, var, "start value")
        for var in self._inputs:
            if self._variable(lookup, var, "input").causality != "input":
                raise SimulatorError(f"{where}: variable {var!r} is not an input")
        for out, var in self._outputs.items():
            self._variable(lookup, var, f"output {out!r}")
        for var, unit in self.units.items():
            if var not in self._inputs and var not in self._outputs.values():
                raise ConfigError(f"units given for {var!r}, which is no input or output")
            try:
                to_internal(0.0, unit)
            except DataError as exc:
                raise ConfigError(f"units of FMU variable {var!r}: {exc.message}") from None

    def _variable(self, lookup: Mapping[str, Any], var: str, role: str) -> Any:
        if var not in lookup:
            close = difflib.get_close_matches(var, list(lookup), n=3)
            raise SimulatorError(
                f"FMU {self.name!r} has no variable {var!r} (for {role})",
                source=self.path,
                hint=f"did you mean {close}?" if close else "list them with `fmpy info FILE`",
            )
        variable = lookup[var]
        if variable.type not in _REAL_TYPES:
            raise SimulatorError(
                f"FMU variable {var!r} (for {role}) is of type {variable.type}; "
                "only Real / Float64 variables are supported",
                source=self.path,
            )
        return variable

    def _check_settable(self, lookup: Mapping[str, Any], var: str, role: str) -> None:
        variable = self._variable(lookup, var, role)
        ok = variable.variability != "constant" and (
            variable.causality == "parameter" or variable.initial in ("exact", "approx")
        )
        if not ok:
            raise SimulatorError(
                f"FMU variable {var!r} (for {role}) cannot be set before a run: it has "
                f"causality {variable.causality!r}, variability {variable.variability!r}",
                source=self.path,
                hint="map it to a parameter of the FMU",
            )

    # -- one run ------------------------------------------------------------

    def _error(self, message: str, log: _Log) -> SimulatorError:
        tail = log.tail()
        return SimulatorError(
            f"FMU {self.name!r} failed: {message}" + (f"; FMU log: {tail}" if tail else ""),
            source=self.path,
        )

    def _instantiate(self, unzipdir: str, description: Any, log: _Log) -> Any:
        from fmpy.simulation import instantiate_fmu

        try:
            return instantiate_fmu(unzipdir, description, "CoSimulation", logger=log)
        except Exception as exc:  # FMPy raises bare Exceptions
            raise self._error(f"cannot instantiate: {exc}", log) from exc

    def _input_table(self, forcing: Forcing) -> np.ndarray:
        """Input values in FMU units, shape (n, n_inputs)."""
        columns = []
        for var, series in self._inputs.items():
            values = forcing[series]
            if var in self.units:
                offset, one = to_internal(np.array([0.0, 1.0]), self.units[var])
                values = (values - offset) / (one - offset)
            columns.append(values)
        return np.column_stack(columns) if columns else np.zeros((forcing.n, 0))

    def _output_table(self, y: np.ndarray) -> dict[str, np.ndarray]:
        result = {}
        for k, (out, var) in enumerate(self._outputs.items()):
            values = y[:, k]
            if var in self.units:
                values = to_internal(values, self.units[var])
            if not np.all(np.isfinite(values)):
                bad = int(np.argmin(np.isfinite(values)))
                raise SimulatorError(
                    f"FMU {self.name!r}: output {out!r} ({var}) is not finite at sample {bad}",
                    source=self.path,
                )
            result[out] = values
        return result

    def _loop(
        self,
        fmu: Any,
        description: Any,
        lookup: Mapping[str, Any],
        start: Mapping[str, float],
        u: np.ndarray,
        step: float,
    ) -> np.ndarray:
        """The communication loop; returns outputs in FMU units, shape (n, n_outputs)."""
        if description.fmiVersion == "2.0":
            api: _Fmi2 = _Fmi2(fmu, bool(description.coSimulation.canInterpolateInputs))
        else:
            api = _Fmi3(fmu, False)
        in_vrs = [lookup[v].valueReference for v in self._inputs]
        out_vrs = [lookup[v].valueReference for v in self._outputs.values()]
        n, m = u.shape[0], self.substeps
        t0 = self.start_time
        api.begin(t0, t0 + (n - 1) * step, self.tolerance, *_vrs_values(lookup, start))
        api.set(in_vrs, u[0].tolist())
        api.end_init()
        y = np.empty((n, len(out_vrs)))
        y[0] = api.get(out_vrs)
        h = step / m
        for i in range(n - 1):
            slope = ((u[i + 1] - u[i]) / step).tolist()
            for j in range(m):
                if j > 0:
                    api.set(in_vrs, (u[i] + (u[i + 1] - u[i]) * (j / m)).tolist())
                api.slopes(in_vrs, slope)
                api.step(t0 + (i + j / m) * step, h)
            api.set(in_vrs, u[i + 1].tolist())
            y[i + 1] = api.get(out_vrs)
        fmu.terminate()
        return y


def _vrs_values(lookup: Mapping[str, Any], start: Mapping[str, float]) -> tuple[list[int], list]:
    names = list(start)
    return [lookup[v].valueReference for v in names], [start[v] for v in names]
