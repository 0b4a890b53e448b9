"""Run a study's simulator once (at the nominal or given parameters) and compare.

This is the quickest look at a study: does the simulator, driven by the
measured boundary conditions, reproduce the measured outputs at all?
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from bayescal.atomic import atomic_write_text
from bayescal.config import Study, build_simulator, nominal_parameters
from bayescal.data.measured import MeasuredData, load_measured
from bayescal.errors import ConfigError
from bayescal.metrics import Metrics, fit_metrics


@dataclass(frozen=True)
class SimulationCheck:
    """One simulator run compared with the measurements.

    Attributes
    ----------
    parameters
        Values used (physical units).
    simulated
        Output name -> series on the study clock.
    measured
        The measured data.
    train, test
        Output name -> metrics over the training window (after the warm-up)
        and over the test window, for the calibrated outputs and the held-out
        sensors.
    """

    parameters: dict[str, float]
    simulated: dict[str, np.ndarray]
    measured: MeasuredData
    train: dict[str, Metrics]
    test: dict[str, Metrics]


def check_simulation(study: Study, overrides: Mapping[str, float] | None = None) -> SimulationCheck:
    """Run the simulator once on the measured boundary conditions and score it.

    Parameters
    ----------
    study
        A validated study.
    overrides
        Parameter values replacing the nominal ones (physical units).
    """
    parameters = nominal_parameters(study)
    for name, value in (overrides or {}).items():
        if name not in parameters:
            raise ConfigError(f"unknown parameter {name!r}; the study has {sorted(parameters)}")
        parameters[name] = float(value)
    measured = load_measured(study)
    simulator = build_simulator(study, screening=True)  # --set may change a candidate too
    simulated = simulator.simulate(parameters, measured.forcing)
    layout = measured.layout
    first = int(layout.train_starts[0]) if layout.m_star else layout.warmup
    train, test = {}, {}
    observed = {**measured.outputs, **measured.held_out}  # held-out sensors are scored too
    for name in (*study.outputs.calibrate, *study.outputs.held_out):
        sim, obs = simulated[name], observed[name]
        train[name] = fit_metrics(sim[first : layout.test_begin], obs[first : layout.test_begin])
        test[name] = fit_metrics(sim[layout.test_begin :], obs[layout.test_begin :])
    return SimulationCheck(parameters, dict(simulated), measured, train, test)


def write_simulation(check: SimulationCheck, folder: Path, title: str = "") -> dict[str, Path]:
    """Write the run as CSV and a measured-vs-simulated PNG into ``folder`` (atomically)."""
    from bayescal.report.plots import plot_measured_vs_simulated

    folder.mkdir(parents=True, exist_ok=True)
    m = check.measured
    frame = pd.DataFrame({"time_utc": pd.to_datetime(m.times)})
    for name, series in check.simulated.items():
        frame[f"{name}_simulated"] = series
    observed = {**m.outputs, **m.held_out}
    for name, series in observed.items():
        frame[f"{name}_measured"] = series
    csv = atomic_write_text(folder / "simulation.csv", frame.to_csv(index=False))
    png = plot_measured_vs_simulated(
        folder / "simulation.png",
        np.asarray(m.times),
        observed,
        {k: check.simulated[k] for k in observed},
        test_begin=m.layout.test_begin,
        warmup_end=int(m.layout.train_starts[0]) if m.layout.m_star else None,
        title=title,
    )
    return {"csv": csv, "png": png}
