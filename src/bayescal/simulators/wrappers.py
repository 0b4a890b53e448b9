"""Simulators wrapped around another one: study parameter names, sensor models, fixed values.

All forward the inner simulator's boundary conditions and outputs.
:class:`TargetedSimulator` exposes a simulator whose own parameters have
fixed names (a box constant, a template placeholder) under the study's
parameter names; :class:`SensorModel` passes outputs through calibrated
sensors (``reading = gain * simulated + offset``); :class:`FixedParameters`
holds some parameters at given values (screening candidates at their
nominal values while the others are calibrated); :class:`IntervalMeans` gives
some outputs as means over the clock intervals, as a logger that averages
records them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from bayescal.errors import SimulatorError
from bayescal.simulators.base import Derivable, Forcing, Simulator, check_parameters

__all__ = ["FixedParameters", "IntervalMeans", "SensorModel", "TargetedSimulator"]


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

    @property
    def derived_units(self) -> dict[str, tuple[str, str]]:
        """The inner simulator's derived quantities (none if it has none)."""
        return dict(self.inner.derived_units) if isinstance(self.inner, Derivable) else {}

    def _inner_derived(self, inner: Mapping[str, float]) -> dict[str, float]:
        return self.inner.derived(inner) if isinstance(self.inner, Derivable) else {}


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

    def derived(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """The inner simulator's derived quantities at the mapped parameters."""
        return self._inner_derived(
            {t: float(v) for name, v in parameters.items() for t in self.targets[name]}
        )


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

    def derived(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """The inner simulator's derived quantities (sensor parameters left out)."""
        return self._inner_derived({k: v for k, v in parameters.items() if k not in self.sensors})

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


@dataclass(frozen=True)
class FixedParameters(_Wrapped):
    """A simulator with some of its parameters held at given values.

    Parameters
    ----------
    inner
        The simulator.
    fixed
        Parameter name -> value it is held at (physical units); these names
        are no longer parameters of the wrapper.
    """

    fixed: Mapping[str, float]

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(n for n in self.inner.parameter_names if n not in self.fixed)

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        check_parameters(parameters, self.parameter_names, type(self.inner).__name__)
        return self.inner.simulate({**self.fixed, **parameters}, forcing)


@dataclass(frozen=True)
class IntervalMeans(_Wrapped):
    """A simulator whose chosen outputs are means over the clock intervals.

    A logger that averages records at the timestamp ``t`` the mean over
    ``(t - step, t]`` (``[data.columns.<name>] aggregate = "mean"``); a
    simulator that gives values at the instants lags it by about half a step,
    which a calibration can only mimic with its parameters (more thermal mass).
    This wrapper runs ``inner`` on a clock ``substeps`` times finer, its
    boundary conditions interpolated linearly between the samples, and
    averages the outputs named in ``means`` over each interval by the
    trapezoidal rule (the first sample, with no interval before it, keeps the
    instantaneous value). The other outputs are the fine run's values at the
    clock instants. A run costs about ``substeps`` times as much.

    Parameters
    ----------
    inner
        The simulator, giving values at the instants.
    means
        Outputs returned as interval means.
    substeps
        Fine steps per clock interval (>= 1; 1 averages the two end values).
    """

    means: tuple[str, ...]
    substeps: int = 6

    def __post_init__(self) -> None:
        if int(self.substeps) < 1:
            raise SimulatorError(f"substeps must be >= 1, got {self.substeps!r}")
        unknown = sorted(set(self.means) - set(self.inner.output_names))
        if unknown and self.inner.output_names:
            raise SimulatorError(
                f"interval means asked of {unknown}, which the simulator does not produce",
                hint=f"it produces {', '.join(self.inner.output_names)}",
            )

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.inner.parameter_names

    def derived(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """The inner simulator's derived quantities."""
        return self._inner_derived(parameters)

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        fine = int(self.substeps)
        out = self.inner.simulate(parameters, forcing.refined(fine))
        result = {}
        for name, values in out.items():
            values = np.asarray(values, dtype=float)
            if name in self.means:
                result[name] = interval_means(values, fine)
            else:
                result[name] = values[::fine].copy()
        return result


def interval_means(fine_values: np.ndarray, substeps: int) -> np.ndarray:
    """Means over each interval of ``substeps`` fine steps, by the trapezoidal rule.

    ``fine_values`` has ``(n - 1) * substeps + 1`` values; the result has ``n``:
    the first the instantaneous value, the ``i``-th the mean over the fine
    values from ``(i - 1) * substeps`` to ``i * substeps``.
    """
    v = np.asarray(fine_values, dtype=float)
    if (v.size - 1) % substeps:
        raise SimulatorError(
            f"{v.size} fine values do not make whole intervals of {substeps} steps"
        )
    out = np.empty((v.size - 1) // substeps + 1)
    out[0] = v[0]
    if out.size > 1:
        cells = v[1:].reshape(-1, substeps).sum(axis=1) - 0.5 * v[substeps::substeps]
        cells += 0.5 * v[:-1:substeps]
        out[1:] = cells / substeps
    return out
