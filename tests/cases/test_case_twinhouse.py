"""The Twin House example: the built-in wall calibrated on real Annex 58 measurements.

The measurements live in ``../shared/data`` beside the repository (never in it);
the pipeline tests skip where that folder is absent. References are independent
of the emulator and the MCMC: the catalogue values of ``shared/data/README.md``
and a direct least-squares fit of the simulator to the same training data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import least_squares

from bayescal import examples
from bayescal.config import WallSimulator, load_study
from bayescal.emulator.assemble import runs_to_columns
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
#: cruder emulator at a corner of the prior) and short chains; enough for the five
#: parameters that the 27 training days identify sharply. NUTS as in the example
#: (the posterior is correlated: Metropolis-within-Gibbs with 4 x (400 + 600) left
#: R-hat 2.1; JAX comes with the dev extra that `make test` installs). The
#: difference process is on, with short chains, so that all three models are
#: compared.
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
sampler = "nuts"
burn = 300
samples = 500

[discrepancy]
enabled = true
burn = 400
samples = 600

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


def _metric(res: Results, model: str, window: str, name: str = "rmse") -> float:
    assert res.predictions is not None
    m = res.predictions.metrics
    row = m[(m["model"] == model) & (m["window"] == window)]
    assert len(row) == 1
    return float(row[name].to_numpy(dtype=float)[0])


def _column(table: pd.DataFrame, name: str) -> dict[str, float]:
    """A column of the posterior summary as parameter -> value."""
    values = table[name].to_numpy(dtype=float)
    return dict(zip(map(str, table.index), values.tolist(), strict=True))


def _least_squares_optimum(res: Results) -> np.ndarray:
    """The simulator fitted directly to the training periods (no emulator, no MCMC).

    Fitted in the metric the calibration's likelihood (eq. 16) sees the data in:
    the measured periods enter it only through their basis weights ``w*``
    (standardised per sample, projected on the PCA basis ``K``), with precision
    ``lambda* K^T K``. So the residual is ``sqrt(k_j^T k_j) (w_j(theta) - w*_j)``
    over all bases and training periods, where ``w(theta)`` are the weights of the
    simulator's output at ``theta``. (A plain least-squares fit of the flux series
    also counts what the basis leaves out and weights the hours of the day equally;
    on this wall it lands up to 3 posterior SDs away, docs/case-studies.md.)
    """
    ctx = res.context
    assert res.emulator is not None
    assembled = res.emulator.assembled
    names = list(ctx.study.parameters)
    layout = ctx.measured.layout
    root_ktk = np.sqrt(assembled.basis.ktk)

    def residual(theta: np.ndarray) -> np.ndarray:
        out = ctx.simulator.simulate(dict(zip(names, theta, strict=True)), ctx.measured.forcing)
        periods = runs_to_columns(layout.cut(out["heat_flux_in"][None]))
        w = assembled.basis.weights(assembled.outputs.apply({"heat_flux_in": periods}))
        return ((w - assembled.w_star) * root_ktk).ravel()

    nominal = np.array([p.nominal for p in ctx.study.parameters.values()])
    lower = np.array([p.prior.lower for p in ctx.study.parameters.values()])
    upper = np.array([p.prior.upper for p in ctx.study.parameters.values()])
    fit = least_squares(residual, nominal, x_scale=(upper - lower) / 4, bounds=(lower, upper))
    assert fit.success
    return np.asarray(fit.x)


@pytest.mark.slow
@pytest.mark.shared_data
def test_calibration_beats_the_catalogue_wall_on_both_windows(results: Results) -> None:
    # The bar: the nominal wall reaches about 0.45 W/m² on the training days
    # (0.28 on the held-out week); a calibration worth the name must beat it on
    # the held-out window. The full-size run gains 28 % there (docs/case-studies.md);
    # the reduced one here must gain at least 10 %.
    for window in ("train", "test"):
        nominal = _metric(results, "nominal", window)
        assert _metric(results, "calibrated", window) < 0.9 * nominal, window
    assert _metric(results, "nominal", "train") == pytest.approx(0.447, abs=0.01)


@pytest.mark.slow
@pytest.mark.shared_data
def test_difference_process_fits_the_training_residual(results: Results) -> None:
    # Delta is fitted to what the calibrated wall leaves on the training days, so
    # there it must take most of the remaining error away. On the held-out week it
    # extrapolates and is not required to help (it does not: docs/case-studies.md).
    calibrated = _metric(results, "calibrated", "train")
    assert _metric(results, "calibrated+delta", "train") < 0.6 * calibrated
    assert np.isfinite(_metric(results, "calibrated+delta", "test"))


@pytest.mark.slow
@pytest.mark.shared_data
def test_posterior_is_inside_the_prior_and_matches_a_direct_fit(results: Results) -> None:
    post = results.posterior
    assert post is not None
    means = _column(post.summary(), "mean")
    study = results.context.study
    optimum = _least_squares_optimum(results)
    for k, (name, p) in enumerate(study.parameters.items()):
        mean, width = means[name], p.prior.upper - p.prior.lower
        # Away from the bounds: the data, not the prior, locate every parameter.
        assert p.prior.lower + 0.1 * width < mean < p.prior.upper - 0.1 * width, name
        # Flat prior and ~1300 training samples: the posterior mean is the
        # simulator's least-squares optimum in the likelihood's metric, up to
        # emulator error and Monte Carlo error of the short chains (posterior SDs
        # are 1-3 % of the prior widths).
        assert abs(mean - optimum[k]) < 0.05 * width, name


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
        # Four NUTS chains of 500 kept draws: R-hat near 1 (the full run: <= 1.003).
        assert 0.99 < r_hat[name] < 1.05, name
    assert post.draws.shape[:2] == (4, 500)


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
