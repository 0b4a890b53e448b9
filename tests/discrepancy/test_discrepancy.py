"""The difference process (the paper's eqs. 18–25) on the virtual wall with known truth."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayescal.calibration.kron import make_algebra
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.design import BetaPrior, UniformPrior
from bayescal.discrepancy import (
    Discrepancy,
    default_priors,
    estimate_discrepancy,
    fit_delta_gp,
    piled_up,
)
from bayescal.discrepancy.delta_gp import hard_threshold
from bayescal.discrepancy.phase import DeltaPhase, empirical_moments, gls_observations
from bayescal.emulator.assemble import Assembled, assemble
from bayescal.emulator.gp import Emulator
from bayescal.emulator.training import train
from bayescal.errors import ConfigError
from bayescal.store.discrepancy import load_discrepancy, save_discrepancy
from virtual_wall import NOISE_VARIANCE, PER_DAY, VirtualExperiment, virtual_experiment

BIAS_PER_KELVIN = 0.05  # injected sensor error per K of outdoor surface temperature [W/m²K]

# --- the algebra of eqs. 20–25 against direct dense computations -----------------------


def _random_problem(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    k = rng.normal(size=(12, 3))
    y = rng.normal(size=(12, 4))
    factor = rng.normal(size=(4, 12, 4))
    return k, y, factor


def test_gls_matches_dense_reference() -> None:
    k, y, factor = _random_problem(0)
    c = 0.3
    got = gls_observations(k, y, factor, c)
    extra = 0.0
    for i in range(y.shape[1]):
        a = c * np.eye(12) + factor[i] @ factor[i].T  # eq. 22, built in full
        a_k, a_y = np.linalg.solve(a, k), np.linalg.solve(a, y[:, i])
        h = k.T @ a_k
        w = np.linalg.solve(h, k.T @ a_y)  # eq. 20
        # 12 x 12 solves against Woodbury through a 4 x 4 system: agree to round-off.
        np.testing.assert_allclose(got.w_star[i], w, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(got.nuggets[:, i], 1.0 / np.diag(h), rtol=1e-10)  # eq. 21
        quad = y[:, i] @ a_y - (k.T @ a_y) @ w  # y^T C y, eq. 24
        extra += -0.5 * (np.linalg.slogdet(a)[1] + quad)
    assert got.extra == pytest.approx(extra, rel=1e-10)


def test_gls_without_discrepancy_is_the_calibration_phase() -> None:
    k, y, factor = _random_problem(1)
    c = 0.2
    got = gls_observations(k, y, np.zeros_like(factor), c)
    ols = np.linalg.lstsq(k, y, rcond=None)[0].T  # eq. 13
    ktk = np.sum(k * k, axis=0)
    np.testing.assert_allclose(got.w_star, ols, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(got.nuggets, np.repeat((c / ktk)[:, None], 4, axis=1), rtol=1e-12)
    rss = np.sum((y - k @ ols.T) ** 2, axis=0)
    assert got.extra == pytest.approx(-0.5 * np.sum(12 * np.log(c) + rss / c), rel=1e-10)


def test_moments_sign_is_observation_minus_model() -> None:
    rng = np.random.default_rng(2)
    k = rng.normal(size=(10, 2))
    mu = rng.normal(size=(3, 2))
    offset = np.linspace(0.5, 1.0, 10)
    y = k @ mu.T + offset[:, None]  # observation = model + a positive error
    mom = empirical_moments(k, y, mu, np.zeros_like(mu), 5, rng)
    # No model spread: every realisation is K mu, so Delta = y - K mu and D = Delta Delta^T.
    np.testing.assert_allclose(mom.delta, np.repeat(offset[:, None], 3, axis=1), atol=1e-12)
    for i in range(3):
        d = mom.factor[i] @ mom.factor[i].T
        np.testing.assert_allclose(d, np.outer(offset, offset), atol=1e-10)


def test_moments_converge_to_their_expectation() -> None:
    rng = np.random.default_rng(3)
    k = rng.normal(size=(6, 2))
    mu, var = rng.normal(size=(1, 2)), np.array([[0.5, 2.0]])
    y = rng.normal(size=(6, 1))
    b = 40_000
    mom = empirical_moments(k, y, mu, var, b, rng)
    delta = y[:, 0] - k @ mu[0]  # E[d], d = y - K w ~ N(delta, S)
    cov = k @ np.diag(var[0]) @ k.T
    expected = np.outer(delta, delta) + cov  # E[d d^T]
    d = mom.factor[0] @ mom.factor[0].T
    # Isserlis: Var(d_a d_b) for a Gaussian d; 5 Monte Carlo standard errors of b draws.
    var_d = np.diag(cov)
    var_prod = (
        np.outer(var_d, var_d)
        + cov**2
        + np.outer(delta**2, var_d)
        + np.outer(var_d, delta**2)
        + 2 * np.outer(delta, delta) * cov
    )
    assert np.all(np.abs(d - expected) < 5 * np.sqrt(var_prod / b))
    assert np.all(np.abs(mom.delta[:, 0] - delta) < 5 * np.sqrt(var_d / b))


# --- priors from the calibration posterior -----------------------------------------------


def test_piled_up_rule() -> None:
    rng = np.random.default_rng(4)
    assert piled_up(rng.beta(1.0, 8.0, 20_000)) == "lower"
    assert piled_up(1.0 - rng.beta(1.0, 8.0, 20_000)) == "upper"
    assert piled_up(np.abs(rng.normal(0.0, 0.1, 20_000))) == "lower"  # half-normal at 0
    assert piled_up(rng.random(20_000)) is None  # spread over the interval
    assert piled_up(rng.normal(0.5, 0.05, 20_000)) is None
    assert piled_up(rng.normal(0.06, 0.02, 20_000)) is None  # mode 3 SD inside the bound


def _fake_posterior(unit: np.ndarray) -> Posterior:
    priors = {"a": UniformPrior(0.0, 2.0), "b": UniformPrior(10.0, 20.0)}
    shape = unit.shape[:2]
    return Posterior.build(
        names=("a", "b"),
        priors=priors,
        unit_draws=unit,
        lam=np.ones(shape),
        lam_star=np.ones(shape),
        log_density=np.zeros(shape),
        acceptance=np.full((shape[0], 4), 0.4),
        seed=0,
        algebra="kronecker",
    )


def test_default_priors_follow_the_paper() -> None:
    rng = np.random.default_rng(5)
    bell = rng.normal(0.4, 0.05, (4, 500))
    pile = rng.beta(1.0, 10.0, (4, 500))
    post = _fake_posterior(np.stack([bell, pile], axis=-1))
    priors = default_priors(post)
    a = priors["a"]
    assert isinstance(a, BetaPrior)
    assert (a.lower, a.upper) == (0.0, 2.0)
    mean = a.a / (a.a + a.b)
    var = a.a * a.b / ((a.a + a.b) ** 2 * (a.a + a.b + 1))
    # Moment matching: the Beta has the sample's mean and variance (sample error ~1 %).
    assert mean == pytest.approx(bell.mean(), abs=1e-12)
    assert var == pytest.approx(bell.var(), rel=1e-9)
    assert priors["b"] == BetaPrior(10.0, 20.0, 1.0, 2.0)  # paper: Beta(1, 2) at a pile-up
    assert default_priors(post, pile_up="away")["b"] == BetaPrior(10.0, 20.0, 2.0, 1.0)


# --- the GP of Delta over x --------------------------------------------------------------


def test_hard_threshold_separates_signal_from_noise() -> None:
    rng = np.random.default_rng(6)
    n, m, sigma = 48, 20, 0.1
    noise = sigma * rng.normal(size=(n, m))
    sv = np.linalg.svd(noise, compute_uv=False)
    threshold, var = hard_threshold(sv, (n, m))
    # The median-based estimate of sigma^2 from 20 singular values: within 25 %.
    assert var == pytest.approx(sigma**2, rel=0.25)
    assert np.sum(sv > threshold) == 0
    x = rng.random((m, 2))
    signal = np.outer(np.sin(np.linspace(0, 3, n)), 0.5 + x[:, 0])
    assert fit_delta_gp(noise, x).n_components == 0
    assert fit_delta_gp(signal + noise, x).n_components == 1


def test_delta_gp_predicts_a_smooth_discrepancy() -> None:
    rng = np.random.default_rng(7)
    n, m, sigma = 24, 16, 0.05
    shape = np.cos(np.linspace(0, 2 * np.pi, n))
    x = rng.random((m, 2))
    x_new = rng.random((6, 2))

    def level(xx: np.ndarray) -> np.ndarray:
        return 0.3 + np.sin(3.0 * xx[:, 0])  # depends on the first input only

    data = np.outer(shape, level(x)) + sigma * rng.normal(size=(n, m))
    gp = fit_delta_gp(data, x)
    mean, var = gp.predict_std(x_new)
    truth = np.outer(shape, level(x_new))
    # Interpolation inside the unit square from 16 periods: error a few times the noise of a
    # component weight (sigma / |shape| ~ 0.015) and well inside the predictive bands.
    assert np.max(np.abs(mean - truth)) < 0.1
    z = (mean - truth) / np.sqrt(var + sigma**2)
    assert np.all(np.abs(z) < 4.0)
    rho = np.exp(-0.25 * gp.beta[0])
    assert rho[0] < rho[1]  # ARD: the inactive second input is the less influential


# --- the full phase on the virtual wall --------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Case:
    ve: VirtualExperiment
    error: np.ndarray  # injected error on the whole record [W/m²]
    assembled: Assembled
    posterior: Posterior
    discrepancy: Discrepancy
    seconds: float


def _experiment() -> VirtualExperiment:
    return virtual_experiment(seed=0, runs=14, periods=10, warmup_days=3, test_days=2)


def _case(ve: VirtualExperiment, em: Emulator | None, error: np.ndarray) -> tuple[Case, Emulator]:
    measured = {"heat_flux_in": ve.measured["heat_flux_in"] + error}
    a = assemble(ve.design, ve.runs, measured, ve.boundary, ve.layout, variance=0.99)
    if em is None:  # the emulator sees the simulations only: one serves both cases
        em = train(a, n_burn=150, n_draws=40, n_chains=1, seed=1)
    post = calibrate(em, a, n_chains=4, n_burn=300, n_draws=400, seed=3)
    start = time.perf_counter()
    d = estimate_discrepancy(
        em, a, post, realisations=30, update_interval=50, n_burn=200, n_draws=300, seed=5
    )
    return Case(ve, error, a, post, d, time.perf_counter() - start), em


@pytest.fixture(scope="module")
def cases() -> dict[str, Case]:
    ve = _experiment()
    clean, em = _case(ve, None, np.zeros(ve.layout.n_total))
    t_out = ve.boundary["temp_surf_out"]
    biased, _ = _case(ve, em, BIAS_PER_KELVIN * (t_out - t_out.mean()))
    return {"clean": clean, "biased": biased}


@pytest.mark.slow
def test_no_discrepancy_when_the_simulator_is_right(cases: dict[str, Case]) -> None:
    case = cases["clean"]
    d = case.discrepancy
    n = d.delta.shape[0]
    se = np.sqrt(NOISE_VARIANCE / n)  # standard error of a period mean of pure noise [W/m²]
    # Period means of Delta: noise plus the emulator's own error (of similar size at 14 runs):
    # 4 noise standard errors is about 3 combined ones.
    assert np.all(np.abs(d.delta.mean(axis=0)) < 4.0 * se), d.delta.mean(axis=0)
    assert abs(d.delta.mean()) < 4.0 * se / np.sqrt(d.delta.shape[1])
    # Nothing above the white-noise threshold, or only the emulator's small error: the GP
    # explains at most a fifth of the training residual (it is 0 with no component kept).
    assert d.explained["heat_flux_in"] < 0.2
    cal, disc = case.posterior, d.posterior
    sd = cal.draws.reshape(-1, 3).std(axis=0)
    shift = np.abs(disc.draws.reshape(-1, 3).mean(axis=0) - cal.draws.reshape(-1, 3).mean(axis=0))
    # theta* stays put: within half a calibration SD (Monte Carlo error of the phase's mean
    # with ESS ~ 40 is ~0.16 SD).
    assert np.all(shift < 0.5 * sd), shift / sd
    assert np.all(np.isnan(disc.acceptance[:, 3:]))  # lambda and lambda* fixed
    assert np.all(disc.lam == np.mean(cal.lam))


def _row(table: pd.DataFrame) -> dict[str, float]:
    values = table.loc["heat_flux_in"].to_numpy(dtype=float)
    return dict(zip(map(str, table.columns), values.tolist(), strict=True))


@pytest.mark.slow
def test_discrepancy_recovers_an_injected_sensor_error(cases: dict[str, Case]) -> None:
    case = cases["biased"]
    d, layout = case.discrepancy, case.ve.layout
    error = layout.cut(case.error)  # (n, m*) [W/m²]
    slope = np.polyfit(error.ravel(), d.delta.ravel(), 1)[0]
    r = np.corrcoef(error.ravel(), d.delta.ravel())[0, 1]
    # Noise SD 0.084 W/m² against an error of SD ~0.17: r can reach ~0.85; the calibration
    # absorbs part of the error by moving cp (slope below 1); 0.6 and [0.6, 1.3] leave margin.
    assert r > 0.6
    assert 0.6 < slope < 1.3  # positive: Delta = observation - model (the paper's eq. 25: < 0)
    fitted_r = np.corrcoef(error.ravel(), d.fitted.ravel())[0, 1]
    assert fitted_r > 0.7  # the GP keeps the systematic part and drops the noise
    model, corrected = d.mse["heat_flux_in"]
    assert corrected < 0.6 * model  # the paper's Table 7: model + Delta fits better
    assert d.explained["heat_flux_in"] == pytest.approx(1.0 - corrected / model)
    bc = {name: layout.cut(series) for name, series in case.ve.boundary.items()}
    corr = _row(d.correlation(bc))
    r_out, r_in = corr["temp_surf_out"], corr["temp_surf_in"]
    # The error follows the outdoor temperature (period means), not the indoor one.
    assert r_out > 0.8
    assert abs(r_in) < r_out
    assert _row(d.correlation(bc, by="sample"))["temp_surf_out"] > 0.5
    mean, var = d.predict(case.assembled.x_test)
    err_test = layout.cut(case.error, "test")
    assert mean.shape == var.shape == err_test.shape
    # On the test window (colder than training) the predicted Delta reduces the injected error.
    assert np.mean((err_test - mean) ** 2) < np.mean(err_test**2)


@pytest.mark.slow
def test_round_trip_gives_identical_predictions(cases: dict[str, Case], tmp_path: Path) -> None:
    for name in ("clean", "biased"):
        d = cases[name].discrepancy
        path = save_discrepancy(d, tmp_path / f"{name}.nc")
        back = load_discrepancy(path)
        x_test = cases[name].assembled.x_test
        for x in (d.x, x_test):
            for got, ref in zip(back.predict(x), d.predict(x), strict=True):
                np.testing.assert_array_equal(got, ref)
        np.testing.assert_array_equal(back.delta, d.delta)
        np.testing.assert_array_equal(back.posterior.draws, d.posterior.draws)
        assert back.posterior.priors == d.posterior.priors
        assert back.explained == d.explained
    assert not list(tmp_path.glob(".*.tmp"))  # no temporary file left behind


def test_bad_inputs_raise_config_errors(small: tuple[Assembled, Emulator, Posterior]) -> None:
    a, em, post = small
    with pytest.raises(ConfigError, match=r"realisations must be an integer >= 2.*got 1"):
        estimate_discrepancy(em, a, post, realisations=1)
    with pytest.raises(ConfigError, match=r"update_interval must be an integer >= 1"):
        estimate_discrepancy(em, a, post, update_interval=0)
    ve = virtual_experiment(seed=4, runs=8, periods=6, warmup_days=2, test_days=0)
    other = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=3)
    with pytest.raises(ConfigError, match=r"basis K \(48, 2\) differs .* \(48, 3\)"):
        estimate_discrepancy(em, other, post)
    renamed = dataclasses.replace(post, names=("a", "b", "c"))
    with pytest.raises(ConfigError, match=r"the posterior has parameters \['a', 'b', 'c'\]"):
        estimate_discrepancy(em, a, renamed)


@pytest.fixture(scope="module")
def small(
    small_wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> tuple[Assembled, Emulator, Posterior]:
    _, a, em = small_wall
    post = calibrate(em, a, n_chains=4, n_burn=50, n_draws=50, seed=1, backend="serial")
    return a, em, post


def test_kronecker_and_dense_targets_agree(small: tuple[Assembled, Emulator, Posterior]) -> None:
    a, em, _ = small
    targets = []
    for kind in ("kronecker", "dense"):
        alg = make_algebra(kind, em.theta, em.x, em.kernels, em.basis.ktk, em.w, a.w_star)
        phase = DeltaPhase(em, a.y_star_std, alg, list(a.priors.values()), em.lam, 40.0, 20)
        targets.append(phase.update(np.full(3, 0.5), np.random.default_rng(8)))
    rng = np.random.default_rng(9)
    for _ in range(4):
        u = rng.random(3)
        fast, ref = (t(u) for t in targets)
        # Schur complement with per-period nuggets B_j vs dense Cholesky of ~54 rows.
        assert fast == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_chains_depend_on_the_seed_only(small: tuple[Assembled, Emulator, Posterior]) -> None:
    a, em, post = small
    ticks: list[int] = []
    runs = [
        estimate_discrepancy(
            em,
            a,
            post,
            realisations=10,
            update_interval=7,
            n_chains=4,
            n_burn=10,
            n_draws=12,
            seed=2,
            callback=ticks.append,
        )
        for _ in range(2)
    ]
    np.testing.assert_array_equal(runs[0].posterior.draws, runs[1].posterior.draws)
    assert runs[0].posterior.draws.shape == (4, 12, 3)
    assert max(ticks) == 4 * (10 + 12)  # progress counts every sweep of every chain
    assert np.all(np.isfinite(runs[0].posterior.log_density))
    assert runs[0].delta.shape == (PER_DAY, 6)
