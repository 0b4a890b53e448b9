"""Leave-one-period-out in physical units: Jacobian, held-out target, PSIS against refits."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from scipy import linalg, stats

from bayescal.calibration import cv
from bayescal.calibration.heldout import HeldOutAlgebra
from bayescal.calibration.loo import period_log_densities
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.calibration.target import BatchedPosterior
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import ObservationModel, OutputNoise
from bayescal.mcmc.diagnostics import import_arviz
from virtual_wall import VirtualExperiment

Wall = tuple[VirtualExperiment, Assembled, Emulator]


def _ar1_corr(n: int, phi: float) -> np.ndarray:
    i = np.arange(n)
    return phi ** np.abs(i[:, None] - i[None, :])


@pytest.mark.parametrize(("model", "phi"), [("white", 0.0), ("ar1", 0.6)])
def test_physical_density_does_not_depend_on_the_standardisation(model: str, phi: float) -> None:
    # One physical model of a period's n samples: y = mu0 + B w + e, w ~ N(mean, diag(var)),
    # e ~ N(0, sigma^2 R). Standardised as (y - centre) / s with two different (centre, s);
    # the centre is moved inside the span of B so the same model is expressible both ways.
    rng = np.random.default_rng(8)
    n, p, m = 10, 2, 3
    basis = rng.normal(size=(n, p))
    mu0 = rng.normal(size=n)
    mean, var = rng.normal(size=(m, p)), rng.uniform(0.1, 0.4, (m, p))
    sigma = 0.3
    y = rng.normal(size=(n, m)) + mu0[:, None]
    cov_phys = [basis @ np.diag(var[i]) @ basis.T + sigma**2 * _ar1_corr(n, phi) for i in range(m)]
    want = np.array(
        [
            stats.multivariate_normal(mu0 + basis @ mean[i], cov_phys[i]).logpdf(y[:, i])
            for i in range(m)
        ]
    )
    got = []
    for scale, shift in ((2.5, np.zeros(p)), (0.2, rng.normal(size=p))):
        centre = mu0 + basis @ shift  # so that y_std = K (w - shift) + e / scale
        k = basis / scale
        obs = ObservationModel(
            (OutputNoise("q", (0, n), tuple(range(p)), model),),
            k,
            (y - centre[:, None]) / scale,  # type: ignore[arg-type]
        )
        values = {"lambda_star": (scale / sigma) ** 2, "phi": phi}
        std = period_log_densities(
            obs,
            values,
            mean - shift,
            var,
            np.einsum("ij,ij->j", k, k),
            np.ones(p),
            obs.ls_weights(),
        )
        got.append(std + cv.log_jacobian(np.full(n, scale)))
    np.testing.assert_allclose(got[0], want, rtol=1e-10)
    np.testing.assert_allclose(got[1], want, rtol=1e-10)


def test_pointwise_scales_give_the_physical_gaussian() -> None:
    # Point-wise standardisation: the standardised model N(K mu, K V K^T + I / lambda*) is,
    # in physical units, N(centre + D K mu, D (K V K^T + I / lambda*) D) with D = diag(sd).
    rng = np.random.default_rng(9)
    n, p = 8, 2
    k = rng.normal(size=(n, p))
    sd, centre = rng.uniform(0.2, 3.0, n), rng.normal(size=n)
    y_phys = centre + sd * rng.normal(size=n)
    obs = ObservationModel(
        (OutputNoise("q", (0, n), (0, 1)),), k, ((y_phys - centre) / sd)[:, None]
    )
    mean, var, lam = rng.normal(size=(1, p)), np.array([[0.3, 0.2]]), 7.0
    std = period_log_densities(
        obs,
        {"lambda_star": lam},
        mean,
        var,
        np.einsum("ij,ij->j", k, k),
        np.ones(p),
        obs.ls_weights(),
    )
    d = np.diag(sd)
    cov = d @ (k @ np.diag(var[0]) @ k.T + np.eye(n) / lam) @ d
    want = stats.multivariate_normal(centre + sd * (k @ mean[0]), cov).logpdf(y_phys)
    assert std[0] + cv.log_jacobian(sd) == pytest.approx(want, rel=1e-10)
    with pytest.raises(ValueError, match="positive"):
        cv.log_jacobian([1.0, 0.0])


def _points(em: Emulator, obs: ObservationModel, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = len(em.parameter_names)
    cols = [rng.uniform(0.1, 0.9, (n, t)), em.lam * np.exp(rng.normal(0, 0.3, (n, 1)))]
    cols.append(rng.uniform(20.0, 400.0, (n, obs.n_outputs)))
    cols.append(rng.uniform(-0.5, 0.8, (n, len(obs.ar_outputs))))
    cols.append(np.exp(rng.uniform(-6.0, -1.0, (n, len(obs.delta_outputs)))))
    return np.concatenate(cols, axis=1)


def _variant(obs: ObservationModel, model: str, discrepancy: bool) -> ObservationModel:
    out = dataclasses.replace(obs.outputs[0], model=model, discrepancy=discrepancy)
    return ObservationModel((out,), obs.k, obs.y_star)


@pytest.mark.parametrize(("model", "discrepancy"), [("white", False), ("ar1", True)])
def test_held_out_target_does_not_see_the_left_out_period(
    small_wall: Wall, model: str, discrepancy: bool
) -> None:
    _, a, em = small_wall
    obs = _variant(a.observations, model, discrepancy)
    priors = list(a.priors.values())
    i = 2
    held = cv.held_out_target(em, obs, priors, i)
    points = _points(em, obs, 4, seed=1)
    before = np.array([held(v) for v in points])
    assert np.all(np.isfinite(before))
    moved = np.array(obs.y_star, copy=True)
    moved[:, i] += 0.7
    again = cv.held_out_target(em, ObservationModel(obs.outputs, obs.k, moved), priors, i)
    np.testing.assert_allclose([again(v) for v in points], before, rtol=1e-10)
    moved[:, i + 1] += 0.7  # another period's data do count
    other = cv.held_out_target(em, ObservationModel(obs.outputs, obs.k, moved), priors, i)
    assert np.all(np.abs(np.array([other(v) for v in points]) - before) > 1e-6)


def _dense_conditional(em: Emulator, obs: ObservationModel, v: np.ndarray, i: int) -> float:
    """log p(y*_i | y*_-i, simulations, v) of one white output, by dense Gaussian algebra
    (up to a constant that does not depend on v)."""
    t = len(em.parameter_names)
    theta_star, lam, lam_star = v[:t], v[t], v[t + 1]
    w_star = obs.ls_weights()
    total = 0.0
    for j, kern in enumerate(em.kernels):
        ktk = em.basis.ktk[j]
        s_x = kern.x_corr(em.x)
        big_a = np.kron(kern.theta_cov(em.theta), s_x) + np.eye(em.w.shape[0]) / (lam * ktk)
        c = kern.theta_cov(em.theta, theta_star[None])[:, 0]
        big_b = np.kron(c[:, None], s_x)
        big_c = kern.variance * s_x + np.eye(s_x.shape[0]) / (lam_star * ktk)
        mu = big_b.T @ linalg.solve(big_a, em.w[:, j])
        sigma = big_c - big_b.T @ linalg.solve(big_a, big_b)
        q = linalg.inv(sigma)
        resid = w_star[:, j] - mu
        rest = np.delete(np.arange(resid.size), i)
        cond_mean = mu[i] - q[i, rest] @ resid[rest] / q[i, i]
        total += stats.norm.logpdf(w_star[i, j], cond_mean, np.sqrt(1.0 / q[i, i]))
    k = obs.k
    y = obs.y_star[:, i]
    rss = float(np.sum((y - k @ w_star[i]) ** 2))
    n, p = k.shape
    return total + 0.5 * (n - p) * np.log(lam_star) - 0.5 * lam_star * rss


def test_held_out_target_is_the_conditional_density_of_the_period(small_wall: Wall) -> None:
    # full(v) - held_out(v) = log p(y*_i | y*_-i, simulations, v) + const: the importance
    # ratio of PSIS and the likelihood the refit drops, checked against dense algebra.
    _, a, em = small_wall
    obs = a.observations
    priors = list(a.priors.values())
    full = cv.held_out_target(em, obs, priors)
    for i in (0, 3):
        held = cv.held_out_target(em, obs, priors, i)
        points = _points(em, obs, 5, seed=10 + i)
        diff = np.array([full(v) - held(v) - _dense_conditional(em, obs, v, i) for v in points])
        spread = np.array([full(v) - held(v) for v in points])
        assert np.ptp(spread) > 1.0  # the density itself moves with v ...
        assert np.ptp(diff) < 1e-8 * max(1.0, np.max(np.abs(spread)))  # ... the constant not


def test_the_shortcut_is_the_general_route(small_wall: Wall) -> None:
    # One white output: the full grid minus the period's conditional density equals the
    # Schur route on the other periods' observed weights, one point or a batch at a time.
    _, a, em = small_wall
    obs = a.observations
    priors = list(a.priors.values())
    points = _points(em, obs, 6, seed=3)
    for i in (0, 5):
        fast = cv.held_out_target(em, obs, priors, i)
        slow = cv.held_out_target(em, obs, priors, i, shortcut=False)
        assert isinstance(fast.algebra, HeldOutAlgebra)
        assert not isinstance(slow.algebra, HeldOutAlgebra)
        want = np.array([slow(v) for v in points])
        np.testing.assert_allclose([fast(v) for v in points], want, rtol=1e-9)
        batch = BatchedPosterior(fast.algebra, fast.prior_terms)(points)
        np.testing.assert_allclose(batch, want, rtol=1e-9)


@pytest.fixture(scope="module")
def wall_posterior(small_wall: Wall) -> Posterior:
    _, a, em = small_wall
    return calibrate(
        em, a, n_chains=4, n_burn=300, n_draws=500, seed=2, backend="vectorised",
        observations=a.observations,
    )  # fmt: skip


def test_psis_matches_an_exact_refit(small_wall: Wall, wall_posterior: Posterior) -> None:
    _, a, em = small_wall
    scores = cv.leave_period_out(em, a.observations, wall_posterior, draws_per_chain=100)
    assert scores.n_periods == a.n_periods
    assert scores.log_jacobian == pytest.approx(-np.sum(np.log(em.outputs.sd)))
    assert np.all(scores.pointwise <= scores.lppd + 1e-9)  # leaving out never helps
    assert scores.p_loo > 0.0
    # The bands of a period the calibration did not see hold their rates on this known
    # truth (white noise, white model): within 3.5 binomial SEs of the n samples.
    assert scores.pit.shape == a.observations.y_star.shape
    n = scores.pit.size
    for level in (0.95, 0.5):
        se = np.sqrt(level * (1.0 - level) / n)
        assert abs(scores.band_coverage(level) - level) < 3.5 * se, (level, scores.pit)
        shares = scores.band_shares(level)
        assert shares.shape == (a.n_periods,)
        assert shares.mean() == pytest.approx(scores.band_coverage(level))
        # the SE with the period as the unit, and the check it makes
        assert scores.band_coverage_se(level) == pytest.approx(
            shares.std(ddof=1) / np.sqrt(a.n_periods)
        )
        assert scores.band_check(level, z=3.5) == "holds"
    # ... and show it when they do not: the same draws with a noise SD five times too small
    aux = np.array(wall_posterior.aux, dtype=float, copy=True)
    aux[..., wall_posterior.aux_names.index("lambda_star")] *= 25.0
    narrow = dataclasses.replace(wall_posterior, aux=aux)
    overconfident = cv.leave_period_out(em, a.observations, narrow, draws_per_chain=100)
    assert overconfident.band_coverage(0.95) < 0.95 - 3.5 * np.sqrt(0.95 * 0.05 / n)
    assert overconfident.band_check(0.95) == "too narrow"
    assert overconfident.band_check(0.5) == "too narrow"
    best = int(np.argmin(scores.pareto_k))
    assert scores.pareto_k[best] < cv.PARETO_K_MAX
    value, refit, pit = cv.refit_period(
        em, a.observations, dict(wall_posterior.priors), best,
        n_chains=4, n_burn=200, n_draws=300, seed=5, backend="serial", draws_per_chain=100,
    )  # fmt: skip
    assert refit.unit_draws.shape[:2] == (4, 300)
    # The refit and the importance-sampling estimate agree within their Monte Carlo error.
    assert value == pytest.approx(scores.psis[best], abs=0.15)
    assert pit.shape == (a.observations.y_star.shape[0],)
    assert np.all((pit > 0.0) & (pit < 1.0))
    done = scores.with_refits({best: value}, ["note"], {best: pit})
    np.testing.assert_array_equal(done.pit[:, best], pit)
    assert done.pointwise[best] == value
    assert done.refit_warnings == ("note",)
    assert done.elpd == pytest.approx(scores.elpd - scores.psis[best] + value)


def test_refit_order_and_unreliable_periods() -> None:
    k = np.array([0.2, 0.9, np.inf, 0.75, 0.1])
    s = cv.PeriodScores(
        psis=np.arange(5.0), pareto_k=k, lppd=np.arange(5.0) + 1, refit=np.full(5, np.nan),
        log_jacobian=0.0, draws=100,
    )  # fmt: skip
    assert s.refit_order() == [2, 1, 3]
    assert s.psis_only.tolist() == [False, True, True, True, False]
    t = s.with_refits({2: -1.0})
    assert t.refit_order() == [1, 3]
    assert t.psis_only.tolist() == [False, True, False, True, False]
    assert t.pointwise.tolist() == [0.0, 1.0, -1.0, 3.0, 4.0]
    assert t.se == pytest.approx(np.sqrt(5 * np.var([0.0, 1.0, -1.0, 3.0, 4.0])))


def test_paired_difference_is_arviz_compare() -> None:
    az = import_arviz()
    rng = np.random.default_rng(4)
    shared = rng.normal(size=(1, 1, 12))  # what every variant finds hard
    data = {}
    for name, shift in (("a", 0.0), ("b", -0.4)):
        loglik = shared + shift + 0.3 * rng.normal(size=(4, 300, 12))
        data[name] = az.from_dict(
            posterior={"mu": rng.normal(size=(4, 300))}, log_likelihood={"y": loglik}
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a pandas deprecation inside ArviZ
        table = az.compare(data)
    loo_a = az.loo(data["a"], pointwise=True).loo_i.values
    loo_b = az.loo(data["b"], pointwise=True).loo_i.values
    diff, se = cv.paired_difference(loo_a, loo_b)
    assert table.index[0] == "a"
    assert diff == pytest.approx(table.loc["b", "elpd_diff"], rel=1e-10)
    assert se == pytest.approx(table.loc["b", "dse"], rel=1e-10)


def test_band_check_takes_the_period_as_the_unit() -> None:
    # 20 periods of 48 samples whose PITs fall inside or outside together: a binomial SE
    # of 960 independent samples would call a 0.90 coverage far off 0.95; over the
    # periods it is within two SEs ...
    rng = np.random.default_rng(0)
    inside = rng.random(20) < 0.9
    pit = np.where(inside, 0.5, 0.999)[None, :] * np.ones((48, 1))
    scores = cv.PeriodScores(
        psis=np.zeros(20), pareto_k=np.zeros(20), lppd=np.zeros(20),
        refit=np.full(20, np.nan), log_jacobian=0.0, draws=10, pit=pit,
    )  # fmt: skip
    cov = scores.band_coverage(0.95)
    assert cov == pytest.approx(inside.mean())
    assert abs(cov - 0.95) > 3.0 * np.sqrt(0.95 * 0.05 / pit.size)
    se = scores.band_coverage_se(0.95)
    assert se == pytest.approx(np.std(inside.astype(float), ddof=1) / np.sqrt(20))
    assert abs(cov - 0.95) < 2.0 * se
    assert scores.band_check(0.95) == "holds"
    # ... while every sample in the middle makes both bands too wide, and none too narrow
    wide = dataclasses.replace(scores, pit=np.full((48, 20), 0.5) + 0.01 * rng.random((48, 20)))
    assert wide.band_check(0.95) == wide.band_check(0.5) == "too wide"
    narrow = dataclasses.replace(scores, pit=np.full((48, 20), 0.999))
    assert narrow.band_coverage_se(0.5) == 0.0
    assert narrow.band_check(0.5) == "too narrow"
    assert cv.PeriodScores(
        psis=np.zeros(2), pareto_k=np.zeros(2), lppd=np.zeros(2),
        refit=np.full(2, np.nan), log_jacobian=0.0, draws=10,
    ).band_check(0.95) == ""  # fmt: skip
