"""A calibrated virtual wall and an insulation scenario whose true change is known.

The tiny study of :mod:`compare_study` (white errors) is calibrated on data the
built-in wall makes at a known truth; the scenario adds 60 mm of EPS outside.
The true change of the mean inside heat flux is the truth's wall with and
without the layer on the same surface temperatures.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from bayescal.config import build_simulator, load_study
from bayescal.pipeline import Options, load_results, run
from bayescal.pipeline.scenario import ScenarioResult, run_scenarios
from compare_study import STUDY
from virtual_wall import PER_DAY, virtual_experiment

LAYER = (
    '{ name = "eps", thickness = 0.06, conductivity = 0.035, density = 20.0, '
    "specific_heat = 1450.0 }"
)
WALL = (
    '{ name = "board_out", thickness = 0.027, conductivity = 0.0316, density = 116.6, '
    'specific_heat = 840.0 }, { name = "concrete", thickness = 0.15, conductivity = 0.12, '
    'density = 552.0, specific_heat = 800.0 }, { name = "board_in", thickness = 0.027, '
    "conductivity = 0.0316, density = 116.6, specific_heat = 840.0 }"
)
SCENARIO = f"""
[baseline]
description = "as calibrated"

[scenarios.eps]
description = "60 mm of EPS outside"
simulator = {{ layers = [ {LAYER}, {WALL} ] }}
"""


def wall_record(seed: int, truth: dict[str, float], days: int = 6) -> pd.DataFrame:
    """Half-hourly surface temperatures and the inside flux with white noise at ``truth``."""
    ve = virtual_experiment(
        seed=seed, truth=truth | {"cp_fb": 840.0}, runs=5, periods=days, warmup_days=1,
        test_days=1,
    )  # fmt: skip
    n = ve.layout.n_total
    times = pd.date_range("2012-02-01", periods=n, freq="30min")
    assert n == PER_DAY * (days + 2)
    return pd.DataFrame(
        {
            "time": times.strftime("%Y-%m-%dT%H:%M:%S"),
            "T_se": np.round(ve.boundary["temp_surf_out"], 6),
            "T_si": np.round(ve.boundary["temp_surf_in"], 6),
            "q_si": np.round(ve.measured["heat_flux_in"], 6),
        }
    )


def calibrated_wall(folder: Path, seed: int, truth: dict[str, float]) -> Any:
    """The tiny study calibrated on the record at ``truth`` (results read back)."""
    folder.mkdir(parents=True, exist_ok=True)
    wall_record(seed, truth).to_csv(folder / "wall.csv", index=False)
    text = STUDY.format(name=folder.name, model="white") + "\n[predict]\nruns = 40\n"
    (folder / "study.toml").write_text(text, encoding="utf-8")
    study = load_study(folder)
    run(study, until="calibrate", options=Options(backend="serial"))
    return load_results(study)


def true_change(results: Any, scenario: ScenarioResult, truth: dict[str, float]) -> float:
    """The truth's change of the mean inside heat flux over the scenarios' window."""
    from bayescal.pipeline.scenario import load_scenarios, study_of

    ctx = results.context
    record = scenario.record
    window = slice(record.layout.test_begin, record.layout.n_total)
    path = ctx.study.root / "scenario.toml"
    _, (eps,) = load_scenarios(path)
    base = build_simulator(ctx.study).simulate(truth, record.forcing)["heat_flux_in"]
    after = build_simulator(study_of(ctx.study, eps, str(path))).simulate(truth, record.forcing)
    return float(np.mean(after["heat_flux_in"][window]) - np.mean(base[window]))


def eps_scenario(results: Any) -> ScenarioResult:
    """The EPS scenario on the study's own record."""
    path = results.context.study.root / "scenario.toml"
    path.write_text(SCENARIO, encoding="utf-8")
    return run_scenarios(results, path)
