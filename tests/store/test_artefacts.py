"""Emulator and posterior artefacts: netCDF round trips and atomic writes."""

from __future__ import annotations

import dataclasses
import json
import os
import stat
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr

from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.calibration.target import build_target
from bayescal.emulator.assemble import Assembled, assemble
from bayescal.emulator.gp import Emulator
from bayescal.emulator.training import train
from bayescal.errors import DataError
from bayescal.store.emulator import (
    CalibrationInputs,
    load_calibration_inputs,
    load_emulator,
    save_emulator,
)
from bayescal.store.posterior import load_posterior, save_posterior, save_posterior_summary
from virtual_wall import virtual_experiment


@pytest.fixture(scope="module")
def fitted() -> tuple[Assembled, Emulator, Posterior]:
    ve = virtual_experiment(seed=6, runs=10, periods=6, warmup_days=2, test_days=1)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2)
    em = train(a, n_burn=60, n_draws=20, n_chains=2, seed=4)
    post = calibrate(em, a, n_chains=4, n_burn=20, n_draws=20, seed=5, backend="serial")
    return a, em, post


def test_emulator_round_trip_predicts_identically(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    a, em, _ = fitted
    path = save_emulator(em, tmp_path / "out" / "emulator.nc", config_hash="abc123")
    back = load_emulator(path)
    rng = np.random.default_rng(0)
    theta = em.theta_normaliser.invert(rng.random((5, 3)))
    x = np.vstack([a.x[:4], a.x_test[:1]])
    for before, after in zip(em.predict(theta, x), back.predict(theta, x), strict=True):
        np.testing.assert_array_equal(before, after)  # float64 stored: bit for bit
    np.testing.assert_array_equal(em.hyper_draws, back.hyper_draws)
    assert back.hyper_names == em.hyper_names
    assert back.outputs.names == em.outputs.names
    assert (back.seed, back.lam_prior, back.log_post_map) == (
        em.seed,
        em.lam_prior,
        em.log_post_map,
    )
    # The input PCA comes back too: the test window transforms the same way.
    bc = virtual_experiment(seed=6, runs=10, periods=6, warmup_days=2, test_days=1).boundary
    test = {n: a.layout.cut(v, "test").T for n, v in bc.items()}
    np.testing.assert_array_equal(back.inputs.transform(test), em.inputs.transform(test))
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["config_hash"] == "abc123"
        assert ds.attrs["seed"] == 4
    assert [p.name for p in path.parent.iterdir()] == ["emulator.nc"]  # no temp file left


def test_netcdf_artefacts_are_readable_by_others(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    # They used to be written 0600 (mkstemp's mode) while every other file got 0644.
    _, em, post = fitted
    old = os.umask(0o022)
    try:
        paths = [save_emulator(em, tmp_path / "e.nc"), save_posterior(post, tmp_path / "p.nc")]
    finally:
        os.umask(old)
    assert [stat.S_IMODE(p.stat().st_mode) for p in paths] == [0o644, 0o644]


def test_posterior_round_trip(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    _, _, post = fitted
    path = save_posterior(post, tmp_path / "posterior.nc", config_hash="h")
    back = load_posterior(path)
    np.testing.assert_array_equal(back.unit_draws, post.unit_draws)
    np.testing.assert_array_equal(back.draws, post.draws)
    np.testing.assert_array_equal(back.lam_star, post.lam_star)
    np.testing.assert_array_equal(back.diagnostics.rhat, post.diagnostics.rhat)
    assert back.priors == post.priors
    assert back.warnings == post.warnings
    assert (back.seed, back.algebra, back.names) == (post.seed, post.algebra, post.names)


def test_wrong_artefact_kind_is_refused(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    _, em, _ = fitted
    path = save_emulator(em, tmp_path / "emulator.nc")
    with pytest.raises(DataError):
        load_posterior(path)
    with pytest.raises(DataError, match="does not exist"):
        load_emulator(tmp_path / "missing.nc")


def test_failed_write_keeps_the_old_file(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _, em, _ = fitted
    path = save_emulator(em, tmp_path / "emulator.nc", config_hash="first")
    before = path.read_bytes()

    def broken(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", broken)
    with pytest.raises(OSError, match="disk full"):
        save_emulator(em, path, config_hash="second")
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["emulator.nc"]


def _with_units(post: Posterior) -> Posterior:
    """The posterior with units and descriptions on two of its priors (cp_fb has none)."""
    given = {"k_cb": ("W/(m·K)", "conductivity of the blocks"), "cp_cb": ("J/(kg·K)", "")}
    priors = {
        name: dataclasses.replace(prior, unit=unit, description=text)
        for name, prior in post.priors.items()
        for unit, text in [given.get(name, ("", ""))]
    }
    return dataclasses.replace(post, priors=priors)


def test_posterior_root_group_is_a_flat_dataset_with_units(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    post = _with_units(fitted[2])
    path = save_posterior(post, tmp_path / "posterior.nc")
    # What a user does first: open the file with xarray and see the draws.
    with xr.open_dataset(path) as ds:
        assert list(ds.data_vars) == [*post.names, "lambda", "lambda_star", "lp"]
        for k, name in enumerate(post.names):
            assert ds[name].dims == ("chain", "draw")
            np.testing.assert_array_equal(ds[name].values, post.draws[..., k])
            assert ds[name].attrs.get("units", "") == post.priors[name].unit
        np.testing.assert_array_equal(ds["lambda_star"].values, post.lam_star)
        np.testing.assert_array_equal(ds["lp"].values, post.log_density)
        assert ds["k_cb"].attrs["units"] == "W/(m·K)"
        assert ds["k_cb"].attrs["description"] == "conductivity of the blocks"
        assert ds["lambda"].attrs["units"] == "1"
        assert "precision" in ds["lambda_star"].attrs["description"]
    # ... and ArviZ reads the same file as InferenceData.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # ArviZ's notice about its 1.0
        import arviz

    idata = arviz.from_netcdf(path)
    assert {"posterior", "sample_stats", "bayescal"} <= set(idata.groups())
    np.testing.assert_array_equal(idata["posterior"]["k_cb"].values, post.draws[..., 0])
    assert idata["posterior"]["k_cb"].attrs["units"] == "W/(m·K)"
    # The units travel through the priors back into the loaded posterior.
    back = load_posterior(path)
    assert back.priors == post.priors
    np.testing.assert_array_equal(back.draws, post.draws)


def test_posterior_summary_csv_has_units_and_descriptions(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    post = _with_units(fitted[2])
    path = save_posterior_summary(post, tmp_path / "posterior-summary.csv")
    table = pd.read_csv(path, index_col="parameter", keep_default_na=False)
    assert list(table.index) == list(post.all_names)
    assert table.loc["k_cb", "unit"] == "W/(m·K)"
    assert table.loc["k_cb", "description"] == "conductivity of the blocks"
    assert table.loc["cp_cb", "unit"] == "J/(kg·K)"
    assert table.loc["lambda", "unit"] == "1"
    np.testing.assert_allclose(table["mean"].to_numpy(float), post.summary()["mean"], rtol=1e-15)


def test_emulator_variables_carry_descriptions(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    em = fitted[1]
    path = save_emulator(em, tmp_path / "emulator.nc", parameter_units=["W/(m·K)"] * 3)
    with xr.open_dataset(path) as ds:
        for name in ("k", "theta", "std_mean", "hyper_draws", "bc0_mean"):
            assert ds[name].attrs["description"], name
        assert ds["theta"].attrs["units"] == "1"
        assert ds["std_mean"].attrs["units"] == "W/m²"  # the one output: heat_flux_in
        assert json.loads(ds.attrs["parameter_units"]) == ["W/(m·K)"] * 3


def test_calibration_rebuilds_from_the_emulator_file_alone(
    fitted: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    # emulator.nc holds the observed weights, standardised measurements and the
    # lambda* prior: with the theta* priors (design.csv) that is the whole target.
    a, em, _ = fitted
    inputs = CalibrationInputs(a.w_star, a.y_star_std, a.lam_star_prior)
    path = save_emulator(em, tmp_path / "emulator.nc", inputs=inputs)
    back = load_calibration_inputs(path)
    np.testing.assert_array_equal(back.y_star_std, a.y_star_std)
    priors = list(a.priors.values())
    original = build_target(em, a.w_star, a.lam_star_prior, priors)
    rebuilt = build_target(load_emulator(path), back.w_star, back.lam_star_prior, priors)
    rng = np.random.default_rng(1)
    for _ in range(5):
        v = np.concatenate([rng.random(3), rng.uniform(10.0, 100.0, 2)])
        assert rebuilt(v) == original(v)  # float64 stored: bit for bit
    with pytest.raises(DataError, match="holds no calibration inputs"):
        load_calibration_inputs(save_emulator(em, tmp_path / "old.nc"))
