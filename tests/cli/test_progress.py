"""Progress bars on the terminal (bayescal.cli.progress)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import sims_for_tests as sims
from bayescal.cli import main
from bayescal.cli import progress as progress_module
from bayescal.cli.progress import mcmc_bar, progress_options, simulation_bar
from bayescal.design import UniformPrior, latin_hypercube
from bayescal.pipeline import Results
from bayescal.runner import run_design
from bayescal.simulators.base import Forcing

N = 48
FORCING = Forcing(3600.0, {"temp_air_out": 10.0 + 5.0 * np.sin(np.arange(N) / 3.0)})
# 10 runs of a Latin hypercube: exactly one has a in [0.9, 1), which Failing breaks.
DESIGN = latin_hypercube({"a": UniformPrior(0.0, 1.0), "b": UniformPrior(-1.0, 1.0)}, 10, seed=1)


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


class Clock:
    """A clock that advances ``step`` seconds each time it is read."""

    def __init__(self, step: float) -> None:
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def test_simulation_bar_counts_runs_and_failures(tmp_path: Path) -> None:
    stream = Terminal()
    progress, close = simulation_bar(10, desc="runs", stream=stream)
    results = run_design(
        sims.Failing(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial", progress=progress
    )
    close()
    err = stream.getvalue()
    assert results.n_failed == 1
    assert "runs: 100%" in err
    assert "failed=1" in err
    assert "\r" in err  # a bar on a terminal


def test_without_a_terminal_simulations_are_plain_lines(tmp_path: Path) -> None:
    stream = io.StringIO()
    progress, close = simulation_bar(10, desc="runs", stream=stream)
    results = run_design(
        sims.Failing(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial", progress=progress
    )
    close()
    text = stream.getvalue()
    assert results.n_failed == 1
    assert "\r" not in text
    lines = text.splitlines()
    assert lines[0] == "runs: started, 10 runs"
    assert lines[-1].startswith("runs: finished 10/10 runs in ")
    assert lines[-1].endswith(", 1 failed")
    assert len(lines) == 2  # the runs took far less than 10 s: no line between


@pytest.mark.parametrize(("ticks", "step", "most"), [(100_000, 0.01, 40), (200_000, 0.18, 100)])
def test_without_a_terminal_mcmc_progress_is_bounded(ticks: int, step: float, most: int) -> None:
    # ticks over 1000 s or 10 h of a fake clock: a line every 10 s at most (every tenth
    # of the time elapsed after 100 s), not one per tick.
    stream = io.StringIO()
    factory = mcmc_bar(quiet=False, stream=stream)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(progress_module, "monotonic", Clock(step))
        tick, close = factory("calibrate", ticks)
        for done in range(1, ticks + 1):
            tick(done)
        close()
    text = stream.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert 12 <= len(lines) <= most
    assert lines[0] == f"calibrate: started, {ticks} it"
    assert lines[-1].startswith(f"calibrate: finished {ticks}/{ticks} it in ")
    assert lines[1].startswith("calibrate: ")
    assert ", 10 s, about " in lines[1]  # the first line after 10 s, with the time left
    assert lines[-2].endswith(" left")


def test_without_a_terminal_a_growing_phase_grows_its_total() -> None:
    stream = io.StringIO()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(progress_module, "monotonic", Clock(20.0))
        tick, close = mcmc_bar(quiet=False, stream=stream)("discrepancy", 10)
        tick(15)
        close()
    lines = stream.getvalue().splitlines()
    assert lines[1].startswith("discrepancy: 15/15 it (100 %)")
    assert lines[-1].startswith("discrepancy: finished 15/15 it")


def test_quiet_writes_nothing() -> None:
    stream = io.StringIO()
    options = progress_options(quiet=True, stream=stream)
    assert options["progress"] is None
    tick, close = options["mcmc_progress"]("calibrate", 100)
    tick(50)
    close()
    assert stream.getvalue() == ""


def test_a_terminal_gets_a_bar() -> None:
    stream = Terminal()
    tick, close = mcmc_bar(quiet=False, stream=stream)("emulator", 100)
    tick(100)
    close()
    assert "\r" in stream.getvalue()
    assert "emulator: 100%" in stream.getvalue()


def test_comparison_table_keeps_long_variant_names_apart() -> None:
    import pandas as pd

    from bayescal.cli.progress import comparison_text

    names = ["box-coheating-white", "box-coheating-white-delta"]
    table = pd.DataFrame(
        {
            "rank": [1, 2],
            "variant": names,
            "elpd": [-10.0, -20.0],
            "se": [1.0, 1.0],
            "elpd_diff": [0.0, 10.0],
            "se_diff": [0.0, 2.0],
            "p_loo": [3.0, 4.0],
            "k_high": [0, 0],
            "refits": [0, 0],
            "periods": [11, 11],
        }
    )
    rows = comparison_text(table, [], {}).splitlines()[2:4]
    assert rows[0].split()[1] == names[0]
    assert rows[1].split()[1] == names[1]


def _made_up_results(tmp_path: Path, piled: bool, calibrated_test_rmse: float) -> Results:
    """Results of the wall example with a made-up posterior and metrics table: no MCMC."""
    import pandas as pd
    import xarray as xr

    from bayescal.calibration.posterior import Posterior
    from bayescal.config import load_study
    from bayescal.examples import copy_example
    from bayescal.pipeline.stages import Predictions, prepare

    ctx = prepare(load_study(copy_example("wall", tmp_path / "wall")))
    rng = np.random.default_rng(0)
    priors = {"k": UniformPrior(0.1, 0.3, unit="W/(m·K)"), "c": UniformPrior(1.0, 2.0)}
    unit = rng.random((4, 200, 2))
    if piled:
        unit[..., 0] = 1.0 - np.abs(rng.normal(0.0, 0.03, (4, 200)))
    lam = rng.gamma(5.0, 1.0, (4, 200, 2))
    post = Posterior.build(
        ["k", "c"], priors, unit, lam=lam[..., 0], lam_star=lam[..., 1],
        acceptance=np.full((4, 4), 0.3),
    )  # fmt: skip
    rows = [
        (o, model, window, rmse)
        for o, test_rmse in (("flux", calibrated_test_rmse), ("sensor", 0.9))
        for model, window, rmse in (
            ("nominal", "train", 2.0), ("calibrated", "train", 0.5),
            ("nominal", "test", 1.0), ("calibrated", "test", test_rmse),
        )
    ]  # fmt: skip
    metrics = pd.DataFrame(rows, columns=["output", "model", "window", "rmse"])
    metrics["n"], metrics["mse"] = 48, metrics["rmse"] ** 2
    ds = xr.Dataset(attrs={"held_out": "sensor", "outputs": "flux,sensor"})
    return Results(ctx, posterior=post, predictions=Predictions(ds, metrics))


def test_describe_says_first_when_the_calibration_did_not_help(tmp_path: Path) -> None:
    from bayescal.cli.progress import describe

    text = describe(_made_up_results(tmp_path, piled=True, calibrated_test_rmse=1.2))
    lines = text.splitlines()
    posterior = lines.index("posterior (physical units):")
    loud = [k for k, line in enumerate(lines) if line.startswith("WARNING: ")]
    assert len(loud) == 2
    assert max(loud) < posterior
    assert lines[loud[0]].startswith("WARNING: calibration: k leans on the upper bound")
    assert "treat it as a fitting constant" in lines[loud[0]]
    assert lines[loud[1]].startswith("WARNING: flux: the calibrated prediction is worse")
    assert lines[loud[1]].endswith("treat them as fitting constants, not properties")
    # one line per output, calibrated and held out, before the posterior table
    head = "out of sample, calibrated against nominal (catalogue) parameters:"
    at = lines.index(head)
    assert lines[at + 1].startswith("  flux (test window): worse: calibrated RMSE 1.2")
    # the held-out sensor: pooled over its whole record, 0.5 and 0.9 against 2 and 1
    assert lines[at + 2].startswith("  sensor (held-out sensor, whole record): better")
    assert at < posterior
    assert "2 warning(s) at the top of this summary" in text

    calm = describe(_made_up_results(tmp_path / "calm", piled=False, calibrated_test_rmse=0.98))
    assert "WARNING" not in calm
    assert "warning(s) at the top" not in calm
    assert "  flux (test window): no better: calibrated RMSE 0.98" in calm


def test_comparison_table_marks_a_variant_whose_calibration_failed() -> None:
    import pandas as pd

    from bayescal.cli.progress import comparison_text

    table = pd.DataFrame(
        {
            "rank": [1, 2], "variant": ["ar1", "white"], "elpd": [-10.0, -30.0],
            "se": [1.0, 1.0], "elpd_diff": [0.0, 20.0], "se_diff": [0.0, 2.0],
            "p_loo": [3.0, 4.0], "k_high": [0, 0], "refits": [0, 0], "periods": [6, 6],
            "diagnostics": ["failed", "passed"],
        }
    )  # fmt: skip
    lines = comparison_text(table, ["ar1: its calibration FAILED ..."], {}).splitlines()
    assert lines[1].endswith("  MCMC")
    assert lines[2].endswith("  FAILED !")
    assert lines[3].endswith("  ok")
    assert (
        "ar1: best; its calibration FAILED its MCMC diagnostics: the rank is not reliable"
        in (lines)[5]
    )
    assert lines[6].startswith("white: worse by 20.0")
    assert "note: ar1: its calibration FAILED ..." in lines


#: Short chains for the wall example: the log's shape, not the calibration, is tested.
SHORT = """
[emulator]
pca_variance = 0.999
burn = 100
samples = 100

[calibration]
chains = 4
burn = 200
samples = 200
max_samples = 200
"""


def test_a_redirected_run_writes_no_carriage_returns(tmp_path: Path) -> None:
    runner = CliRunner()  # its standard error is no terminal, like `bayescal run S > log 2>&1`
    folder = tmp_path / "wall"
    assert runner.invoke(main, ["init", "wall", str(folder)]).exit_code == 0
    text = (folder / "study.toml").read_text(encoding="utf-8")
    (folder / "study.toml").write_text(text[: text.index("[emulator]")] + SHORT, "utf-8")
    result = runner.invoke(
        main, ["run", str(folder), "--until", "calibrate", "--backend", "serial"]
    )
    assert result.exit_code == 0, result.output
    log = result.stdout + result.stderr
    assert "\r" not in log
    for stage in ("simulations", "emulator", "calibration"):
        assert f"{stage}: started, " in result.stderr
        assert f"{stage}: finished " in result.stderr
    assert len(result.stderr.splitlines()) < 3 * 100
