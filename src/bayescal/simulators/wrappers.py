"""Simulators wrapped around another one: study parameter names, sensor models, fixed values.

All forward the inner simulator's boundary conditions and outputs.
:class:`TargetedSimulator` exposes a simulator whose own parameters have
fixed names (a box constant, a template placeholder) under the study's
parameter names; :class:`SensorModel` passes outputs through calibrated
sensors (``reading = gain * simulated + offset``); :class:`FixedParameters`
holds some parameters at given values (screening candidates at their
nominal values while the others are calibrated).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from bayescal.errors import SimulatorError
from bayescal.simulators.base import Derivable, Forcing, Simulator, check_parameters

__all__ = ["FixedParameters", "SensorModel", "TargetedSimulator"]


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
