"""The Twin House example: the built-in wall calibrated on real Annex 58 measurements.

The measurements live in ``../shared/data`` beside the repository (never in it);
the pipeline tests skip where that folder is absent. References are independent
of the emulator and the MCMC: the catalogue values of ``shared/data/README.md``
and the measured temperature inside the wall, which the calibration never sees.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayescal import examples
from bayescal.config import WallSimulator, load_study
from bayescal.examples import copy_example
from bayescal.pipeline import Options, Results, run
from paths import SHARED_DATA

DATA = SHARED_DATA
DATA_FILE = DATA / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"
SHIPPED_DATA_LINE = 'file = "data/validationdataN2Exp1.txt"'
SERIAL = Options(backend="serial", chains_backend="serial")

#: The wall behind the west-façade sensors, outside to inside, from the table in
#: shared/data/README.md: thickness [m], k [W/(m·K)], rho [kg/m³], c [J/(kg·K)].
CATALOGUE = [
    (0.010, 0.8, 1200.0, 1000.0),
    (0.080, 0.04, 80.0, 840.0),
    (0.030, 1.0, 1200.0, 1000.0),
    (0.300, 0.22, 800.0, 1000.0),
    (0.010, 1.0, 1200.0, 1000.0),
]

#: Reduced sizes: the full 50 runs (with 25, one chain stuck in a spurious mode of the
#: cruder emulator at a corner of the prior) and short chains. The example's AR(1)
#: errors need Metropolis-within-Gibbs (with its joint move of the five parameters).
REDUCED = """
[design]
runs = 50

[emulator]
pca_variance = 0.999
history_periods = 1
burn = 150
samples = 150

[calibration]
chains = 4
sampler = "mwg"
moves = "joint"  # as the example
burn = 400
samples = 400
max_samples = 400  # the reduced size as it is: no extension

[discrepancy]
enabled = false

[predict]
method = "simulator"
runs = 20
"""


def test_example_is_listed_ships_no_data_and_uses_the_catalogue() -> None:
    assert "twinhouse" in examples.available()
    folder = examples.path("twinhouse")
    assert (folder / "README.md").is_file()
    # The measurements must never be copied into the repository.
    assert not (folder / "data").exists()
    study = load_study(folder)
    wall = study.simulator
    assert isinstance(wall, WallSimulator)
    layers = [(la.thickness, la.conductivity, la.density, la.specific_heat) for la in wall.layers]
    assert layers == CATALOGUE
    by_target = {t: p for p in study.parameters.values() for t in p.targets}
    catalogue = {"brick.conductivity": 0.22, "brick.specific_heat": 1000.0}
    catalogue["eps.conductivity"] = 0.04
    catalogue["plaster_in.specific_heat"] = 1000.0
    catalogue["measured.heat_flux_in.offset"] = 0.0  # the plate read true
    for target, value in catalogue.items():
        p = by_target[target]
        assert p.nominal == value, target
        assert p.prior.lower < value < p.prior.upper, target
    assert study.periods.test_fraction == 0.2
    assert study.predict.method == "simulator"
    # The temperature inside the wall is a held-out sensor; the flux has AR(1) errors
    # and a discrepancy over the days' conditions (both chosen by bayescal compare).
    assert study.outputs.held_out == ["temp_interface_2"]
    assert study.outputs.errors["heat_flux_in"].model == "ar1"
    assert study.outputs.errors["heat_flux_in"].discrepancy in (True, "conditions")


def _study_folder(tmp_path: Path) -> Path:
    """The example copied as ``bayescal init`` does, pointed at the shared data."""
    if not DATA.is_dir():
        pytest.skip(f"{DATA} is absent: the Annex 58 measurements are not in a fresh clone")
    target = copy_example("twinhouse", tmp_path / "twinhouse")
    path = target / "study.toml"
    text = path.read_text(encoding="utf-8")
    assert text.count(SHIPPED_DATA_LINE) == 1
    text = text.replace(SHIPPED_DATA_LINE, f"file = {DATA_FILE.as_posix()!r}")
    cut = text.index("[design]")
    path.write_text(text[:cut] + REDUCED, encoding="utf-8")
    return target


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Results:
    folder = _study_folder(tmp_path_factory.mktemp("twinhouse"))
    return run(load_study(folder), until="predict", options=SERIAL)


def _metric(
    res: Results, model: str, window: str, name: str = "rmse", output: str = "heat_flux_in"
) -> float:
    assert res.predictions is not None
    m = res.predictions.metrics
    row = m[(m["model"] == model) & (m["window"] == window) & (m["output"] == output)]
    assert len(row) == 1
    return float(row[name].to_numpy(dtype=float)[0])


def _column(table: pd.DataFrame, name: str) -> dict[str, float]:
    """A column of the posterior summary as parameter -> value."""
    values = table[name].to_numpy(dtype=float)
    return dict(zip(map(str, table.index), values.tolist(), strict=True))


@pytest.mark.slow
@pytest.mark.shared_data
def test_calibration_beats_the_catalogue_wall_on_the_training_days_and_its_band_holds_the_test_week(
    results: Results,
) -> None:
    # The nominal wall reaches about 0.44 W/m² on the training days (0.28 on the
    # held-out week). Since the three 06:00 events are excluded (2026-11-28) the
    # full-size run gains 60 % on the training days and is 10 % worse than the catalogue
    # on the held-out week (the discrepancy, extrapolated to its conditions, adds a
    # bias), where its 95 % band holds 0.975 of the half-hours (docs/case-studies.md).
    # Issue 15 asks for the test week's RMSE to be reported against the catalogue's and
    # for its 95 % band to cover 0.90-0.99 of it: never confidently wrong.
    nominal = _metric(results, "nominal", "train")
    assert _metric(results, "calibrated", "train") < 0.95 * nominal
    assert nominal == pytest.approx(0.4385, abs=0.005)
    assert np.isfinite(_metric(results, "calibrated", "test"))
    assert 0.90 <= _metric(results, "calibrated", "test", "coverage95") <= 0.99


@pytest.mark.slow
@pytest.mark.shared_data
def test_the_held_out_temperature_is_never_confidently_wrong(results: Results) -> None:
    # Column 16 (temp_interface_2, inside the wall) is never calibrated on. The
    # calibrated wall must predict it better than the catalogue wall, or else cover
    # it with its band at >= 80 % on both windows (issue 15's acceptance).
    for window in ("train", "test"):
        better = _metric(results, "calibrated", window, "rmse", "temp_interface_2") < _metric(
            results, "nominal", window, "rmse", "temp_interface_2"
        )
        covered = _metric(results, "calibrated", window, "coverage95", "temp_interface_2")
        assert better or covered >= 0.8, (window, covered)


@pytest.mark.slow
@pytest.mark.shared_data
def test_posterior_is_inside_the_prior(results: Results) -> None:
    post = results.posterior
    assert post is not None
    means = _column(post.summary(), "mean")
    for name, p in results.context.study.parameters.items():
        mean, width = means[name], p.prior.upper - p.prior.lower
        # Away from the bounds: the data, not the prior, locate every parameter.
        assert p.prior.lower + 0.1 * width < mean < p.prior.upper - 0.1 * width, name
    # The AR(1) coefficient of the flux's errors: clearly positive (0.38 at full size,
    # where the discrepancy takes the day-to-day misfit; 0.77 without it).
    assert 0.2 < means["phi"] < 0.95


@pytest.mark.slow
@pytest.mark.shared_data
def test_diagnostics_are_computed(results: Results) -> None:
    post = results.posterior
    assert post is not None
    table = post.summary()
    r_hat = _column(table, "r_hat")
    ess_bulk, ess_tail = _column(table, "ess_bulk"), _column(table, "ess_tail")
    for name in [*results.context.study.parameters, "lambda", "lambda_star"]:
        assert ess_bulk[name] > 0, name  # a NaN fails too
        assert ess_tail[name] > 0, name
        # Four short chains of 400 kept draws: R-hat near 1 (the full run: <= 1.008).
        assert 0.99 < r_hat[name] < 1.1, name
    assert post.draws.shape[:2] == (4, 400)


@pytest.mark.slow
@pytest.mark.shared_data
def test_predictions_cover_the_held_out_week(results: Results) -> None:
    assert results.predictions is not None
    ds = results.predictions.dataset
    windows = ds["window"].values
    test = windows == "test"
    # test_fraction = 0.2 of the 41-day record: a whole-sample share of it.
    assert test.sum() == results.context.measured.layout.test
    assert test.sum() >= 0.19 * windows.size
    cal = ds["heat_flux_in_calibrated"].values[test]
    lower = ds["heat_flux_in_calibrated_lower"].values[test]
    upper = ds["heat_flux_in_calibrated_upper"].values[test]
    assert np.isfinite(cal).all()
    assert np.all((lower <= cal) & (cal <= upper))
    for model in ("nominal", "calibrated"):
        assert np.isfinite(_metric(results, model, "test"))
    assert 0.0 <= _metric(results, "calibrated", "test", "coverage95") <= 1.0
