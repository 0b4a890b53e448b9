"""The simulator protocol and the boundary-condition container.

A simulator maps calibration parameters (physical units) and boundary-condition
series on the study clock to output series on the same clock. Simulators are
deterministic, cheap to construct and picklable so that they can run in worker
processes; the built-in ones do no I/O.

Time convention
---------------
Series are sampled at the instants ``t_i = start + i * step``; between samples
the built-in simulators interpolate boundary conditions linearly, and their
outputs are the values at the same instants.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from bayescal.errors import SimulatorError


@dataclass(frozen=True)
class Forcing:
    """Boundary-condition series on one regular clock.

    Parameters
    ----------
    step
        Time step of the clock. [s]
    series
        Glossary name -> values, all of the same length ``n``, in internal
        units (°C, W/m², W, m/s, ...).
    start
        Time of the first sample, UTC (``numpy.datetime64``); needed by
        simulators that compute solar geometry.
    """

    step: float
    series: Mapping[str, np.ndarray]
    start: np.datetime64 = field(default_factory=lambda: np.datetime64("2000-01-01T00:00"))

    def __post_init__(self) -> None:
        if not np.isfinite(self.step) or self.step <= 0:
            raise SimulatorError(f"forcing time step must be positive, got {self.step!r} s")
        lengths = {name: np.shape(v) for name, v in self.series.items()}
        shapes = set(lengths.values())
        if len(shapes) > 1:
            raise SimulatorError(f"forcing series have different shapes: {lengths}")
        for name, v in self.series.items():
            if np.ndim(v) != 1:
                raise SimulatorError(f"forcing series {name!r} must be 1-D, got ndim={np.ndim(v)}")
            if not np.all(np.isfinite(v)):
                raise SimulatorError(f"forcing series {name!r} contains NaN or infinite values")

    @property
    def n(self) -> int:
        """Number of samples."""
        for v in self.series.values():
            return int(np.shape(v)[0])
        return 0

    @property
    def times(self) -> np.ndarray:
        """Sample instants (UTC ``datetime64[s]``)."""
        offsets = (np.arange(self.n) * self.step).astype("timedelta64[s]")
        return np.asarray(self.start, dtype="datetime64[s]") + offsets

    def require(self, names: tuple[str, ...] | list[str], who: str) -> None:
        """Raise a clear error if any of ``names`` is missing."""
        missing = [n for n in names if n not in self.series]
        if missing:
            raise SimulatorError(
                f"{who} needs boundary condition(s) {missing}, "
                f"the forcing has {sorted(self.series)}",
                hint="map the measured columns to these glossary names in [data.columns]",
            )

    def __getitem__(self, name: str) -> np.ndarray:
        return np.asarray(self.series[name], dtype=float)

    def refined(self, k: int, names: tuple[str, ...] | None = None) -> Forcing:
        """The forcing on a clock ``k`` times finer (same start), each series
        interpolated linearly between its samples; only ``names`` (those present)
        where given."""
        keep = self.series if names is None else [n for n in names if n in self.series]
        coarse = np.arange(self.n, dtype=float)
        fine = np.arange((self.n - 1) * k + 1, dtype=float) / k
        series = {name: np.interp(fine, coarse, self[name]) for name in keep}
        return Forcing(self.step / k, series, self.start)


@runtime_checkable
class Simulator(Protocol):
    """What the pipeline needs from a simulator."""

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the calibration parameters ``simulate`` accepts."""
        ...

    @property
    def input_names(self) -> tuple[str, ...]:
        """Glossary names of the boundary-condition series it needs."""
        ...

    @property
    def output_names(self) -> tuple[str, ...]:
        """Glossary (or model-specific) names of the series it returns."""
        ...

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        """Run once.

        Parameters
        ----------
        parameters
            Calibration parameter values in physical units; names not given
            keep the simulator's nominal values.
        forcing
            Boundary conditions on the study clock.

        Returns
        -------
        dict
            Output name -> series of length ``forcing.n``.
        """
        ...


@runtime_checkable
class Derivable(Protocol):
    """A simulator that computes physical summaries of a parameter set.

    ``derived_units`` maps each quantity's name to ``(unit, description)``;
    ``derived(parameters)`` returns their values (the wall's U-value, thermal
    resistance and areal heat capacity, the box's heat-loss coefficient). The
    pipeline evaluates them at every posterior draw.
    """

    @property
    def derived_units(self) -> Mapping[str, tuple[str, str]]:
        """Quantity name -> ``(unit, description)``."""
        ...

    def derived(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """The quantities at ``parameters`` (physical units)."""
        ...


def check_parameters(parameters: Mapping[str, float], allowed: tuple[str, ...], who: str) -> None:
    """Raise :class:`SimulatorError` for unknown or non-finite parameter values."""
    unknown = sorted(set(parameters) - set(allowed))
    if unknown:
        raise SimulatorError(f"{who} has no parameter(s) {unknown}; it accepts {list(allowed)}")
    for name, value in parameters.items():
        if not np.isfinite(value):
            raise SimulatorError(f"{who}: parameter {name!r} is not finite ({value!r})")
