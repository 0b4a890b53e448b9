"""What an EnergyPlus run reports, and reading it back on the study clock.

:func:`request_outputs` removes the model's own reports (``Output:Variable``,
``Output:Meter``, tables, surface lists...) and asks for the series a study
needs, at every EnergyPlus time step, in ``eplusout.sql`` only: a reference
building asks for hundreds of hourly series and tables that would cost run
time and disk and that nobody reads. :func:`read_output` reads one series
back and puts it on the study clock:

``aggregate = "point"``
    The value at each clock instant, interpolated linearly between the ends
    of EnergyPlus's time steps (the instantaneous series of a wall or a box).
``aggregate = "sum"``
    The total over each clock interval ``(t - step, t]``: the sum of the
    time steps' values in it (a meter's J per time step add up to the J of a
    clock interval).
``aggregate = "mean"``
    The mean over each clock interval (a zone temperature averaged over an
    hour, like a logger's hourly mean).

A clock instant between time-step ends splits a time step in proportion
(the cumulative sum is interpolated linearly), so sums and means stay exact
where the clock is on EnergyPlus's grid, the usual case (an hourly clock and
six time steps per hour).
"""

from __future__ import annotations

import calendar
import sqlite3
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from bayescal.errors import SimulatorError

__all__ = [
    "AGGREGATES",
    "MODEL_REPORT_OBJECTS",
    "OutputSpec",
    "interval_series",
    "parse_output",
    "read_output",
    "request_outputs",
]

_DAY = 86400.0
AGGREGATES = ("point", "mean", "sum")

MODEL_REPORT_OBJECTS = (
    "Output:Variable",
    "Output:Meter",
    "Output:Meter:MeterFileOnly",
    "Output:Meter:Cumulative",
    "Output:Meter:Cumulative:MeterFileOnly",
    "Output:Table:Monthly",
    "Output:Table:Annual",
    "Output:Table:TimeBins",
    "Output:Table:SummaryReports",
    "OutputControl:Table:Style",
    "Output:Surfaces:Drawing",
    "Output:Surfaces:List",
    "Output:Constructions",
    "Output:VariableDictionary",
    "Output:Schedules",
    "Output:EnvironmentalImpactFactors",
    "Output:SQLite",
)
"""Report objects of a model that the adapter removes before adding its own requests."""


@dataclass(frozen=True)
class OutputSpec:
    """An EnergyPlus report variable or meter returned as an output series.

    Parameters
    ----------
    variable
        Report variable name (``"Zone Mean Air Temperature"``) or, with
        ``meter=True``, meter name (``"Electricity:Facility"``).
    key
        Key value (the surface, zone... name), case-insensitive; ignored for
        a meter.
    scale
        Factor applied to the values (``-1`` to flip a sign convention).
    meter
        ``variable`` names a meter (``Output:Meter``): its value per time step
        is an energy [J].
    aggregate
        ``"point"``, ``"mean"`` or ``"sum"`` over each clock interval (see
        the module notes).
    """

    variable: str
    key: str
    scale: float = 1.0
    meter: bool = False
    aggregate: Literal["point", "mean", "sum"] = "point"


def parse_output(name: str, spec: Any) -> OutputSpec:
    """An :class:`OutputSpec` from ``(variable, key[, scale])``, a mapping or itself.

    A mapping holds ``variable`` and ``key``, or ``meter``; and optionally
    ``scale`` and ``aggregate``.
    """
    if isinstance(spec, OutputSpec):
        found = spec
    elif isinstance(spec, Sequence) and not isinstance(spec, str) and len(spec) in (2, 3):
        found = OutputSpec(str(spec[0]), str(spec[1]), float(spec[2]) if len(spec) == 3 else 1.0)
    elif isinstance(spec, Mapping) and ("meter" in spec) != ("variable" in spec):
        meter = "meter" in spec
        found = OutputSpec(
            str(spec["meter"] if meter else spec["variable"]),
            "" if meter else str(spec.get("key", "")),
            float(spec.get("scale", 1.0)),
            meter,
            spec.get("aggregate", "point"),
        )
    else:
        raise SimulatorError(
            f"output {name!r} must be (variable, key), (variable, key, scale) or a mapping "
            f"with 'variable' and 'key' or 'meter', got {spec!r}"
        )
    if found.aggregate not in AGGREGATES:
        raise SimulatorError(
            f"output {name!r}: aggregate must be one of {AGGREGATES}, got {found.aggregate!r}"
        )
    if found.meter and found.aggregate == "point":
        raise SimulatorError(
            f"output {name!r}: the meter {found.variable!r} gives energy per time step; "
            "aggregate it with 'sum' (or 'mean')"
        )
    return found


def request_outputs(model: dict[str, Any], outputs: Mapping[str, OutputSpec]) -> None:
    """Replace the model's reports by the series of ``outputs``, every time step, in SQLite."""
    for key in [k for k in model if k.lower() in {o.lower() for o in MODEL_REPORT_OBJECTS}]:
        del model[key]
    variables: dict[str, Any] = {}
    meters: dict[str, Any] = {}
    for name, spec in outputs.items():
        if spec.meter:
            meters[f"bayescal {name}"] = {
                "key_name": spec.variable,
                "reporting_frequency": "Timestep",
            }
        else:
            variables[f"bayescal {name}"] = {
                "key_value": spec.key,
                "variable_name": spec.variable,
                "reporting_frequency": "Timestep",
            }
    if variables:
        model["Output:Variable"] = variables
    if meters:
        model["Output:Meter"] = meters
    model["Output:SQLite"] = {"Output:SQLite 1": {"option_type": "Simple"}}


_QUERY = (
    "SELECT t.Month, t.Day, t.Hour, t.Minute, r.Value FROM ReportData r "
    "JOIN ReportDataDictionary d ON r.ReportDataDictionaryIndex = d.ReportDataDictionaryIndex "
    "JOIN Time t ON r.TimeIndex = t.TimeIndex "
    "WHERE upper(d.Name) = upper(?) AND upper(coalesce(d.KeyValue, '')) = upper(?) "
    "AND d.IsMeter = ? "
    "AND (t.WarmupFlag IS NULL OR t.WarmupFlag = 0) ORDER BY t.TimeIndex"
)


def read_output(
    sql: Path, spec: OutputSpec, year: int, seconds: np.ndarray, interval: float
) -> np.ndarray:
    """One requested series from ``eplusout.sql``, on the study clock, scaled.

    Parameters
    ----------
    sql
        The run's ``eplusout.sql``.
    spec
        The series.
    year
        Calendar year of the run.
    seconds
        Clock instants, seconds since 1 January 00:00 local standard time. [s]
    interval
        Clock step: the length of the intervals ``(t - interval, t]`` of a sum
        or a mean. [s]
    """
    if not sql.is_file():
        raise SimulatorError("EnergyPlus wrote no eplusout.sql", source=str(sql.parent))
    connection = sqlite3.connect(f"file:{sql}?mode=ro", uri=True)
    try:
        key = "" if spec.meter else spec.key
        found = connection.execute(_QUERY, (spec.variable, key, int(spec.meter))).fetchall()
        rows = np.array(found, float)
    finally:
        connection.close()
    if rows.size == 0:
        what = f"{spec.variable!r} for key {spec.key!r}"
        if spec.meter:
            what = f"meter {spec.variable!r}"
        raise SimulatorError(
            f"EnergyPlus reported no {what}",
            hint="check the name (and key) against eplusout.rdd / eplusout.mdd of a run of "
            "the model",
        )
    month_start = np.cumsum([0] + [calendar.monthrange(year, m)[1] for m in range(1, 12)])
    day = month_start[rows[:, 0].astype(int) - 1] + rows[:, 1] - 1
    times = day * _DAY + rows[:, 2] * 3600.0 + rows[:, 3] * 60.0
    if spec.aggregate == "point":
        values = np.interp(seconds, times, rows[:, 4])
    else:
        values = interval_series(times, rows[:, 4], seconds, interval, spec.aggregate)
    return spec.scale * values


def interval_series(
    times: np.ndarray, values: np.ndarray, ends: np.ndarray, interval: float, how: str
) -> np.ndarray:
    """Sums or means of time-step values over the intervals ``(t - interval, t]``.

    Parameters
    ----------
    times
        End of each time step, increasing, equally spaced. [s]
    values
        Value of each time step: an amount (``"sum"``) or a mean rate or
        level over the step (``"mean"``).
    ends
        End of each interval. [s]
    interval
        Length of the intervals. [s]
    how
        ``"sum"`` or ``"mean"``.

    Raises
    ------
    SimulatorError
        If an interval starts before the first time step or ends after the last.
    """
    step = float(np.median(np.diff(times))) if times.size > 1 else interval
    grid = np.concatenate(([times[0] - step], times))
    amounts = values * (step if how == "mean" else 1.0)
    cumulative = np.concatenate(([0.0], np.cumsum(amounts)))
    if ends[0] - interval < grid[0] - 1e-6 or ends[-1] > grid[-1] + 1e-6:
        raise SimulatorError(
            "EnergyPlus's run period does not cover the clock's intervals "
            f"({(grid[0] - ends[0] + interval) / 3600.0:.3g} h missing at the start)",
            hint="this is a bug of the adapter's run period; please report it",
        )
    total = np.interp(ends, grid, cumulative) - np.interp(ends - interval, grid, cumulative)
    return np.asarray(total / interval if how == "mean" else total, dtype=float)
