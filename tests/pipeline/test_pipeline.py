"""The end-to-end pipeline on the wall example: stages, caching, forcing, CLI."""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import load_study
from bayescal.demo import TRUTH
from bayescal.errors import ConfigError
from bayescal.pipeline import Options, Results, load_results, run
from bayescal.store.stages import STAGES

SERIAL = Options(backend="serial", chains_backend="serial")
#: Short chains: enough for the sharply identified parameters of the example.
FAST = """
[emulator]
pca_variance = 0.999
burn = 200
samples = 200

[calibration]
chains = 4
burn = 400
samples = 600
max_samples = 600

[predict]
method = "{method}"
runs = 20
draws = 100
"""


def _study(tmp_path: Path, method: str = "simulator") -> Path:
    runner = CliRunner()
    target = tmp_path / "wall"
    result = runner.invoke(main, ["init", "wall", str(target)])
    assert result.exit_code == 0, result.output
    text = (target / "study.toml").read_text(encoding="utf-8")
    cut = text.index("[emulator]")
    (target / "study.toml").write_text(text[:cut] + FAST.format(method=method), "utf-8")
    return target


@pytest.fixture(scope="module")
def first(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Results]:
    folder = _study(tmp_path_factory.mktemp("pipeline"))
    return folder, run(load_study(folder), until="predict", options=SERIAL)


def test_every_stage_runs_and_writes_its_files(first: tuple[Path, Results]) -> None:
    folder, res = first
    assert res.ran == STAGES[: STAGES.index("predict") + 1]
    out = folder / "out"
    for name in ("design.csv", "simulations.npz", "emulator.nc", "posterior.nc"):
        assert (out / name).is_file(), name
    record = json.loads((out / "stages.json").read_text())
    assert set(record) == set(res.ran)
    assert "calibrate: done" in (out / "bayescal.log").read_text()


def test_the_truth_is_covered_and_the_fit_reaches_the_noise(first: tuple[Path, Results]) -> None:
    _, res = first
    assert res.posterior is not None
    assert res.predictions is not None
    lower, upper = res.posterior.interval(0.95)
    # The example is a virtual experiment with known truth (examples/wall/data/README.md).
    for k, name in enumerate(res.posterior.names):
        if name in ("k_cb", "cp_cb"):
            assert lower[k] <= TRUTH[name] <= upper[k], name
    m = res.predictions.metrics.set_index(["model", "window"])
    # The measured flux carries noise of variance 0.007 (W/m²)²; the calibrated
    # simulator must reach it on both windows within its sampling error plus the
    # ~1e-4 CTF-versus-finite-volume difference (same bound as test_simulate_cli).
    for window in ("train", "test"):
        assert m.loc[("calibrated", window), "mse"] == pytest.approx(0.007, abs=2e-3)
        assert m.loc[("calibrated", window), "mse"] < m.loc[("nominal", window), "mse"]
        assert m.loc[("calibrated", window), "coverage95"] >= 0.9


def test_predictions_dataset_follows_the_layout(first: tuple[Path, Results]) -> None:
    _, res = first
    assert res.predictions is not None
    ds = res.predictions.dataset
    windows = ds["window"].values
    cal = ds["heat_flux_in_calibrated"].values
    assert np.all(np.isnan(cal[windows == "warmup"]))
    assert np.all(np.isfinite(cal[(windows == "train") | (windows == "test")]))
    lo, hi = ds["heat_flux_in_calibrated_lower"].values, ds["heat_flux_in_calibrated_upper"].values
    ok = np.isfinite(cal)
    assert np.all(lo[ok] <= cal[ok])
    assert np.all(cal[ok] <= hi[ok])


def test_failing_chains_are_extended_and_a_short_stop_is_loud(tmp_path: Path) -> None:
    folder = _study(tmp_path, method="emulator")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    fixed = "burn = 400\nsamples = 600\nmax_samples = 600\n"
    assert fixed in text
    path.write_text(text.replace(fixed, "burn = 100\nsamples = 40\nmax_samples = 30\n"), "utf-8")
    with pytest.raises(ConfigError, match=r"max_samples \(30\) is below samples \(40\)"):
        load_study(folder)
    path.write_text(path.read_text("utf-8").replace("max_samples = 30", "max_samples = 60"))
    said: list[str] = []
    res = run(load_study(folder), until="calibrate", options=SERIAL, say=said.append)
    assert res.posterior is not None
    # 4 x 40 draws cannot pass (bulk ESS >= 400): extended by half, to the most, 60.
    assert res.posterior.draws.shape[1] == 60
    assert "calibration: chains extended from 40 to 60 kept draws (still failing)" in said
    loud = [line for line in said if line.startswith("WARNING: the calibration did NOT")]
    assert len(loud) == 1
    assert "max_samples = 60 kept draws per chain" in loud[0]
    assert loud[0].endswith("raise max_samples or burn, or try moves = 'joint'")


def test_second_run_reuses_everything(first: tuple[Path, Results]) -> None:
    folder, res = first
    again = run(load_study(folder), until="predict", options=SERIAL)
    assert again.ran == ()
    assert again.reused == res.ran
    assert again.posterior is not None
    assert res.posterior is not None
    np.testing.assert_array_equal(again.posterior.draws, res.posterior.draws)


def test_a_changed_setting_reruns_only_later_stages(tmp_path: Path) -> None:
    folder = _study(tmp_path, method="emulator")
    run(load_study(folder), until="calibrate", options=SERIAL)
    runs_before = sorted((folder / "out" / "simulations" / "runs").iterdir())
    path = folder / "study.toml"
    path.write_text(path.read_text().replace("samples = 600", "samples = 500"), "utf-8")
    res = run(load_study(folder), until="predict", options=SERIAL)
    assert res.reused == ("design", "simulate", "emulator")
    assert res.ran == ("calibrate", "discrepancy", "predict")
    assert res.posterior is not None
    assert res.posterior.draws.shape[1] == 500  # max_samples went down with samples
    # Emulator predictions: no posterior runs were added to the run cache.
    runs_after = sorted((folder / "out" / "simulations" / "runs").iterdir())
    assert set(runs_before) < set(runs_after)
    assert len(runs_after) == len(runs_before) + 1  # the nominal run only
    forced = run(load_study(folder), from_stage="emulator", until="emulator", options=SERIAL)
    assert forced.ran == ("emulator",)
    assert forced.reused == ("design", "simulate")


def test_unknown_stage_is_a_config_error(first: tuple[Path, Results]) -> None:
    folder, _ = first
    with pytest.raises(ConfigError, match="from_stage must be one of design, simulate"):
        run(load_study(folder), from_stage="bogus")


def test_cli_show_and_errors(first: tuple[Path, Results], tmp_path: Path) -> None:
    folder, _ = first
    runner = CliRunner()
    shown = runner.invoke(main, ["show", str(folder)])
    assert shown.exit_code == 0, shown.output
    assert re.search(r"k_cb\s+0\.12", shown.output)
    assert "max_abs_error is the paper's 'MAE'" in shown.output
    assert "The test window is read only for these final metrics" in shown.output
    # identifiability: principal directions, contraction and the correlation matrix
    assert "what the data fix" in shown.output
    assert "prior-to-posterior contraction" in shown.output
    assert re.search(r"posterior correlation.*\n\s+k_cb\s+cp_cb", shown.output)
    assert re.search(r"k_cb\s+\+1\.00", shown.output)
    empty = _study(tmp_path)
    result = runner.invoke(main, ["show", str(empty)])
    assert result.exit_code == 2
    assert result.output.count("\n") == 1
    assert "has no finished calibration" in result.output
    bad = runner.invoke(main, ["run", str(folder), "--from", "nowhere"])
    assert bad.exit_code == 2
    assert "Traceback" not in bad.output


def test_load_results_matches_the_run(first: tuple[Path, Results]) -> None:
    folder, res = first
    loaded = load_results(load_study(folder))
    assert loaded.posterior is not None
    assert res.posterior is not None
    np.testing.assert_array_equal(loaded.posterior.draws, res.posterior.draws)
    assert loaded.predictions is not None
    assert res.predictions is not None
    np.testing.assert_allclose(
        loaded.predictions.metrics["mse"].to_numpy(), res.predictions.metrics["mse"].to_numpy()
    )


@pytest.mark.slow
def test_discrepancy_and_report_through_the_pipeline(tmp_path: Path) -> None:
    folder = _study(tmp_path)
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    path.write_text(
        text + "\n[discrepancy]\nenabled = true\nrealisations = 20\nupdate_interval = 50\n"
        "burn = 300\nsamples = 500\nmax_samples = 500\n",
        "utf-8",
    )
    res = run(load_study(folder), options=SERIAL)
    assert res.discrepancy is not None
    # The discrepancy phase's own chain lengths, not [calibration]'s 400 + 600 (not
    # extended: max_samples = samples).
    assert res.discrepancy.posterior.draws.shape[:2] == (4, 500)
    assert res.discrepancy.converged is not None
    assert res.predictions is not None
    ds = res.predictions.dataset
    for name in ("delta", "corrected", "corrected_lower", "corrected_upper"):
        assert f"heat_flux_in_{name}" in ds
    corrected = ds["heat_flux_in_corrected"].values
    # Corrected = the simulator at draws of the Delta phase + Delta: finite where predicted.
    windows = ds["window"].values
    assert np.all(np.isfinite(corrected[(windows == "train") | (windows == "test")]))
    models = set(res.predictions.metrics["model"])
    assert models == {"nominal", "calibrated", "calibrated+delta"}
    assert res.report is not None
    html = res.report.read_text(encoding="utf-8")
    assert "Discrepancy" in html
    # The settings table names the samplers and each phase's own chain lengths.
    assert "Metropolis-within-Gibbs, 4 chains x (400 + 600)" in html
    assert "Metropolis-within-Gibbs with Delta updates, 4 chains x (300 + 500)" in html
    assert (folder / "out" / "discrepancy.nc").is_file()


def test_a_study_stopped_after_the_emulator_loads_and_shows(
    first: tuple[Path, Results], tmp_path: Path
) -> None:
    folder, res = first
    copy = tmp_path / "wall"
    shutil.copytree(folder, copy)
    notes: list[str] = []
    # Forcing calibrate and stopping before it leaves a study stopped after the emulator.
    stopped = run(
        load_study(copy), from_stage="calibrate", until="emulator", options=SERIAL, say=notes.append
    )
    assert stopped.ran == ()
    assert stopped.reused == ("design", "simulate", "emulator")
    # A reused stage says how long it took when it ran (from stages.json).
    record = json.loads((copy / "out" / "stages.json").read_text())
    assert set(record) == {"design", "simulate", "emulator"}
    for stage in stopped.reused:
        when = dt.datetime.strptime(record[stage]["finished"], "%Y-%m-%dT%H:%M:%S%z")
        expected = (
            f"{stage}: up to date, reused (ran {record[stage]['seconds']:.1f} s on "
            f"{when:%Y-%m-%d %H:%M})"
        )
        assert expected in notes
    loaded = load_results(load_study(copy))
    assert loaded.emulator is not None
    assert res.emulator is not None
    assert loaded.emulator.loo.rmse == res.emulator.loo.rmse
    assert (loaded.posterior, loaded.predictions, loaded.report) == (None, None, None)
    assert loaded.missing() == ("calibrate", "predict", "report")
    runner = CliRunner()
    shown = runner.invoke(main, ["show", str(copy)])
    assert shown.exit_code == 0, shown.output
    assert "emulator leave-one-run-out RMSE" in shown.output
    missing = [line for line in shown.output.splitlines() if "not run yet" in line]
    assert len(missing) == 1
    assert missing[0].startswith("not run yet: calibrate, predict, report")
    report = runner.invoke(main, ["report", str(copy)])
    assert report.exit_code == 2
    assert report.output.count("\n") == 1
    assert "the report needs the emulator, calibrate and predict stages" in report.output
    assert "not run yet: calibrate, predict" in report.output


def test_strict_exits_non_zero_on_failed_diagnostics(
    first: tuple[Path, Results], monkeypatch: pytest.MonkeyPatch
) -> None:
    folder, res = first
    runner = CliRunner()
    # The fixture's own chains: the exit status follows its diagnostics.
    ok = runner.invoke(main, ["run", str(folder), "--until", "predict", "--strict", "-q"])
    assert ok.exit_code == (3 if res.diagnostic_warnings() else 0), ok.output
    # A failed diagnostic: status 3, one line naming it, the results kept.
    failed = ("calibration: k_cb: R-hat 1.05 > 1.01", "calibration: k_cb: bulk ESS 80 < 400")
    monkeypatch.setattr(Results, "diagnostic_warnings", lambda self: failed)
    bad = runner.invoke(main, ["run", str(folder), "--until", "predict", "--strict", "-q"])
    assert bad.exit_code == 3
    assert bad.output.count("\n") == 1
    assert "R-hat 1.05" in bad.output
    assert "and 1 more" in bad.output
    assert "Traceback" not in bad.output
    assert (folder / "out" / "posterior.nc").is_file()
    lenient = runner.invoke(main, ["run", str(folder), "--until", "predict", "-q"])
    assert lenient.exit_code == 0


def test_diagnostic_warnings_name_their_phase(first: tuple[Path, Results]) -> None:
    _, res = first
    assert res.posterior is not None
    diag = dataclasses.replace(res.posterior.diagnostics, warnings=("k_cb: R-hat 1.2 > 1.01",))
    post = dataclasses.replace(res.posterior, diagnostics=diag)
    found = dataclasses.replace(res, posterior=post).diagnostic_warnings()
    assert found[0] == "calibration: k_cb: R-hat 1.2 > 1.01"
