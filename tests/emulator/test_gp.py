"""Emulator: hyperparameter posterior (eq. 9), training, prediction and LOO-CV."""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest
from scipy import integrate, stats

from bayescal.emulator.assemble import Assembled
from bayescal.emulator.dense import dense_training_logpdf
from bayescal.emulator.gp import Emulator
from bayescal.emulator.hyper import HyperLayout, log_prior_beta
from bayescal.emulator.kernel import SeparableKernel
from bayescal.emulator.training import TrainingPosterior
from bayescal.errors import DataError
from virtual_wall import VirtualExperiment, random_truth, simulate


def _small_problem(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    theta, x = rng.random((6, 2)), rng.random((5, 3))
    w = rng.normal(size=(30, 2))
    ktk = np.array([20.0, 3.0])
    return theta, x, w, ktk


def _reference_log_post(
    theta: np.ndarray, x: np.ndarray, w: np.ndarray, ktk: np.ndarray, v: np.ndarray
) -> float:
    """Eq. 9 from the dense reference and scipy.stats densities (same constant dropped)."""
    layout = HyperLayout(2, 5)
    beta, tau, lam = layout.unpack(v)
    kernels = [SeparableKernel.from_beta(beta[j], tau[j], 2) for j in range(2)]
    lik = dense_training_logpdf(theta, x, kernels, ktk, w, lam).logpdf
    rho = np.exp(-beta / 4.0)
    prior_beta = np.sum(stats.beta.logpdf(rho, 1.0, 0.1) + np.log(rho / 4.0))
    prior_tau = np.sum(stats.gamma.logpdf(tau, 5.0, scale=1.0 / 5.0))
    prior_lam = stats.gamma.logpdf(lam, 300.0, scale=1.0 / 40.0)
    return float(lik + prior_beta + prior_tau + prior_lam)


def test_log_posterior_matches_dense_reference_and_scipy_priors() -> None:
    theta, x, w, ktk = _small_problem(0)
    target = TrainingPosterior(theta, x, w, ktk, (300.0, 40.0))
    rng = np.random.default_rng(1)
    layout = target.layout
    points = [
        layout.pack(rng.uniform(0.1, 4.0, (2, 5)), rng.uniform(0.5, 2.0, 2), rng.uniform(5, 10))
        for _ in range(4)
    ]
    mine = np.array([target(v) for v in points])
    ref = np.array([_reference_log_post(theta, x, w, ktk, v) for v in points])
    # Equal up to one additive constant (the Gamma normalisers): differences agree to
    # rounding of O(100)-sized sums (Cholesky vs eigen-decomposition).
    np.testing.assert_allclose(mine - mine[0], ref - ref[0], atol=1e-8)


def test_cache_gives_the_same_value_as_a_fresh_evaluation() -> None:
    theta, x, w, ktk = _small_problem(2)
    target = TrainingPosterior(theta, x, w, ktk, (300.0, 40.0))
    rng = np.random.default_rng(3)
    v = target.layout.pack(rng.uniform(0.5, 3.0, (2, 5)), [1.0, 1.2], 7.0)
    target(v)
    for i in rng.permutation(target.layout.d):
        proposal = v.copy()
        proposal[i] *= math.exp(rng.normal(0.0, 0.3))
        cached = target(proposal)
        fresh = pickle.loads(pickle.dumps(target))  # caches are dropped by pickling
        # Same arithmetic; LAPACK may round differently with other memory alignment.
        assert cached == pytest.approx(fresh(proposal), rel=1e-13)
        if rng.random() < 0.5:  # accept half of the moves, as MwG would
            v = proposal
        assert target(v) == pytest.approx(fresh(v), rel=1e-13)


def test_beta_prior_is_the_beta_prior_of_rho_transformed() -> None:
    # P(beta < b) = P(rho > exp(-b/4)) under rho ~ Beta(1, 0.1).
    for b0 in (1e-3, 0.5, 4.0):
        mass, _ = integrate.quad(
            lambda b: math.exp(log_prior_beta(np.array([b]), 1.0, 0.1)), 0.0, b0, limit=200
        )
        expected = stats.beta.sf(math.exp(-b0 / 4.0), 1.0, 0.1)
        # quad on an integrable b^-0.9 singularity: ~1e-6 relative accuracy.
        assert mass == pytest.approx(expected, rel=1e-5)
    assert log_prior_beta(np.array([0.0]), 1.0, 0.1) == -math.inf


@pytest.fixture(scope="module")
def wall(
    paper_wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> tuple[VirtualExperiment, Assembled, Emulator]:
    return paper_wall


def test_map_is_at_least_as_good_as_the_best_draw(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    _, a, em = wall
    assert np.isfinite(em.log_post_best)
    assert em.log_post_map >= em.log_post_best
    assert em.hyper_draws.shape == (1, 100, em.layout.d)
    assert len(em.hyper_names) == em.layout.d
    # The input with no influence on the wall's inside flux drifts to rho = 1 (ARD):
    # cp_fb is the least influential calibration input of the leading basis.
    rho = em.rho[0, : len(a.parameter_names)]
    assert rho[2] == max(rho)


def test_loo_cv_error_is_small_and_bands_are_calibrated(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    _, _, em = wall
    loo = em.loo_cv()
    rmse, sd = loo.rmse["heat_flux_in"], loo.output_sd["heat_flux_in"]
    # The basis keeps 99 % of the variance, so ~10 % of the SD is left out of it
    # (sqrt(0.01)); the GP error adds little on top.
    assert rmse < 0.1 * sd
    # 25 x 48 x 30 correlated residuals: the coverage is an average over many
    # dependent samples; 2 % either side of 95 % allows for that dependence.
    assert 0.93 <= loo.coverage(0.95) <= 0.97


def test_closed_form_loo_equals_refitting_without_each_run(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    _, _, em = wall
    mean, var = em.loo_predict()
    n_runs = em.theta.shape[0]
    n_per = em.x.shape[0]
    # Reference: drop the run, rebuild the conditioned GP from scratch, predict it.
    for run in (0, n_runs // 2, n_runs - 1):
        keep_run = np.arange(n_runs) != run
        keep = np.repeat(keep_run, n_per)
        reduced = dataclasses.replace(
            em, theta=em.theta[keep_run], w=em.w[keep], y_std=em.y_std[:, keep], conditional=None
        )
        ref_mean, ref_var = reduced.predict_std(em.theta[run], em.x)
        # Two exact routes through eigen-decompositions of matrices with condition
        # numbers up to ~1e8 (nugget against the largest eigenvalue): agreement to
        # ~1e-10 of the unit-variance standardised scale is rounding.
        np.testing.assert_allclose(mean[run], ref_mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(var[run], ref_var, rtol=1e-8, atol=1e-10)


def test_predictions_reproduce_the_runs_at_design_points(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    ve, a, em = wall
    m_star = a.n_periods
    for k in (0, 11, 29):
        mean, var = em.predict(ve.design.values[k], a.x)
        run = ve.layout.cut(ve.runs["heat_flux_in"][k])
        in_basis = a.outputs.invert(a.basis.reconstruct(a.w[k * m_star : (k + 1) * m_star]))
        truncation = np.sqrt(np.mean((run - in_basis) ** 2))
        # At a training input the GP mean returns the weight up to its tiny nugget
        # (~1e-4 of the weight variance): the error is the basis truncation.
        assert np.sqrt(np.mean((run - mean) ** 2)) < 1.05 * truncation
        assert np.all(var >= a.outputs.sd[:, None] ** 2 / em.lam * (1 - 1e-12))


def test_held_out_runs_fall_inside_their_bands_at_the_expected_rate(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    ve, a, em = wall
    rng = np.random.default_rng(5)
    inside = []
    for _ in range(6):
        truth = random_truth(rng, margin=0.0)
        run = ve.layout.cut(simulate(ve.boundary, truth))
        mean, var = em.predict(np.array(list(truth.values())), a.x)
        inside.append(np.mean(np.abs(run - mean) <= 1.96 * np.sqrt(var)))
    # 6 runs x 1200 correlated samples; 95 % nominal, +-3 % for the dependence.
    assert 0.92 <= float(np.mean(inside)) <= 0.98


def test_prediction_checks_input_widths(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    _, a, em = wall
    with pytest.raises(DataError, match=r"expected theta with 3 columns and x with 4 columns"):
        em.predict(np.ones(2), a.x)


def _test_window(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> tuple[Assembled, Emulator]:
    _, a, em = wall
    assert a.y_test_sim_std is not None
    assert a.x_test.shape[0] == 2
    return a, em.extended(a.x_test, a.y_test_sim_std)


def test_extended_emulator_equals_dense_conditioning_on_all_periods(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    a, ext = _test_window(wall)
    n_runs, m_all = a.n_runs, a.n_periods + a.x_test.shape[0]
    assert ext.x.shape[0] == m_all
    assert ext.w.shape == (n_runs * m_all, a.basis.p)
    rng = np.random.default_rng(3)
    theta0 = rng.random((3, a.theta.shape[1]))
    x0 = np.vstack([a.x_test, a.x[:1]])
    mean, var = ext.predict_weights(theta0, x0)
    for j, (kernel, nugget) in enumerate(zip(ext.kernels, ext.nuggets, strict=True)):
        # Dense reference: the run-major grid covariance S_theta ⊗ S_x + a I over the
        # R runs x (m* + 2) periods, factorised whole.
        cov = np.kron(kernel.theta_cov(a.theta), kernel.x_corr(ext.x))
        cov[np.diag_indices_from(cov)] += nugget
        c = np.stack(
            [np.kron(kernel.theta_cov(t[None], a.theta)[0], kernel.x_corr(x[None], ext.x)[0])
             for t, x in zip(theta0, x0, strict=True)]
        )  # fmt: skip
        solved = np.linalg.solve(cov, np.column_stack([ext.w[:, j], c.T]))
        ref_mean = c @ solved[:, 0]
        ref_var = kernel.variance - np.sum(c * solved[:, 1:].T, axis=1)
        np.testing.assert_allclose(mean[:, j], ref_mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(var[:, j], ref_var, rtol=0, atol=1e-9)
    # the training periods' weights are kept, the test window's appended per run (the
    # projection of the longer matrix may sum in another order: equal to rounding)
    grid = ext.w.reshape(n_runs, m_all, -1)
    np.testing.assert_allclose(
        grid[:, : a.n_periods], a.w.reshape(n_runs, a.n_periods, -1), rtol=0, atol=1e-12
    )
    with pytest.raises(DataError, match="expected x of 2 periods"):
        wall[2].extended(a.x_test, a.y_test_sim_std[:, :-1])


def test_extended_emulator_predicts_new_runs_on_the_test_window_within_its_bands(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    ve, a, ext = (wall[0], *_test_window(wall))
    rng = np.random.default_rng(5)
    inside: dict[str, list[float]] = {"trained": [], "extended": []}
    for _ in range(12):
        truth = random_truth(rng, margin=0.0)
        run = ve.layout.cut(simulate(ve.boundary, truth), "test")
        for name, em in (("trained", wall[2]), ("extended", ext)):
            mean, var = em.predict(np.array(list(truth.values())), a.x_test)
            inside[name].append(float(np.mean(np.abs(run - mean) <= 1.96 * np.sqrt(var))))
    # 12 runs x 96 correlated samples; 95 % nominal, as on the training periods
    # (measured: 0.943). The emulator trained on the training periods alone
    # extrapolates in x to the test days and its band holds about half (0.54).
    assert 0.92 <= float(np.mean(inside["extended"])) <= 0.98
    assert float(np.mean(inside["trained"])) < 0.8


def test_out_of_basis_excess_is_what_the_test_runs_leave_beyond_the_training_ones(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    _, a, _ = wall
    assert a.y_test_sim_std is not None
    k = a.basis.k

    def mean_square_left(y: np.ndarray) -> float:
        coef = np.linalg.lstsq(k, y, rcond=None)[0]
        return float(np.mean((y - k @ coef) ** 2))

    excess = a.out_of_basis_excess()
    want = mean_square_left(a.y_test_sim_std) - mean_square_left(a.y_std)
    # the test days' series have shapes the basis was not built from
    assert want > 0.0
    np.testing.assert_allclose(excess, want, rtol=1e-9)
    assert not dataclasses.replace(a, y_test_sim_std=None).out_of_basis_excess().any()
    # the test window's runs replaced by training ones: nothing beyond, never negative
    n_test = a.x_test.shape[0] * a.n_runs
    same = dataclasses.replace(a, y_test_sim_std=a.y_std[:, :n_test] * 0.5)
    assert not same.out_of_basis_excess().any()
