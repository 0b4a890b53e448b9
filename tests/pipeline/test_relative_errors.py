"""Errors proportional to the level (``[outputs.errors.NAME] relative = true``).

A meter accurate to 3 % is calibrated on ``log(y + floor)``
(:class:`bayescal.emulator.noise.LogLevel`), its bands computed there and
mapped back (:func:`bayescal.pipeline.predict.simulator_band` with
``transforms``). Checked here: the map and its mean against Monte Carlo, the
mapped band's edges against the quantiles of sampled measurements, the bands'
coverage on a known truth with multiplicative noise (binomial bounds) where
absolute errors miss their 50 % rate, the study file's options and refusals,
and the log-Jacobian that puts ``bayescal compare`` in the measurements' units.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from bayescal.calibration.cv import PeriodScores
from bayescal.calibration.posterior import Posterior
from bayescal.config import load_study
from bayescal.emulator.assemble import Assembled, NoiseSpec, assemble
from bayescal.emulator.noise import LogLevel
from bayescal.errors import ConfigError, DataError
from bayescal.examples import copy_example
from bayescal.periods import layout_periods
from bayescal.pipeline.compare import relative_jacobian
from bayescal.pipeline.predict import simulator_band
from bayescal.pipeline.simnoise import simulator_noise
from box_study import reduced_box
from virtual_wall import PRIORS, simulate, virtual_experiment

DRAWS = 12
SIGMA = 0.05  # the meter's relative noise
NAME = "heat_flux_in"  # the glossary name the positive "meter" series borrows


def _level(flux: np.ndarray) -> np.ndarray:
    """A positive series spanning a factor ~40 from the wall's inside flux."""
    return 100.0 * np.exp(0.8 * (np.asarray(flux) + 5.5))


def _experiment(relative: bool) -> tuple[Assembled, np.ndarray, np.ndarray, LogLevel, dict]:
    ve = virtual_experiment(seed=11, runs=8, periods=8, warmup_days=2, test_days=4)
    rng = np.random.default_rng(3)
    truth = _level(simulate(ve.boundary, ve.truth))
    measured = truth * np.exp(SIGMA * rng.standard_normal(truth.size))
    runs = _level(ve.runs[NAME])
    train = ve.layout.cut(measured)
    level = LogLevel(0.01 * float(np.mean(train)))
    if relative:
        runs, meas = level.forward(runs), level.forward(measured)
    else:
        runs, meas = runs, measured
    a = assemble(
        ve.design, {NAME: runs}, {NAME: meas}, ve.boundary, ve.layout, components=2,
        scale="output", noise={NAME: NoiseSpec("white", relative=relative)},
    )  # fmt: skip
    return a, measured, truth, level, ve.truth


def _posterior(a: Assembled, truth: dict[str, float]) -> Posterior:
    obs = a.observations
    unit = np.array([PRIORS[n].to_unit(truth[n]) for n in PRIORS])
    jitter = np.random.default_rng(0).normal(0.0, 1e-9, (2, DRAWS // 2, unit.size))
    names = ["lambda", *obs.names()]
    aux = np.ones((2, DRAWS // 2, len(names)))
    return Posterior.build(
        list(PRIORS), PRIORS, unit + jitter, acceptance=np.full((2, unit.size + len(names)), 0.3),
        aux=aux, aux_names=names, noise=obs.outputs,
    )  # fmt: skip


def test_the_log_map_its_inverse_and_its_mean() -> None:
    level = LogLevel(0.5)
    y = np.array([0.0, 1.0, 250.0, np.nan])
    z = level.forward(y)
    np.testing.assert_allclose(level.inverse(z[:3]), y[:3], rtol=1e-14, atol=1e-14)
    assert np.isnan(z[3])
    np.testing.assert_allclose(level.log_jacobian(y[:3]), -np.log(y[:3] + 0.5), rtol=1e-14)
    rng = np.random.default_rng(1)
    mu, var = 2.0, 0.09
    sample = level.inverse(rng.normal(mu, np.sqrt(var), 400_000))
    se = sample.std() / np.sqrt(sample.size)
    assert abs(float(level.mean(mu, var)) - sample.mean()) < 4.0 * se
    with pytest.raises(DataError, match=r"above -floor"):
        level.forward(np.array([1.0, -0.7]), "measured gas")
    with pytest.raises(ConfigError, match=r"floor"):
        LogLevel(0.0)


def test_mapped_edges_are_the_quantiles_of_the_measurements() -> None:
    level = LogLevel(1.0)
    rng = np.random.default_rng(2)
    mu = rng.normal(3.0, 0.2, (30, 5))
    var = np.full_like(mu, 0.04)
    from bayescal.pipeline.predict import _mixture_band

    band = _mixture_band({"g": mu}, {"g": var}, {}, 0.9, {"g": level})
    comp = rng.integers(0, mu.shape[0], 200_000)
    for t in range(mu.shape[1]):
        y = level.inverse(rng.normal(mu[comp, t], 0.2))
        lo, hi = np.quantile(y, [0.05, 0.95])
        assert band.lower["g"][t] == pytest.approx(lo, rel=5e-3)
        assert band.upper["g"][t] == pytest.approx(hi, rel=5e-3)
        assert band.mean["g"][t] == pytest.approx(y.mean(), rel=5e-3)


def _coverage(relative: bool) -> dict[float, tuple[int, int]]:
    a, measured, truth, level, truth_params = _experiment(relative)
    post = _posterior(a, truth_params)
    run = level.forward(truth) if relative else truth
    runs = {NAME: np.tile(run, (DRAWS, 1))}
    lam = simulator_noise(a, runs, post, np.arange(DRAWS))
    transforms = {NAME: level} if relative else None
    band = simulator_band(a, runs, lam, measured={NAME: measured}, transforms=transforms)
    test = np.zeros(a.layout.n_total, dtype=bool)
    test[a.layout.test_begin :] = True
    y = measured[test]
    out = {}
    for p, lo, hi in ((0.95, band.lower, band.upper), (0.5, band.lower50, band.upper50)):
        inside = (y >= lo[NAME][test]) & (y <= hi[NAME][test])
        out[p] = (int(inside.sum()), int(inside.size))
    if relative:  # the noise the bands hold is the meter's, as a fraction of the level
        assert band.noise_sd[NAME] == pytest.approx(SIGMA, rel=0.15)
    return out


def test_relative_bands_cover_at_their_rates_where_absolute_ones_do_not() -> None:
    relative, absolute = _coverage(True), _coverage(False)
    for p in (0.95, 0.5):
        k, n = relative[p]
        lo, hi = stats.binom.interval(0.998, n, p)
        assert lo <= k <= hi, (p, k, n)
    # one SD for all levels: too wide at low levels, too narrow at high ones
    k, n = absolute[0.5]
    lo, hi = stats.binom.interval(0.998, n, 0.5)
    assert not lo <= k <= hi, (k, n)


def test_the_study_file_states_relative_errors(tmp_path: Path) -> None:
    folder = copy_example("box-coheating", tmp_path / "box")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    head = text[: text.index("[outputs.errors.heating_power]")]
    rest = text[text.index("[outputs.errors.heating_power]") :]
    path.write_text(
        head + rest.replace(
            "[outputs.errors.heating_power]",
            '[outputs.errors.heating_power]\nrelative = true\nsd = "3 %"\nfloor = "1 W"', 1,
        ), encoding="utf-8",
    )  # fmt: skip
    study = load_study(folder)
    assert study.outputs.relative("heating_power")
    assert study.outputs.noise_sd("heating_power") == pytest.approx(0.03)
    assert study.outputs.floor("heating_power") == pytest.approx(1.0)
    dump = study.outputs.calibration_dump()["errors"]["heating_power"]
    assert dump["relative"] is True
    # a study without them dumps as before (stage keys unchanged)
    plain = load_study(copy_example("box-coheating", tmp_path / "plain"))
    assert "relative" not in plain.outputs.calibration_dump()["errors"]["heating_power"]


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        ('relative = true\nsd = "3 W"', r"not a fraction"),
        ('floor = "1 W"', r"floor is for relative errors"),
        ("relative = true\nfloor = -1.0", r"floor must be > 0"),
    ],
)
def test_impossible_relative_errors_are_refused(tmp_path: Path, lines: str, message: str) -> None:
    folder = copy_example("box-coheating", tmp_path / "box")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    path.write_text(
        text.replace(
            "[outputs.errors.heating_power]", f"[outputs.errors.heating_power]\n{lines}", 1
        ),
        encoding="utf-8",
    )
    with pytest.raises(ConfigError, match=message):
        load_study(folder)


def test_relative_errors_and_the_difference_process_phase_are_refused(tmp_path: Path) -> None:
    folder = copy_example("box-coheating", tmp_path / "box")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    text = text.replace(
        "[outputs.errors.heating_power]", "[outputs.errors.heating_power]\nrelative = true", 1
    )
    path.write_text(text.replace("enabled = false", "enabled = true"), encoding="utf-8")
    with pytest.raises(ConfigError, match=r"do not combine with the difference-process phase"):
        load_study(folder)


def test_outputs_below_minus_the_floor_are_refused_in_one_line() -> None:
    """Values of the training periods or the test window below -floor name the output;
    those of the warm-up are not read."""
    from bayescal.pipeline.stages import level_values

    ve = virtual_experiment(seed=11, runs=8, periods=8, warmup_days=2, test_days=4)
    series = _level(ve.measured[NAME])
    ctx = SimpleNamespace(
        measured=SimpleNamespace(layout=ve.layout, outputs={NAME: series}),
        transforms={NAME: LogLevel(1.0)},
    )
    warm = series.copy()
    warm[: ve.layout.warmup] = -50.0
    out = level_values(ctx, {NAME: warm}, "simulated")  # type: ignore[arg-type]
    assert np.isnan(out[NAME][: ve.layout.warmup]).all()
    np.testing.assert_allclose(
        out[NAME][ve.layout.test_begin :], np.log(series[ve.layout.test_begin :] + 1.0)
    )
    bad = series.copy()
    bad[ve.layout.test_begin + 3] = -50.0
    with pytest.raises(DataError, match=r"^simulated heat_flux_in: relative errors need values"):
        level_values(ctx, {NAME: bad}, "simulated")  # type: ignore[arg-type]


def test_runs_are_read_on_the_whole_periods_covering_a_partial_test_window() -> None:
    """A test window of 2.5 periods: its first period begins before it. The runs there
    are on the log scale (the emulator route conditions on them), the measurements
    before the window are not read."""
    from bayescal.pipeline.stages import assemble_runs, level_values

    ve = virtual_experiment(seed=11, runs=8, periods=8, warmup_days=2, test_days=4)
    period = ve.layout.period
    layout = layout_periods(ve.layout.n_total, period, ve.layout.warmup, 5 * period // 2)
    first = int(layout.test_starts[0])
    assert first < layout.test_begin
    series = _level(ve.measured[NAME])
    ctx = SimpleNamespace(
        measured=SimpleNamespace(
            layout=layout, outputs={NAME: series}, forcing=SimpleNamespace(series=ve.boundary)
        ),
        transforms={NAME: LogLevel(1.0)},
        study=SimpleNamespace(
            outputs=SimpleNamespace(calibrate=[NAME], errors={}, noise_sd=lambda _: None),
            emulator=SimpleNamespace(
                pca_variance=0.99, pca_components=None, input_pca_variance=0.9,
                history_periods=0, standardise="output",
            ),
        ),
    )  # fmt: skip
    runs = _level(ve.runs[NAME])
    simulated = level_values(ctx, {NAME: runs}, "simulated")[NAME]  # type: ignore[arg-type]
    measured = level_values(ctx, {NAME: series}, "measured")[NAME]  # type: ignore[arg-type]
    gap = slice(first, layout.test_begin)
    np.testing.assert_allclose(simulated[:, gap], np.log(runs[:, gap] + 1.0))
    assert np.isnan(measured[gap]).all()
    sims = SimpleNamespace(design=ve.design, unit=ve.design.unit, outputs={NAME: runs})
    a = assemble_runs(ctx, sims)  # type: ignore[arg-type]
    assert a.y_test_sim_std is not None
    assert np.isfinite(a.y_test_sim_std).all()
    assert a.y_test_sim_std.shape[1] == 8 * layout.test_starts.size


def test_compare_adds_the_log_jacobian_per_period() -> None:
    ve = virtual_experiment(seed=11, runs=8, periods=8, warmup_days=2, test_days=4)
    measured = _level(ve.measured[NAME])
    level = LogLevel(0.3)
    ctx = SimpleNamespace(
        measured=SimpleNamespace(layout=ve.layout, outputs={NAME: measured}),
        transforms={NAME: level},
    )
    jac = relative_jacobian(ctx)  # type: ignore[arg-type]
    want = -np.log(ve.layout.cut(measured) + 0.3).sum(axis=0)
    np.testing.assert_allclose(jac, want, rtol=1e-13)
    m = jac.size
    scores = PeriodScores(
        psis=np.zeros(m), pareto_k=np.zeros(m), lppd=np.ones(m), refit=np.full(m, np.nan),
        log_jacobian=0.0, draws=10,
    )  # fmt: skip
    shifted = scores.shifted(jac)
    np.testing.assert_allclose(shifted.pointwise, jac)
    np.testing.assert_allclose(shifted.lppd, 1.0 + jac)
    assert np.isnan(shifted.refit).all()


def _box(tmp_path: Path, name: str, relative: bool) -> Path:
    # the box is cooled at times in some runs (heating power down to -46 W): a floor
    # of 60 W keeps every level positive (errors relative above it, absolute below)
    errors = 'relative = true\nfloor = "60 W"' if relative else ""
    return reduced_box("box-coheating", tmp_path / name, errors)


@pytest.mark.slow
def test_a_study_with_relative_errors_runs_and_compare_prefers_the_true_error_model(
    tmp_path: Path,
) -> None:
    """The co-heating box's meter noise is additive (2 W): with the log-Jacobian in the
    scores, compare must prefer absolute errors; without it, the log scale's densities
    would win by ~log(level) per sample."""
    from bayescal.pipeline import Options, run
    from bayescal.pipeline.compare import compare

    options = Options(backend="serial", chains_backend="serial")
    relative = _box(tmp_path, "relative", True)
    absolute = _box(tmp_path, "absolute", False)
    res = run(load_study(relative), until="predict", options=options)
    assert res.posterior is not None
    assert res.predictions is not None
    assert [o.unit for o in res.posterior.noise] == ["relative"]
    from bayescal.cli.progress import describe

    shown = describe(res)
    assert "on the scale of log(heating_power + floor)" in shown
    assert "measurement noise of heating_power (ar1): SD" in shown
    assert "relative" in shown
    ds = res.predictions.dataset
    train = ds["window"].values == "train"
    mean = ds["heating_power_calibrated"].values[train]
    lower = ds["heating_power_calibrated_lower"].values[train]
    upper = ds["heating_power_calibrated_upper"].values[train]
    measured = ds["heating_power_measured"].values[train]
    assert np.all(lower < mean)
    assert np.all(mean < upper)
    m = res.predictions.metrics
    rows = m[(m["window"] == "train")].set_index("model")
    assert rows.loc["calibrated", "mse"] < rows.loc["nominal", "mse"]
    assert 0.8 < np.mean((measured >= lower) & (measured <= upper)) <= 1.0
    result = compare(
        [relative, absolute],
        output=tmp_path / "cmp",
        options=options,
        max_refits=0,
        catalogue=False,
    )
    ranked = [v.label for v in result.variants]
    assert ranked[0] == "absolute", result.table
    gap = result.variants[0].scores.elpd - result.variants[1].scores.elpd
    jacobian = float(np.sum(np.log(measured + 60.0)))
    assert gap < 0.1 * jacobian  # same units: far less than the log-Jacobian itself
