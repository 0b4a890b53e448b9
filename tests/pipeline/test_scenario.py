"""``bayescal predict --scenario``: scenarios against the baseline, draw by draw."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.errors import ConfigError
from bayescal.pipeline.scenario import run_scenarios
from scenario_wall import SCENARIO, calibrated_wall, eps_scenario, true_change

TRUTH = {"k_cb": 0.124, "cp_cb": 845.41}


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Any:
    return calibrated_wall(tmp_path_factory.mktemp("scenario") / "wall", 3, TRUTH)


def test_the_paired_change_covers_the_truths_and_is_narrower(calibrated: Any) -> None:
    result = eps_scenario(calibrated)
    table = result.table
    row = table[(table["summary"] == "mean") & (table["output"] == "heat_flux_in")].iloc[0]
    truth = true_change(calibrated, result, TRUTH)
    assert truth > 0.5  # W/m²: the insulation changes the inside flux visibly
    assert row["lower95"] <= truth <= row["upper95"], (row["lower95"], truth, row["upper95"])
    # the shared uncertainty cancels: the paired interval is narrower than the unpaired
    assert row["paired_over_unpaired"] < 0.9, row["paired_over_unpaired"]
    paired = result.draws[("eps", "heat_flux_in", "mean")]
    base = result.draws[("baseline", "heat_flux_in", "mean")]
    np.testing.assert_allclose(row["change"], np.mean(paired - base))
    assert result.n_draws == paired.size


def test_bad_scenario_files_are_one_line_errors(calibrated: Any, tmp_path: Path) -> None:
    cases = {
        "no such scenario file": None,
        "no scenario": "[baseline]\n",
        "unknown key": "[scenarios.a]\nsimulatr = { layers = [] }\n",
        "unknown key 'simulator.layerz'": "[scenarios.a]\nsimulator = { layerz = 3 }\n",
        "is not a target of the wall simulator": (
            '[scenarios.a]\nsimulator = { layers = [ { name = "x", thickness = 0.1, '
            "conductivity = 0.1, density = 10.0, specific_heat = 900.0 } ] }\n"
        ),
        "inside its prior": "[scenarios.a]\nset = { k_cb = 5.0 }\n",
        "not a calibrated parameter": "[scenarios.a]\nset = { k_xx = 0.1 }\n",
        "unknown table": "[scenario.a]\nset = { k_cb = 0.1 }\n",
    }
    for i, (message, text) in enumerate(cases.items()):
        path = tmp_path / f"s{i}.toml"
        if text is not None:
            path.write_text(text, encoding="utf-8")
        with pytest.raises(ConfigError, match=message):
            run_scenarios(calibrated, path)


def test_cli_scenario_prints_the_changes_and_writes_them(calibrated: Any, tmp_path: Path) -> None:
    path = tmp_path / "scenario.toml"
    path.write_text(SCENARIO, encoding="utf-8")
    study = str(calibrated.context.study.path)
    out = tmp_path / "out"
    res = CliRunner().invoke(
        main, ["predict", study, "--scenario", str(path), "--out", str(out), "-q"]
    )
    assert res.exit_code == 0, res.output
    assert "eps: mean heat_flux_in" in res.output
    assert (out / "scenarios.csv").is_file()
    assert (out / "scenario-draws.csv").is_file()
    neither = CliRunner().invoke(main, ["predict", study])
    assert neither.exit_code == 2
    assert "--data FILE, --scenario FILE or --as STUDY" in neither.output
