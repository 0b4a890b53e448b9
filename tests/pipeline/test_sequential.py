"""A posterior as the next prior: ``[study] prior_from`` and ``bayescal update``.

A virtual wall record of 14 days (the built-in wall at a known truth, white
noise; :mod:`sequential_study`): the study is calibrated on its first eight
days, then ``update`` adds the rest with the first posterior as prior.
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import tomli_w
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import load_study
from bayescal.design import PosteriorPrior
from bayescal.errors import BayescalError, ConfigError
from bayescal.pipeline import Options, load_results, run, sequential
from bayescal.pipeline import update as update_module
from bayescal.pipeline.sequential import prior_from_draws, warm_starts
from bayescal.pipeline.update import (
    HISTORY_FILE,
    reuse_runs,
    runs_line,
    update,
    update_files,
    write_history,
)
from sequential_study import END, write_study


def _moments(posterior: Any, k: int) -> tuple[float, float]:
    draws = posterior.draws.reshape(-1, len(posterior.names))[:, k]
    return float(draws.mean()), float(draws.std())


def _study(folder: Path, end: str | None = END, extra: str = "") -> Path:
    return write_study(folder, end, extra)


@pytest.fixture(scope="module")
def first(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = _study(tmp_path_factory.mktemp("sequential") / "wall")
    run(load_study(folder), until="calibrate", options=Options(backend="serial"))
    return folder


def test_update_adds_the_new_days_with_the_posterior_as_prior(
    first: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "wall"
    shutil.copytree(first, folder)
    study = load_study(folder)
    said: list[str] = []
    done = update(study, options=Options(backend="serial"), say=said.append)
    assert [p.name for p in update_files(study)] == ["update-001.toml"]
    assert any("prior of k_cb, cp_cb from the posterior" in line for line in said)
    assert any("the calibration chains start from its draws" in line for line in said)
    # the record is cut by data.start / data.end: the runs' boundary conditions are new
    assert (
        "runs: re-simulated: the boundary conditions now cover 6 more days and start 6 days "
        "later" in "\n".join(said)
    )
    new = load_results(done.study)
    assert new.posterior is not None
    assert all(isinstance(p, PosteriorPrior) for p in new.posterior.priors.values())
    history = pd.read_csv(folder / "out" / HISTORY_FILE)
    assert list(history["update"]) == [0, 1]
    assert pd.Timestamp(history["last_training"][1]) > pd.Timestamp(history["last_training"][0])
    width = history["k_cb_upper"] - history["k_cb_lower"]
    assert width[1] < width[0]  # more days and the previous posterior: narrower
    # the rows come from each step's posterior-summary.csv; written again, the earlier
    # step's row is taken from the file and only the newest step's is read
    summary = pd.read_csv(folder / "out" / "posterior-summary.csv", index_col=0)
    assert history["k_cb_mean"][0] == pytest.approx(summary.loc["k_cb", "mean"], rel=1e-12)
    assert "lambda_mean" not in history.columns  # parameters and derived quantities only
    read: list[str] = []
    real = update_module._history_row
    monkeypatch.setattr(
        update_module, "_history_row", lambda s, label, *a: read.append(label) or real(s, label, *a)
    )
    write_history(study, 1)
    assert read == ["1"]
    pd.testing.assert_frame_equal(pd.read_csv(folder / "out" / HISTORY_FILE), history)
    # Bayes' rule: the update is the first posterior times the new days' likelihood,
    # which the same study without prior_from (uniform priors) shows alone. For these
    # near-Gaussian posteriors the product's mean and SD are the precision-weighted
    # ones; the tolerance is a few Monte Carlo standard errors (ESS ~ 200 a chain set).
    raw = tomllib.loads((folder / "update-001.toml").read_text(encoding="utf-8"))
    del raw["study"]["prior_from"]
    raw["study"]["output_dir"] = "out/plain"
    (folder / "plain.toml").write_text(tomli_w.dumps(raw), encoding="utf-8")
    plain = load_study(folder / "plain.toml")
    run(plain, until="calibrate", options=Options(backend="serial"))
    before = load_results(study).posterior
    alone = load_results(plain).posterior
    after = new.posterior
    assert before is not None
    assert alone is not None
    for k, name in enumerate(after.names):
        m1, s1 = _moments(before, k)
        m2, s2 = _moments(alone, k)
        m, s = _moments(after, k)
        weight1, weight2 = s1**-2, s2**-2
        product_mean = (weight1 * m1 + weight2 * m2) / (weight1 + weight2)
        product_sd = (weight1 + weight2) ** -0.5
        assert abs(m - product_mean) < 0.35 * product_sd, (name, m, product_mean, product_sd)
        assert s == pytest.approx(product_sd, rel=0.2), name
    # the update's record starts one warm-up before the first study's test window
    assert load_study(folder / "update-001.toml").data.start == pd.Timestamp("2012-02-07")
    # nothing newer: the record after the last test window is too short for a period
    with pytest.raises(BayescalError):
        update(load_study(folder), options=Options(backend="serial"))


def test_warm_started_chains_sample_the_same_posterior_as_cold_ones(
    first: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A study with ``prior_from`` starts its chains at draws of the previous posterior
    (different draws, spread from its centre to its tails); the draws after burn-in
    are the same posterior as from the dispersed default starts: means within four
    combined Monte Carlo standard errors (ESS-based MCSE of each run), SDs within
    four combined MCSEs of the SD."""
    folder = tmp_path / "wall"
    shutil.copytree(first, folder)
    done = update(load_study(folder), options=Options(backend="serial"))
    starts = warm_starts(done.study, 4)
    assert starts is not None
    assert starts.shape == (4, 2)
    assert len({tuple(row) for row in starts}) == 4  # one draw per chain
    before = load_results(load_study(folder)).posterior
    assert before is not None
    unit = before.unit_draws.reshape(-1, 2)
    for row in starts:  # each start is one of the previous draws
        assert np.any(np.all(np.isclose(unit, row, rtol=0, atol=1e-12), axis=1))
    raw = tomllib.loads((folder / "update-001.toml").read_text(encoding="utf-8"))
    raw["study"]["output_dir"] = "out/cold"
    (folder / "cold.toml").write_text(tomli_w.dumps(raw), encoding="utf-8")
    shutil.copytree(folder / "out" / "update-001", folder / "out" / "cold")
    cold_study = load_study(folder / "cold.toml")
    monkeypatch.setattr(sequential, "warm_starts", lambda study, n: None)
    run(cold_study, from_stage="calibrate", until="calibrate", options=Options(backend="serial"))
    warm = load_results(done.study).posterior
    cold = load_results(cold_study).posterior
    assert warm is not None
    assert cold is not None
    assert not np.array_equal(warm.unit_draws, cold.unit_draws)
    a, b = warm.summary(), cold.summary()
    for name in warm.names:
        se_mean = float(np.hypot(a.loc[name, "mcse_mean"], b.loc[name, "mcse_mean"]))
        se_sd = float(np.hypot(a.loc[name, "mcse_sd"], b.loc[name, "mcse_sd"]))
        assert abs(a.loc[name, "mean"] - b.loc[name, "mean"]) < 4 * se_mean, name
        assert abs(a.loc[name, "sd"] - b.loc[name, "sd"]) < 4 * se_sd, name


def test_runs_with_the_same_boundary_conditions_are_linked(first: Path, tmp_path: Path) -> None:
    folder = tmp_path / "wall"
    shutil.copytree(first, folder)
    raw = tomllib.loads((folder / "study.toml").read_text(encoding="utf-8"))
    raw["study"]["output_dir"] = "again"
    (folder / "again.toml").write_text(tomli_w.dumps(raw), encoding="utf-8")
    study, again = load_study(folder), load_study(folder / "again.toml")
    line = runs_line(study, again)
    assert line == f"runs: reused 8 from {folder / 'out' / 'simulations'}"
    assert len(list((folder / "again" / "simulations" / "runs").glob("*.npz"))) == 8
    run(again, until="simulate", options=Options(backend="serial"))
    linked = sorted((folder / "again" / "simulations" / "runs").glob("*.npz"))
    assert len(linked) == 8  # the design's runs found in the cache, none made again
    assert all(f.stat().st_nlink == 2 for f in linked)
    assert reuse_runs(folder / "out" / "simulations", folder / "again" / "simulations") == 8


def test_prior_from_refuses_an_unfinished_or_unrelated_study(first: Path, tmp_path: Path) -> None:
    empty = _study(tmp_path / "empty")
    other = _study(tmp_path / "other", extra=f'prior_from = "{empty}"\n')
    with pytest.raises(ConfigError, match="holds no finished calibration"):
        prior_from_draws(load_study(other))
    text = (first / "study.toml").read_text(encoding="utf-8")
    unrelated = tmp_path / "unrelated"
    shutil.copytree(first, unrelated)
    renamed = text.replace("parameters.k_cb", "parameters.k_xx").replace(
        "parameters.cp_cb", "parameters.cp_xx"
    )
    (unrelated / "study.toml").write_text(renamed, encoding="utf-8")
    third = _study(tmp_path / "third", extra=f'prior_from = "{first}"\n')
    made = prior_from_draws(load_study(third))
    assert made is not None
    assert made.shared == ("k_cb", "cp_cb")
    assert "logit-normal fitted to" in made.describe()
    renamed_study = tmp_path / "fourth"
    _study(renamed_study, extra=f'prior_from = "{first}"\n')
    (renamed_study / "study.toml").write_text(
        (renamed_study / "study.toml").read_text(encoding="utf-8").replace("k_cb", "k_xx"),
        encoding="utf-8",
    )
    shared = prior_from_draws(load_study(renamed_study))
    assert shared is not None
    assert shared.shared == ("cp_cb",)


def test_cli_update_on_an_uncalibrated_study_is_one_line(tmp_path: Path) -> None:
    folder = _study(tmp_path / "raw")
    res = CliRunner().invoke(main, ["update", str(folder)])
    assert res.exit_code == 2
    assert res.output.count("\n") == 1
    assert "no finished calibration to update" in res.output
