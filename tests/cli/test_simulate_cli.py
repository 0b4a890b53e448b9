"""simulate / init / demo: the quick look at a study, through the API and the CLI."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bayescal import examples
from bayescal.cli import main
from bayescal.cli.progress import metrics_text
from bayescal.config import build_simulator, load_study, nominal_parameters
from bayescal.demo import TRUTH, run_demo
from bayescal.errors import ConfigError
from bayescal.metrics import Metrics, fit_metrics
from bayescal.simulate import check_simulation


def test_metrics_against_hand_computation() -> None:
    measured = np.array([10.0, 12.0, 14.0, 16.0])
    simulated = np.array([11.0, 11.0, 15.0, 18.0])
    m = fit_metrics(simulated, measured, p=1)
    e = simulated - measured  # 1, -1, 1, 2
    assert m.mse == pytest.approx(7 / 4)
    assert m.max_abs_error == 2.0
    assert m.mean_abs_error == pytest.approx(5 / 4)
    assert m.bias == pytest.approx(3 / 4)
    # Guideline 14 with p = 1: n - p = 3 degrees of freedom, mean measured 13.
    assert m.cv_rmse == pytest.approx(100 * np.sqrt(7 / 3) / 13)
    assert m.nmbe == pytest.approx(100 * -e.sum() / (3 * 13))


def test_factory_maps_study_parameters_onto_the_wall() -> None:
    study = load_study(examples.path("wall"))
    sim = build_simulator(study)
    assert set(sim.parameter_names) == set(study.parameters)
    assert nominal_parameters(study) == {"k_cb": 0.12, "cp_cb": 800.0, "cp_fb": 840.0}


def test_example_truth_fits_to_the_stated_noise() -> None:
    # The example's flux is EnergyPlus (CTF) at the truth plus noise of variance 0.007;
    # CTF and the built-in wall differ by ~0.01 W/m² RMSE, so at the truth the
    # training MSE must be the noise variance within its sampling error
    # (sd of a 1200-sample variance estimate: 0.007 * sqrt(2/1200) ~ 3e-4) plus ~1e-4.
    check = check_simulation(load_study(examples.path("wall")), TRUTH)
    assert check.train["heat_flux_in"].mse == pytest.approx(0.007, abs=1.2e-3)
    nominal = check_simulation(load_study(examples.path("wall")))
    assert nominal.train["heat_flux_in"].mse > 2 * check.train["heat_flux_in"].mse


def test_unknown_override_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="unknown parameter 'k_xx'"):
        check_simulation(load_study(examples.path("wall")), {"k_xx": 1.0})


def test_cli_init_and_simulate(tmp_path: Path) -> None:
    runner = CliRunner()
    target = tmp_path / "study"
    result = runner.invoke(main, ["init", "wall", str(target)])
    assert result.exit_code == 0, result.output
    assert (target / "study.toml").is_file()
    result = runner.invoke(main, ["simulate", str(target), "--set", "k_cb=0.124"])
    assert result.exit_code == 0, result.output
    assert "k_cb=0.124" in result.output
    png = target / "out" / "simulate" / "simulation.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a second init into the same folder refuses to overwrite
    again = runner.invoke(main, ["init", "wall", str(target)])
    assert again.exit_code == 2
    assert "exists and is not empty" in again.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["init", "nosuch", "x"], "no example 'nosuch'"),
        (["simulate", "STUDY", "--set", "k_cb"], "--set expects NAME=VALUE"),
        (["simulate", "STUDY", "--set", "zz=1"], "unknown parameter 'zz'"),
    ],
)
def test_cli_user_errors_are_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    runner = CliRunner()
    runner.invoke(main, ["init", "wall", str(tmp_path / "s")])
    args = [str(tmp_path / "s") if a == "STUDY" else a for a in args]
    result = runner.invoke(main, args)
    assert result.exit_code == 2
    assert message in result.output
    assert "Traceback" not in result.output


def test_demo_writes_figures(tmp_path: Path) -> None:
    figures = run_demo(tmp_path / "demo", calibrate=False, quiet=True)
    assert len(figures) == 2
    assert all(f.stat().st_size > 10_000 for f in figures)


def test_metrics_text_keeps_the_tutorials_layout() -> None:
    # The table of `bayescal simulate` as docs/tutorial.md shows it (columns from the one
    # list in bayescal.metrics).
    m = Metrics(1188, 0.02289, 0.1513, 0.1263, 0.4218, 0.115, 1.82, 1.38)
    text = metrics_text({"heat_flux_in": m}, {})
    assert text.splitlines() == [
        "output          window       n        MSE      RMSE   mean|e|    max|e|      bias"
        "  CV(RMSE)%   NMBE%",
        "heat_flux_in    train     1188    0.02289    0.1513    0.1263    0.4218     0.115"
        "       1.82    1.38",
    ]
