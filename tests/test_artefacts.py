"""Emulator and posterior artefacts: netCDF round trips and atomic writes."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from bayescal.artefacts import load_emulator, load_posterior, save_emulator, save_posterior
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.emulator.assemble import Assembled, assemble
from bayescal.emulator.gp import Emulator
from bayescal.emulator.training import train
from bayescal.errors import DataError
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
